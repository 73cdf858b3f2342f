#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Does the report's per-axis σ cover a camera's true error? For each camera of a result: the
//! error against the reference in the camera's own frame (root LiDAR aligned), the edge check's
//! σ at the result (as the report computes it), and the Newton step to the edge cost's own
//! minimum (how far the edge score would move the camera: a bias the σ does not see).
//!
//! `cargo run --release --no-default-features --example sigma_check -- LOG REFERENCE RESULT [FRAMES]`

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
        let newton = check.local_model(at).newton_step();
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
        match newton {
            Some(n) => println!("  newton {}", fmt(n)),
            None => println!("  newton (H not positive definite)"),
        }
    }
}
