//! Does the hand-eye's rotation bias come from the estimator or from the keypoints? Each
//! camera's pairs are read from the truth; every match is triangulated with the true extrinsic
//! and reprojected exactly into both images (the estimator's input without keypoint error),
//! then again with symmetric noise of `NOISE_PX` pixels; the fit from the truth is printed for
//! the measured, the exact and the noisy rays, as the rotation error about the camera's axes.
//!
//! Probes of the measured matches, by environment: `SHIFT_PX=DX,DY` moves every measured
//! keypoint by a constant offset (pixels at the camera's focal length) before the fit, and
//! `UPPER=1` keeps only the matches above the optical axis (no ground). `RESIDUALS=1` also
//! prints each camera's mean distance of its matches from their epipolar lines under the truth.
//!
//! `cargo run --release --no-default-features --example hand_eye_exact -- LOG.mcap GT [NOISE_PX]`
//! (docs/experiments/pipeline.md, "The hand-eye tilts every camera down").

mod reference;

use glam::DVec3;
use rigcal::classical::camera_motion::{DEFAULT_FRAMES, camera_pairs};
use rigcal::classical::hand_eye::{MotionPair, solve};
use rigcal::classical::lidar_translation::triangulate;
use rigcal::log::Drive;
use rigcal::sim::noise::hash3;

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (log, gt) = match (args.first(), args.get(1)) {
        (Some(l), Some(g)) => (l, g),
        _ => return Err("usage: hand_eye_exact LOG.mcap GT.yaml [NOISE_PX]".into()),
    };
    let noise_px: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let drive = Drive::open(std::path::Path::new(log)).map_err(|e| e.to_string())?;
    let truth = reference::at_reference(&drive.rig, gt)?;
    // The probes of the measured matches (module docs).
    let shift: Vec<f64> = std::env::var("SHIFT_PX")
        .unwrap_or_default()
        .split(',')
        .filter_map(|v| v.parse().ok())
        .collect();
    let (dx, dy) = (
        shift.first().copied().unwrap_or(0.0),
        shift.get(1).copied().unwrap_or(0.0),
    );
    let upper_only = std::env::var("UPPER").is_ok();
    let residuals = std::env::var("RESIDUALS").is_ok();
    let names: Vec<String> = truth.cameras().map(|c| c.name.clone()).collect();
    for name in &names {
        let Some(sensor) = truth.sensor(name) else {
            continue;
        };
        let x = sensor.vehicle_from_sensor;
        let fx = sensor.camera.as_ref().map_or(1000.0, |c| c.fx);
        let found = camera_pairs(
            &drive,
            &truth,
            name,
            DEFAULT_FRAMES,
            &[],
            false,
            &|_, _, _| {},
        )
        .map_err(|e| e.to_string())?;
        // Standard normal draws from the simulator's seeded hash (Box–Muller), one per call.
        let mut draws = 0i32;
        let mut gauss = move || {
            draws += 1;
            let a = f64::from(hash3(draws, 0, 0, 7)).max(1e-12);
            let b = f64::from(hash3(draws, 1, 0, 7));
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        let remade = |sigma_px: f64, gauss: &mut dyn FnMut() -> f64| -> Vec<MotionPair> {
            found
                .pairs
                .iter()
                .map(|p| {
                    let points = triangulate(std::slice::from_ref(p), &found.world_from_vehicle, x);
                    let j_from_i = (x.inverse() * p.vehicle_motion * x).inverse();
                    let mut jitter = |r: DVec3| -> DVec3 {
                        let (u, v) = (r.x / r.z, r.y / r.z);
                        let s = sigma_px / fx;
                        DVec3::new(u + s * gauss(), v + s * gauss(), 1.0).normalize_or_zero()
                    };
                    let rays = points
                        .iter()
                        .map(|t| {
                            let in_i = x.rotation.inverse() * t.from_camera;
                            let in_j = j_from_i.transform_point(in_i);
                            (
                                jitter(in_i.normalize_or_zero()),
                                jitter(in_j.normalize_or_zero()),
                            )
                        })
                        .collect();
                    MotionPair { rays, ..p.clone() }
                })
                .collect()
        };
        let shifted: Vec<MotionPair> = found
            .pairs
            .iter()
            .map(|p| {
                let mv = |r: DVec3| {
                    DVec3::new(r.x / r.z + dx / fx, r.y / r.z + dy / fx, 1.0).normalize_or_zero()
                };
                MotionPair {
                    rays: p
                        .rays
                        .iter()
                        .filter(|(a, _)| !upper_only || a.y < 0.0)
                        .map(|(a, b)| (mv(*a), mv(*b)))
                        .collect(),
                    ..p.clone()
                }
            })
            .collect();
        if residuals {
            epipolar_residuals(name, fx, x, &found.pairs);
        }
        let exact = remade(0.0, &mut gauss);
        let noisy = remade(noise_px, &mut gauss);
        let axes = |pairs: &[MotionPair]| -> String {
            match solve(pairs, x) {
                Ok(f) => {
                    let turned = x.rotation.inverse() * f.vehicle_from_camera.rotation;
                    let a = rigcal::geometry::so3::log(turned)
                        .to_array()
                        .map(f64::to_degrees);
                    format!("{:+.3} {:+.3} {:+.3}°", a[0], a[1], a[2])
                }
                Err(e) => e.to_string(),
            }
        };
        println!(
            "{name:20} fx {fx:.0} measured {}  shifted ({dx}, {dy}) px {}  exact {}  noisy ({noise_px} px) {}",
            axes(&found.pairs),
            axes(&shifted),
            axes(&exact),
            axes(&noisy)
        );
    }
    Ok(())
}

