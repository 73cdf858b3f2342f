#![allow(clippy::unwrap_used, clippy::expect_used)]
//! UniCal's cameras on a written drive, watched against the ground truth: every LiDAR is held
//! at the truth (the Pandar64 frozen as the root), the cameras start from the log's
//! `/tf_static` (or `RIGCAL_INIT`), and every `RIGCAL_EVERY` iterations the mean camera error,
//! the colour loss and the alignment term's kept matches are printed.
//! `cargo run --release --example unical_cameras -- LOG GROUND_TRUTH [ITERATIONS]`
//! Environment: `RIGCAL_LR_CAMERA` (camera pose rate), `RIGCAL_FRAMES` (images per camera, 8),
//! `RIGCAL_ALIGN=none|ray-distance|surface`, `RIGCAL_ALIGN_WEIGHT`, `RIGCAL_ALIGN_MAX_PX`,
//! `RIGCAL_WARMUP` (pose warm-up iterations), `RIGCAL_ALIGN_RELEASE` (the iteration from which
//! cameras follow the correspondence term alone, before the warm-up ends),
//! `RIGCAL_ALIGN_RELEASE_RATE` (their rate until then, as a fraction of the camera rate), `RIGCAL_RAMP` (the pose rates' linear ramp after it),
//! `RIGCAL_INIT_STEPS` (geometry initialisation steps), `RIGCAL_SCALE` (image scale, 0.125),
//! `RIGCAL_RGB_WEIGHT`, `RIGCAL_INTENSITY_WEIGHT`, `RIGCAL_VIEW=false` (view-independent
//! surface colour), `RIGCAL_TRANSLATION_RATE` (camera translation rate over the rotation's), `RIGCAL_SHARED_TRANSLATION=true` (a translation the cameras share, `calibrate --shared-camera-translation`),
//! `RIGCAL_CAMERA_DECAY` (the camera pose rate's final fraction), `RIGCAL_OPACITY=interval|per-sample`
//! (the opacity model), `RIGCAL_BETA` (β's initial value), `RIGCAL_ROUNDS` (rounds of
//! ITERATIONS, each with a fresh scene at the cameras the last one reached; as `calibrate
//! --rounds`), `RIGCAL_SILHOUETTE` (share of
//! heat-map draws around LiDAR silhouettes), `RIGCAL_UNIFORM` (share of uniform draws once the
//! heat maps are on), `RIGCAL_C2F=LEVELS,FRACTION|off` (coarse-to-fine hash grid; the preset's by default), `RIGCAL_VECTORS` (print every
//! camera's error vector and their mean). Frozen-scene probe: with `RIGCAL_PROBE=N` the cameras
//! start at the truth and the scene learns for N iterations (poses fixed), then the cameras
//! jump to their start and only their poses move (the scene frozen unless `RIGCAL_JOINT` is
//! set).

use std::path::PathBuf;

