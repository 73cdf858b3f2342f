#![allow(clippy::unwrap_used, clippy::expect_used)]
//! A LiDAR registered to the trajectory by its own sweeps ([`rigcal::classical::trajectory_icp`]),
//! against the ground truth: `cargo run --release --example trajectory_icp -- LOG GROUND_TRUTH
//! [LIDAR] [FRAMES] [PERTURB_DEG PERTURB_CM]` (start: the log's `/tf_static`, or the truth
//! perturbed by the given rotation and translation when they are given). The ground truth is a
//! native calibration file or a PandaSet-style `ground_truth.json`.

use std::path::PathBuf;

use glam::DVec3;
use rigcal::calib::file::CalibrationFile;
use rigcal::classical::icp::IcpConfig;
use rigcal::classical::trajectory_icp::{TrajectoryFit, register_to_trajectory};
use rigcal::log::Drive;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let drive = Drive::open(&PathBuf::from(&args[1])).unwrap();
    let truth_path = PathBuf::from(&args[2]);
    let truth = if truth_path.extension().is_some_and(|e| e == "json") {
        rigcal::calib::dataset_json::load_reference(&truth_path).unwrap()
    } else {
        CalibrationFile::load_rig(&truth_path).unwrap()
    };
    let name = args
        .get(3)
        .cloned()
        .unwrap_or_else(|| truth.lidars().next().unwrap().name.clone());
    let frames: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(10);
    let mut rig = drive.rig.clone();
    let exact = truth.sensor(&name).unwrap().vehicle_from_sensor;
    if let (Some(d), Some(c)) = (
        args.get(5).and_then(|s| s.parse::<f64>().ok()),
        args.get(6).and_then(|s| s.parse::<f64>().ok()),
    ) {
        rig.sensor_mut(&name).unwrap().vehicle_from_sensor = exact.perturbed_right(
            DVec3::new(0.6, -0.5, 0.62).normalize_or_zero() * d.to_radians(),
            DVec3::new(0.5, 0.6, -0.62).normalize_or_zero() * c / 100.0,
        );
    }
    let start = rig.sensor(&name).unwrap().vehicle_from_sensor;
    let (r0, t0) = exact.difference(start);
    let clock = std::time::Instant::now();
    let fit = register_to_trajectory(
        &drive,
        &rig,
        &name,
        frames,
        &[],
        IcpConfig::default(),
        &mut |_, _| {},
    )
    .unwrap();
    let TrajectoryFit::Fitted {
        vehicle_from_lidar: found,
        unobserved,
    } = fit
    else {
        println!("{name}: not fitted: {fit:?}");
        return;
    };
    let (r, t) = exact.difference(found);
    let d = found.translation - exact.translation;
    println!(
        "{name}: {:.3}° / {:.2} cm -> {:.3}° / {:.2} cm (x {:.2} y {:.2} z {:.2} cm) in {:.1} s, {frames} sweeps, unobserved {unobserved:?}",
        r0.to_degrees(),
        t0 * 100.0,
        r.to_degrees(),
        t * 100.0,
        d.x * 100.0,
        d.y * 100.0,
        d.z * 100.0,
        clock.elapsed().as_secs_f64()
    );
}
