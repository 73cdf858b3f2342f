#![allow(clippy::unwrap_used, clippy::expect_used)]
//! UniCal's cameras on a written drive, watched against the ground truth: every LiDAR is held
//! at the truth (the Pandar64 frozen as the root), the cameras start from the log's
//! `/tf_static` (or `RIGCAL_INIT`), and every `RIGCAL_EVERY` iterations the mean camera error,
//! the colour loss and the alignment term's kept matches are printed.
//! `cargo run --release --example unical_cameras -- LOG GROUND_TRUTH [ITERATIONS]`
//! Environment: `RIGCAL_LR_CAMERA` (camera pose rate), `RIGCAL_FRAMES` (images per camera, 8),
//! `RIGCAL_ALIGN=none|ray-distance|surface`, `RIGCAL_ALIGN_WEIGHT`, `RIGCAL_ALIGN_MAX_PX`,
//! `RIGCAL_WARMUP` (pose warm-up iterations), `RIGCAL_SCALE` (image scale, 0.125),
//! `RIGCAL_RGB_WEIGHT`, `RIGCAL_INTENSITY_WEIGHT`, `RIGCAL_VIEW=false` (view-independent surface colour),
//! `RIGCAL_TRANSLATION_RATE` (camera translation rate over the rotation's), `RIGCAL_CAMERA_DECAY`
//! (the camera pose rate's final fraction), `RIGCAL_VECTORS` (print every camera's error vector). Frozen-scene probe: with `RIGCAL_PROBE=N` the cameras start at the
//! truth and the scene learns for N iterations (poses fixed), then the cameras jump to their
//! start and only their poses move (the scene frozen unless `RIGCAL_JOINT` is set).

use std::path::PathBuf;

use rigcal::calib::file::CalibrationFile;
use rigcal::log::Drive;
use rigcal::unical::calibrator::UnicalLidarStage;
use rigcal::unical::depth_calib::DepthCalibConfig;