/// Each measured match's distance from its epipolar line under the truth, as an image offset
/// of its second keypoint (pixels at `fx`): the mean offset over all matches and over the
/// matches in each half of the first image (above / below, left / right of the optical axis),
/// and the mean size. Only this component moves a motion estimate (an error along the line
/// is a depth).
fn epipolar_residuals(name: &str, fx: f64, x: rigcal::geometry::Rigid, pairs: &[MotionPair]) {
    // [all, upper, lower, left, right, flow down, flow up]: (sum dx, sum dy, sum |e|, count)
    let mut bins = [[0.0f64; 4]; 7];
    for p in pairs {
        let i_from_j = x.inverse() * p.vehicle_motion * x;
        let c = i_from_j.translation;
        for &(a, b) in &p.rays {
            let n = a.cross(c).normalize_or_zero();
            let b_i = i_from_j.rotation * b;
            let e = n.dot(b_i);
            let n_j = i_from_j.rotation.inverse() * n;
            // The offset's direction in image j: n_j's projection at b.
            let off = glam::DVec2::new(n_j.x - b.x / b.z * n_j.z, n_j.y - b.y / b.z * n_j.z)
                .normalize_or_zero()
                * (e * fx);
            let flow_down = b.y / b.z > a.y / a.z;
            let mut add = |k: usize| {
                bins[k][0] += off.x;
                bins[k][1] += off.y;
                bins[k][2] += e.abs() * fx;
                bins[k][3] += 1.0;
            };
            add(0);
            add(if a.y < 0.0 { 1 } else { 2 });
            add(if a.x < 0.0 { 3 } else { 4 });
            add(if flow_down { 5 } else { 6 });
        }
    }
    let label = [
        "all",
        "upper",
        "lower",
        "left",
        "right",
        "flow-down",
        "flow-up",
    ];
    let parts: Vec<String> = bins
        .iter()
        .zip(label)
        .map(|(b, l)| {
            let n = b[3].max(1.0);
            format!(
                "{l} {:.0}: ({:+.3}, {:+.3}) |{:.2}|",
                b[3],
                b[0] / n,
                b[1] / n,
                b[2] / n
            )
        })
        .collect();
    println!("{name:20} residual px {}", parts.join("  "));
}