#[allow(dead_code)] // only the opacity setting is read here
mod common;

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
    // The native file or a dataset's JSON (PandaSet's `ground_truth.json`).
    let truth = rigcal::calib::dataset_json::load_reference(&PathBuf::from(&args[2])).unwrap();
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
        pose_ramp: env("RIGCAL_RAMP", defaults.pose_ramp),
        alignment_release: std::env::var("RIGCAL_ALIGN_RELEASE")
            .ok()
            .and_then(|v| v.parse().ok())
            .or(defaults.alignment_release),
        alignment_release_rate: env("RIGCAL_ALIGN_RELEASE_RATE", defaults.alignment_release_rate),
        geometry_init_steps: env("RIGCAL_INIT_STEPS", defaults.geometry_init_steps),
        alignment: env("RIGCAL_ALIGN", defaults.alignment),
        alignment_weight: env("RIGCAL_ALIGN_WEIGHT", defaults.alignment_weight),
        alignment_settings: settings,
        rgb_weight: env("RIGCAL_RGB_WEIGHT", defaults.rgb_weight),
        intensity_weight: env("RIGCAL_INTENSITY_WEIGHT", defaults.intensity_weight),
        view_dependent_colour: env("RIGCAL_VIEW", defaults.view_dependent_colour),
        camera_translation_rate: env("RIGCAL_TRANSLATION_RATE", defaults.camera_translation_rate),
        shared_camera_translation: env(
            "RIGCAL_SHARED_TRANSLATION",
            defaults.shared_camera_translation,
        ),
        camera_pose_final_fraction: env("RIGCAL_CAMERA_DECAY", defaults.camera_pose_final_fraction),
        silhouette_share: env("RIGCAL_SILHOUETTE", defaults.silhouette_share),
        // `LEVELS,FRACTION` or `off`, as `calibrate --coarse-to-fine`.
        coarse_to_fine: std::env::var("RIGCAL_C2F")
            .map_or(Ok(defaults.coarse_to_fine), |v| {
                rigcal::unical::depth_calib::CoarseToFine::parse_setting(&v)
            })
            .expect("RIGCAL_C2F"),
        heatmap_uniform_share: env("RIGCAL_UNIFORM", defaults.heatmap_uniform_share),
        opacity: common::opacity_from_env(defaults.opacity),
        beta_init: env("RIGCAL_BETA", defaults.beta_init),
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
    let (mut colour, mut align, mut kept, mut n) = (0.0, 0.0, 0usize, 0usize);
    let rounds: usize = env("RIGCAL_ROUNDS", 1);
    // How soon the extrinsics first move (issue 5: within 5 s of the optimisation starting).
    let initial_extrinsics = stage.calibration().extrinsics();
    let (mut optimisation_start, mut moved) = (None::<std::time::Instant>, false);
    for it in 0..iterations * rounds.max(1) {
        if it > 0 && it % iterations == 0 {
            stage.calibration_mut().restart();
            println!(
                "round {}: a fresh scene at the cameras reached",
                it / iterations + 1
            );
        }
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
        let started = *optimisation_start.get_or_insert_with(std::time::Instant::now);
        let r = stage.calibration_mut().step();
        if !moved && stage.calibration().extrinsics() != initial_extrinsics {
            moved = true;
            println!(
                "first extrinsic change: iteration {}, {:.2} s into the optimisation",
                it + 1,
                started.elapsed().as_secs_f64()
            );
        }
        colour += r.colour_loss;
        align += r.alignment_loss;
        kept += r.alignment_matches;
        n += 1;
        if (it + 1) % every == 0 || (it + 1) % iterations == 0 {
            let per = camera_errors(&stage, &truth);
            let k = per.len().max(1) as f64;
            let (rot, tr) = per.iter().fold((0.0, 0.0), |(a, b), e| {
                (a + e.rotation_deg.length(), b + e.translation_cm.length())
            });
            let each: Vec<String> = per
                .iter()
                .map(|e| {
                    format!(
                        "{:.2}/{:.1}",
                        e.rotation_deg.length(),
                        e.translation_cm.length()
                    )
                })
                .collect();
            println!(
                "{:5} {:6.1}s cameras {:.3}° {:.2} cm | colour {:.5} align {:.2} kept {:.1} β {:.0} | {}",
                it + 1,
                t0.elapsed().as_secs_f64(),
                rot / k,
                tr / k,
                colour / n as f64,
                align / n as f64,
                kept as f64 / n as f64,
                stage.calibration().beta(),
                each.join(" ")
            );
            (colour, align, kept, n) = (0.0, 0.0, 0, 0);
            if std::env::var("RIGCAL_VECTORS").is_ok() {
                print_error_vectors(&per);
            }
        }
    }
}

/// A camera's error as vectors in the vehicle frame: translation, estimated − true camera
/// centre (cm); rotation, log(R_est R_true⁻¹) (degrees; its length is the rotation error).
struct CameraError {
    name: String,
    translation_cm: glam::DVec3,
    rotation_deg: glam::DVec3,
}

fn camera_errors(stage: &UnicalLidarStage, truth: &rigcal::calib::Rig) -> Vec<CameraError> {
    stage
        .calibration()
        .extrinsics()
        .into_iter()
        .filter_map(|(name, t)| {
            let s = truth.sensor(&name).filter(|s| s.camera.is_some())?;
            let rotation = t.rotation * s.vehicle_from_sensor.rotation.conjugate();
            Some(CameraError {
                translation_cm: (t.translation - s.vehicle_from_sensor.translation) * 100.0,
                rotation_deg: rigcal::geometry::so3::log(rotation) * (180.0 / std::f64::consts::PI),
                name,
            })
        })
        .collect()
}

/// Every camera's error vectors and their mean over the cameras: a common part is an offset
/// every camera shares, which the learned texture can follow.
fn print_error_vectors(errors: &[CameraError]) {
    let line = |name: &str, t: glam::DVec3, r: glam::DVec3| {
        println!(
            "      {name:>20} dt ({:6.2} {:6.2} {:6.2}) cm  dr ({:6.3} {:6.3} {:6.3})°",
            t.x, t.y, t.z, r.x, r.y, r.z
        );
    };
    for e in errors {
        line(&e.name, e.translation_cm, e.rotation_deg);
    }
    let k = errors.len().max(1) as f64;
    line(
        "mean",
        errors.iter().map(|e| e.translation_cm).sum::<glam::DVec3>() / k,
        errors.iter().map(|e| e.rotation_deg).sum::<glam::DVec3>() / k,
    );
}