fn env<T: std::str::FromStr>(key: &str, default: T) -> T {
    std::env::var(key)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let log = PathBuf::from(&args[1]);
    let truth = CalibrationFile::load_rig(&PathBuf::from(&args[2])).unwrap();
    let iterations: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(600);
    let drive = Drive::open(&log).unwrap();
    let mut rig = drive.rig.clone();
    if let Ok(init) = std::env::var("RIGCAL_INIT") {
        rig = CalibrationFile::load_rig(&PathBuf::from(init)).unwrap();
    }
    // LiDARs at the truth and held: only the cameras' basin is measured.
    for lidar in truth.lidars() {
        rig.sensor_mut(&lidar.name).unwrap().vehicle_from_sensor = lidar.vehicle_from_sensor;
    }
    let start = rig.clone();
    let probe: usize = env("RIGCAL_PROBE", 0);
    if probe > 0 {
        rig = truth.clone();
    }
    let lidars: Vec<String> = truth.lidars().map(|l| l.name.clone()).collect();
    let defaults = DepthCalibConfig::default();
    let mut settings = defaults.alignment_settings;
    settings.max_error_px = env("RIGCAL_ALIGN_MAX_PX", settings.max_error_px);
    let config = DepthCalibConfig {
        iterations,
        frozen_sensor: Some(lidars[0].clone()),
        held_sensors: lidars[1..].to_vec(),
        lr_camera_pose: env("RIGCAL_LR_CAMERA", defaults.lr_camera_pose),
        pose_warmup: if probe > 0 {
            probe
        } else {
            env("RIGCAL_WARMUP", defaults.pose_warmup)
        },
        alignment: env("RIGCAL_ALIGN", defaults.alignment),
        alignment_weight: env("RIGCAL_ALIGN_WEIGHT", defaults.alignment_weight),
        alignment_settings: settings,
        rgb_weight: env("RIGCAL_RGB_WEIGHT", defaults.rgb_weight),
        intensity_weight: env("RIGCAL_INTENSITY_WEIGHT", defaults.intensity_weight),
        view_dependent_colour: env("RIGCAL_VIEW", defaults.view_dependent_colour),
        camera_translation_rate: env("RIGCAL_TRANSLATION_RATE", defaults.camera_translation_rate),
        camera_pose_final_fraction: env("RIGCAL_CAMERA_DECAY", defaults.camera_pose_final_fraction),
        correspondence_cache: Some(std::env::temp_dir().join("rigcal-probe-matches")),
        ..defaults
    };
    let t0 = std::time::Instant::now();
    let mut stage = UnicalLidarStage::from_drive(&drive, &rig, 4, &[], config)
        .unwrap()
        .with_cameras(
            &drive,
            env("RIGCAL_FRAMES", 8),
            &[],
            env("RIGCAL_SCALE", 0.125),
        )
        .unwrap();
    if let Some(m) = drive
        .trajectory
        .time_range_nanos()
        .and_then(|(a, b)| rigcal::geometry::motion::MotionSummary::of(&drive.trajectory, a, b))
    {
        eprintln!(
            "drive: {:.1} s, {:.0} m, turns {:.0}° in all (yaw rate up to {:.0}°/s)",
            m.duration_s, m.distance_m, m.total_turn_deg, m.max_abs_yaw_rate_deg_s
        );
    }
    let pairs = stage.calibration().correspondences.pairs.len();
    eprintln!(
        "prepared in {:.1} s, {pairs} matched pairs",
        t0.elapsed().as_secs_f64()
    );
    let every: usize = env("RIGCAL_EVERY", 25);
    let errors = |stage: &UnicalLidarStage| {
        let mut per = Vec::new();
        for (name, t) in stage.calibration().extrinsics() {
            let Some(s) = truth.sensor(&name) else {
                continue;
            };
            if s.camera.is_some() {
                let (r, m) = s.vehicle_from_sensor.difference(t);
                per.push((name, r.to_degrees(), m * 100.0));
            }
        }
        per
    };
    let (mut colour, mut align, mut kept, mut n) = (0.0, 0.0, 0usize, 0usize);
    for it in 0..iterations {
        if probe > 0 && it == probe {
            let calib = stage.calibration_mut();
            for cam in start.cameras() {
                calib.set_extrinsic(&cam.name, cam.vehicle_from_sensor);
            }
            if std::env::var("RIGCAL_JOINT").is_err() {
                calib.config.lr_field = 0.0;
            }
            println!("probe: cameras back at their start");
        }
        let r = stage.calibration_mut().step();
        colour += r.colour_loss;
        align += r.alignment_loss;
        kept += r.alignment_matches;
        n += 1;
        if (it + 1) % every == 0 || it + 1 == iterations {
            let per = errors(&stage);
            let k = per.len().max(1) as f64;
            let (rot, tr) = per
                .iter()
                .fold((0.0, 0.0), |(a, b), (_, r, t)| (a + r, b + t));
            let each: Vec<String> = per
                .iter()
                .map(|(_, r, t)| format!("{r:.2}/{t:.1}"))
                .collect();
            println!(
                "{:5} {:6.1}s cameras {:.3}° {:.2} cm | colour {:.5} align {:.2} kept {:.1} | {}",
                it + 1,
                t0.elapsed().as_secs_f64(),
                rot / k,
                tr / k,
                colour / n as f64,
                align / n as f64,
                kept as f64 / n as f64,
                each.join(" ")
            );
            (colour, align, kept, n) = (0.0, 0.0, 0, 0);
            if std::env::var("RIGCAL_VECTORS").is_ok() {
                print_error_vectors(&stage, &truth);
            }
        }
    }
}

/// Each camera's error as vectors in the vehicle frame (translation: estimated − true camera
/// centre, cm; rotation: log(R_est R_true⁻¹), degrees) and their mean over the cameras: a
/// common part is an offset every camera shares, which the learned texture can follow.
fn print_error_vectors(stage: &UnicalLidarStage, truth: &rigcal::calib::Rig) {
    let (mut sum_t, mut sum_r, mut k) = (glam::DVec3::ZERO, glam::DVec3::ZERO, 0.0);
    for (name, t) in stage.calibration().extrinsics() {
        let Some(s) = truth.sensor(&name) else {
            continue;
        };
        if s.camera.is_none() {
            continue;
        }
        let dt = (t.translation - s.vehicle_from_sensor.translation) * 100.0;
        let dr =
            rigcal::geometry::so3::log(t.rotation * s.vehicle_from_sensor.rotation.conjugate())
                * (180.0 / std::f64::consts::PI);
        println!(
            "      {name:>20} dt ({:6.2} {:6.2} {:6.2}) cm  dr ({:6.3} {:6.3} {:6.3})°",
            dt.x, dt.y, dt.z, dr.x, dr.y, dr.z
        );
        sum_t += dt;
        sum_r += dr;
        k += 1.0;
    }
    let (mt, mr) = (sum_t / k, sum_r / k);
    println!(
        "      {:>20} dt ({:6.2} {:6.2} {:6.2}) cm  dr ({:6.3} {:6.3} {:6.3})°",
        "mean", mt.x, mt.y, mt.z, mr.x, mr.y, mr.z
    );
}
