#![allow(clippy::unwrap_used, clippy::expect_used)]
//! UniCal's LiDAR stage on a simulated drive: perturb every LiDAR, learn the scene and the
//! extrinsics from depth, print the error against the ground truth as it goes.
//! `cargo run --release --example unical_lidar -- [ITERATIONS] [SECONDS] [PERTURBATION_SCALE] [BETA_INIT] [REGULARISER_WEIGHT]`
//! Environment: `RIGCAL_ROOT` (first LiDAR frozen at the truth), `RIGCAL_NEWTON` (preconditioned
//! pose steps), `RIGCAL_REGISTRATION=N`, `RIGCAL_C2F=LEVELS,FRACTION|off`, `RIGCAL_LR_POSE=RATE`,
//! `RIGCAL_OPACITY=interval|per-sample`.

mod common;

use glam::DVec3;
use rigcal::unical::depth_calib::{DepthCalibConfig, DepthCalibration, LidarData};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let iterations: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(300);
    let seconds: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(3.0);
    // Scale of the initial perturbation (0: start at the ground truth, to see the scene's own
    // rendering error).
    let perturbation: f64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let defaults = DepthCalibConfig::default();
    let beta_init: f32 = args
        .get(4)
        .and_then(|s| s.parse().ok())
        .unwrap_or(defaults.beta_init);
    let regulariser_weight: f32 = args
        .get(5)
        .and_then(|s| s.parse().ok())
        .unwrap_or(defaults.regulariser_weight);
    let (rig, traj, world) = common::drive(seconds);
    let t0 = std::time::Instant::now();
    let lidars: Vec<LidarData> = rig
        .lidars
        .iter()
        .enumerate()
        .map(|(k, l)| {
            let sign = if k == 0 { perturbation } else { -perturbation };
            // With RIGCAL_ROOT set the first LiDAR is the frozen root, left at the truth.
            let sign = if k == 0 && std::env::var("RIGCAL_ROOT").is_ok() {
                0.0
            } else {
                sign
            };
            let initial = l.vehicle_from_lidar.perturbed_right(
                DVec3::new(0.6, -0.5, 0.6) * sign * 1f64.to_radians(),
                DVec3::new(0.06, -0.05, 0.05) * sign,
            );
            common::lidar_data(&world, l, &traj, seconds, initial)
        })
        .collect();
    eprintln!(
        "simulated {} LiDARs in {:.1} s",
        lidars.len(),
        t0.elapsed().as_secs_f64()
    );
    let truth: Vec<_> = rig.lidars.iter().map(|l| l.vehicle_from_lidar).collect();
    let config = DepthCalibConfig {
        lr_pose: std::env::var("RIGCAL_LR_POSE")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(defaults.lr_pose),
        frozen_sensor: std::env::var("RIGCAL_ROOT")
            .is_ok()
            .then(|| rig.lidars[0].name.clone()),
        iterations,
        registration_steps: std::env::var("RIGCAL_REGISTRATION")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(defaults.registration_steps),
        // `LEVELS,FRACTION` or `off`; unset: the preset's.
        coarse_to_fine: std::env::var("RIGCAL_C2F")
            .map_or(Ok(defaults.coarse_to_fine), |v| {
                rigcal::unical::depth_calib::CoarseToFine::parse_setting(&v)
            })
            .expect("RIGCAL_C2F"),
        lidar_pose_update: if std::env::var("RIGCAL_NEWTON").is_ok() {
            rigcal::unical::pose_newton::PoseUpdate::Newton(Default::default())
        } else {
            rigcal::unical::pose_newton::PoseUpdate::Adam
        },
        beta_init,
        regulariser_weight,
        opacity: common::opacity_from_env(defaults.opacity),
        ..defaults
    };
    let mut calib = DepthCalibration::new(config, traj, lidars);
    eprintln!(
        "occupancy {:.1} % of {:?} voxels",
        calib.occupancy.occupied_fraction() * 100.0,
        calib.occupancy.dims
    );
    let t0 = std::time::Instant::now();
    for it in 0..iterations {
        let r = calib.step();
        if let Some(loss) = r.geometry_init_loss {
            if it % 25 == 0 {
                eprintln!(
                    "it {it:4} geometry init loss {loss:.4} · {:.2} s/it",
                    t0.elapsed().as_secs_f64() / (it + 1) as f64
                );
            }
            continue;
        }
        if it % 25 == 0 || it + 1 == iterations {
            let errs: Vec<String> = calib
                .extrinsics()
                .iter()
                .zip(&truth)
                .map(|((n, e), t)| {
                    let (r, d) = t.difference(*e);
                    format!("{n} {:.3}° {:.1} cm", r.to_degrees(), d * 100.0)
                })
                .collect();
            // After root alignment: the second LiDAR in the first one's frame.
            let ext = calib.extrinsics();
            let relative = (ext.len() >= 2).then(|| {
                let est = ext[0].1.inverse() * ext[1].1;
                let want = truth[0].inverse() * truth[1];
                let (r, d) = want.difference(est);
                // The translation error's components in the first LiDAR's frame.
                let e = (est.translation - want.translation) * 100.0;
                format!(
                    " · relative {:.3}° {:.1} cm ({:+.1} {:+.1} {:+.1})",
                    r.to_degrees(),
                    d * 100.0,
                    e.x,
                    e.y,
                    e.z
                )
            });
            let errs = errs.join(" · ") + &relative.unwrap_or_default();
            eprintln!(
                "it {it:4} depth loss {:.4} |err| {:.3} m int {:.4} reg {:.3} β {:.1} · {} · {:.2} s/it",
                r.loss,
                r.mean_abs_error_m,
                r.intensity_loss,
                r.regulariser_loss,
                r.beta,
                errs,
                t0.elapsed().as_secs_f64() / (it + 1) as f64
            );
        }
    }
    // Where the rendered depth error is: quantiles of |rendered − true| by range and by the
    // ray's elevation (grazing returns from the ground have small negative elevations).
    let mut residuals = Vec::new();
    for s in 0..calib.lidars.len() {
        // Per LiDAR, the median signed error by range: a systematic offset (not the tail) is
        // what a LiDAR that looks one way reads as a translation.
        let own = calib.depth_residuals(s, 4000);
        let bands: Vec<String> = [(0.0, 10.0), (10.0, 20.0), (20.0, 40.0), (40.0, 1e9)]
            .iter()
            .map(|&(lo, hi)| {
                let mut v: Vec<f32> = own
                    .iter()
                    .filter(|r| r.range_m >= lo && r.range_m < hi)
                    .map(|r| r.error_m)
                    .collect();
                v.sort_by(f32::total_cmp);
                match v.get(v.len() / 2) {
                    Some(m) => format!("{lo}..{hi} m {:+.1} cm (n {})", m * 100.0, v.len()),
                    None => format!("{lo}..{hi} m -"),
                }
            })
            .collect();
        eprintln!(
            "{}: median signed error by range: {}",
            calib.lidars[s].name,
            bands.join(" · ")
        );
        residuals.extend(own);
    }
    let quantiles = |mut v: Vec<f32>| -> String {
        if v.is_empty() {
            return "-".into();
        }
        v.sort_by(f32::total_cmp);
        let q = |p: f64| v[((v.len() - 1) as f64 * p) as usize];
        format!(
            "n {:5} median {:.2} p90 {:.2} p99 {:.2} m",
            v.len(),
            q(0.5),
            q(0.9),
            q(0.99)
        )
    };
    for (lo, hi) in [
        (0.0, 10.0),
        (10.0, 20.0),
        (20.0, 40.0),
        (40.0, 80.0),
        (80.0, 1e9),
    ] {
        let v = residuals
            .iter()
            .filter(|r| r.range_m >= lo && r.range_m < hi)
            .map(|r| r.error_m.abs())
            .collect();
        eprintln!("range {lo:>3}..{hi:<4} m: {}", quantiles(v));
    }
    for (lo, hi) in [(-90.0, -10.0), (-10.0, -3.0), (-3.0, 0.0), (0.0, 90.0)] {
        let v = residuals
            .iter()
            .filter(|r| r.elevation_rad.to_degrees() >= lo && r.elevation_rad.to_degrees() < hi)
            .map(|r| r.error_m.abs())
            .collect();
        eprintln!("elevation {lo:>4}..{hi:<3}°: {}", quantiles(v));
    }
    let signed: f32 =
        residuals.iter().map(|r| r.error_m).sum::<f32>() / residuals.len().max(1) as f32;
    eprintln!("mean signed error {signed:.3} m (negative: rendered too short)");
    // Is the tail incomplete accumulation (D = Σ w τ short by (1 − A)·range) or opacity in
    // front of the return? Compare the error of D with that of D / A on the worst rays.
    let bad: Vec<_> = residuals.iter().filter(|r| r.error_m.abs() > 1.0).collect();
    let low_a = bad.iter().filter(|r| r.accumulation < 0.95).count();
    eprintln!(
        "{} rays err > 1 m: {} with A < 0.95; |D/A − range| {}",
        bad.len(),
        low_a,
        quantiles(
            bad.iter()
                .map(|r| ((r.error_m + r.range_m) / r.accumulation.max(1e-3) - r.range_m).abs())
                .collect()
        )
    );
    eprintln!(
        "accumulation over all rays: {}",
        quantiles(residuals.iter().map(|r| r.accumulation).collect())
    );
}
