#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Does the report's per-axis σ cover a camera's true error? For each camera of a result: the
//! error against the reference in the camera's own frame (root LiDAR aligned), the edge check's
//! σ at the result (as the report computes it), and the Newton step to the edge cost's own
//! minimum (how far the edge score would move the camera: a bias the σ does not see).
//!
//! `cargo run --release --no-default-features --example sigma_check -- LOG REFERENCE RESULT [FRAMES]`

use glam::DVec3;
use rigcal::calib::Rig;
use rigcal::calib::file::CalibrationFile;
use rigcal::log::Drive;
use rigcal::pipeline::edge_check::EdgeCheck;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let drive = Drive::open(std::path::Path::new(&args[0])).unwrap();
    let reference = CalibrationFile::load_rig(std::path::Path::new(&args[1])).unwrap();
    let end = CalibrationFile::load_rig(std::path::Path::new(&args[2])).unwrap();
    let frames: usize = args.get(3).and_then(|a| a.parse().ok()).unwrap_or(8);
    let lidar = end.lidars().next().unwrap().name.clone();
    let pose = |rig: &Rig, s: &str| rig.sensor(s).unwrap().vehicle_from_sensor;
    let cameras: Vec<String> = end.cameras().map(|c| c.name.clone()).collect();
    for cam in &cameras {
        let at = pose(&end, cam);
        let truth = pose(&end, &lidar) * pose(&reference, &lidar).inverse() * pose(&reference, cam);
        let delta = at.inverse() * truth;
        let q = if delta.rotation.w < 0.0 {
            -delta.rotation
        } else {
            delta.rotation
        };
        let (axis, angle) = q.to_axis_angle();
        let rot = axis * angle;
        let err = [
            rot.x,
            rot.y,
            rot.z,
            delta.translation.x,
            delta.translation.y,
            delta.translation.z,
        ];
        let check = EdgeCheck::new(&drive, &end, (cam, &lidar), frames, &[], &[]).unwrap();
        let sig = check.sigmas(at).0;
        // Newton step of the summed score by central differences.
        let step = [
            0.3f64.to_radians(),
            0.3f64.to_radians(),
            0.3f64.to_radians(),
            0.03,
            0.03,
            0.03,
        ];
        let f = |d: [f64; 6]| {
            check.score(
                at.perturbed_right(DVec3::new(d[0], d[1], d[2]), DVec3::new(d[3], d[4], d[5])),
            )
        };
        let unit = |i: usize, s: f64| -> [f64; 6] {
            std::array::from_fn(|k| if k == i { s * step[i] } else { 0.0 })
        };
        let f0 = f([0.0; 6]);
        let mut h = [[0.0; 6]; 6];
        let mut g = [0.0; 6];
        for i in 0..6 {
            let (p, m) = (f(unit(i, 1.0)), f(unit(i, -1.0)));
            g[i] = (p - m) / (2.0 * step[i]);
            h[i][i] = (p + m - 2.0 * f0) / (step[i] * step[i]);
            for j in i + 1..6 {
                let at2 = |a: f64, b: f64| {
                    let mut d = unit(i, a);
                    d[j] = b * step[j];
                    f(d)
                };
                let v = (at2(1.0, 1.0) - at2(1.0, -1.0) - at2(-1.0, 1.0) + at2(-1.0, -1.0))
                    / (4.0 * step[i] * step[j]);
                h[i][j] = v;
                h[j][i] = v;
            }
        }
        let hm = solve(h, g);
        let fmt = |v: [f64; 6]| {
            format!(
                "{:+.3} {:+.3} {:+.3}° {:+.2} {:+.2} {:+.2} cm",
                v[0].to_degrees(),
                v[1].to_degrees(),
                v[2].to_degrees(),
                v[3] * 100.0,
                v[4] * 100.0,
                v[5] * 100.0
            )
        };
        println!("{cam}");
        println!("  error  {}", fmt(err));
        println!("  sigma  {}", fmt(sig));
        match hm {
            Some(n) => println!("  newton {}", fmt(n.map(|x| -x))),
            None => println!("  newton (H not invertible)"),
        }
    }
}

/// Solve H x = g by Gaussian elimination with partial pivoting.
fn solve(mut h: [[f64; 6]; 6], mut g: [f64; 6]) -> Option<[f64; 6]> {
    for c in 0..6 {
        let p = (c..6).max_by(|&a, &b| h[a][c].abs().total_cmp(&h[b][c].abs()))?;
        if h[p][c].abs() < 1e-12 {
            return None;
        }
        h.swap(c, p);
        g.swap(c, p);
        for r in c + 1..6 {
            let k = h[r][c] / h[c][c];
            for j in c..6 {
                h[r][j] -= k * h[c][j];
            }
            g[r] -= k * g[c];
        }
    }
    let mut x = [0.0; 6];
    for r in (0..6).rev() {
        x[r] = (g[r] - (r + 1..6).map(|j| h[r][j] * x[j]).sum::<f64>()) / h[r][r];
    }
    Some(x)
}
