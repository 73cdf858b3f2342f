//! Running one bench case: get its drive (simulated once into the bench's `drives/` folder, or
//! a recorded log), start from the reference perturbed by the case's rotation and translation
//! (seeded, every sensor), step the method to the end, and measure against the reference after
//! root alignment (method.md §13) after every step, so the report has convergence curves.
//!
//! UniCal runs with cameras also render a held-out camera frame (the frame of the first camera
//! farthest from every training frame) with the fitted scene and compare it with the recorded
//! image: PSNR and SSIM at the resolution the camera trained at.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use super::suite::{Case, DriveSpec, Method, UnicalSettings};
use crate::calib::dataset_json::load_reference;
use crate::calib::{Rig, SensorKind};
use crate::eval::photometric::{psnr, ssim};
use crate::geometry::rig_errors;
use crate::log::{Drive, spread_evenly};
use crate::optim::edge_refine::EdgeRefiner;
use crate::optim::runner::Calibrator;
use crate::sim::rigs::{RigPreset, SimRig};
use crate::sim::synth::{SynthConfig, perturb_rig, synthesize};
use crate::unical::calibrator::{UnicalLidarStage, training_stamps};
use crate::unical::depth_calib::DepthCalibConfig;
use crate::unical::pose_newton::{NewtonConfig, PoseUpdate};

/// One sensor's error against the reference after root alignment.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SensorResult {
    pub sensor: String,
    pub kind: &'static str,
    /// Whether the method estimates this sensor (the others keep their initial guess).
    pub optimised: bool,
    pub initial_rotation_deg: f64,
    pub initial_translation_cm: f64,
    pub final_rotation_deg: f64,
    pub final_translation_cm: f64,
    /// How far the method moved the sensor's own extrinsic from its start (no alignment).
    pub moved_deg: f64,
    pub moved_cm: f64,
}

/// Mean errors of the optimised cameras and non-root LiDARs at one step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Errors {
    pub camera_rotation_deg: Option<f64>,
    pub camera_translation_cm: Option<f64>,
    pub lidar_rotation_deg: Option<f64>,
    pub lidar_translation_cm: Option<f64>,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CurvePoint {
    pub step: usize,
    /// Seconds since the optimisation started (preparation excluded).
    pub seconds: f64,
    pub errors: Errors,
}

/// What one run gave.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CaseResult {
    pub key: String,
    pub method: String,
    pub drive: String,
    pub perturb_deg: f64,
    pub perturb_cm: f64,
    pub seed: u64,
    pub root: String,
    pub sensors: Vec<SensorResult>,
    pub initial: Errors,
    pub result: Errors,
    pub steps: usize,
    /// Loading the drive and preparing the method (simulating a drive not included).
    pub prepare_secs: f64,
    /// The optimisation itself.
    pub run_secs: f64,
    pub curve: Vec<CurvePoint>,
    /// Held-out frame rendered by the fitted scene (UniCal with cameras).
    pub photometric: Option<Photometric>,
    /// Why the run failed, if it did (the rest of the suite still runs).
    pub error: Option<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Photometric {
    pub camera: String,
    pub frame: usize,
    pub width: u32,
    pub height: u32,
    pub psnr_db: f64,
    pub ssim: f64,
}

impl CaseResult {
    /// A result with nothing measured yet (`error`: why the run could not happen).
    pub fn failed(case: &Case, error: Option<String>) -> Self {
        Self {
            key: case.key(),
            method: case.method.label().into(),
            drive: case.drive.name(),
            perturb_deg: case.perturb_deg,
            perturb_cm: case.perturb_cm,
            seed: case.seed,
            root: String::new(),
            sensors: Vec::new(),
            initial: Errors::default(),
            result: Errors::default(),
            steps: 0,
            prepare_secs: 0.0,
            run_secs: 0.0,
            curve: Vec::new(),
            photometric: None,
            error,
        }
    }
}

/// The drive's MCAP and reference, simulating it first if it is not in `drives_dir`.
pub fn ensure_drive(
    spec: &DriveSpec,
    drives_dir: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(PathBuf, PathBuf), super::BenchError> {
    match spec {
        DriveSpec::Log { mcap, ground_truth } => Ok((mcap.clone(), ground_truth.clone())),
        DriveSpec::Sim {
            scene,
            trajectory,
            seconds,
            scale,
            seed,
        } => {
            let name = spec.name();
            let mcap = drives_dir.join(format!("{name}.mcap"));
            let gt = drives_dir.join(format!("{name}-ground-truth.yaml"));
            if mcap.is_file() && gt.is_file() {
                return Ok((mcap, gt));
            }
            std::fs::create_dir_all(drives_dir)
                .map_err(|e| format!("cannot create {}: {e}", drives_dir.display()))?;
            let mut cfg = SynthConfig::new(
                *scene,
                SimRig::preset(RigPreset::Pandaset),
                *trajectory,
                *seconds,
                *seed,
            );
            cfg.scale = *scale;
            synthesize(&cfg, &mcap, &gt, progress).map_err(|source| {
                super::BenchError::Simulate {
                    name: name.to_string(),
                    source,
                }
            })?;
            Ok((mcap, gt))
        }
    }
}

/// Run `case` on its drive; `progress(step, steps)` after every step. Failures are reported in
/// [`CaseResult::error`].
pub fn run_case(
    case: &Case,
    mcap: &Path,
    ground_truth: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> CaseResult {
    let mut out = CaseResult::failed(case, None);
    if let Err(e) = run_into(case, mcap, ground_truth, progress, &mut out) {
        out.error = Some(e);
    }
    out
}

fn run_into(
    case: &Case,
    mcap: &Path,
    ground_truth: &Path,
    progress: &mut dyn FnMut(usize, usize),
    out: &mut CaseResult,
) -> Result<(), String> {
    let started = Instant::now();
    let drive = Drive::open(mcap).map_err(|e| e.to_string())?;
    let reference = load_reference(ground_truth).map_err(|e| e.to_string())?;
    // Errors are relative to the first LiDAR, or the first camera when the method leaves the
    // LiDARs alone (camera-only: the cameras cannot know where a LiDAR is).
    let camera_root = matches!(&case.method, Method::UniCal(s) if !s.lidar_supervision);
    let (kind, candidates) = if camera_root {
        ("camera", reference.cameras().collect::<Vec<_>>())
    } else {
        ("LiDAR", reference.lidars().collect())
    };
    out.root = candidates
        .iter()
        .map(|s| s.name.clone())
        .find(|n| drive.rig.sensor(n).is_some())
        .ok_or_else(|| {
            format!(
                "{} has no {kind} of {}",
                mcap.display(),
                ground_truth.display()
            )
        })?;
    let perturbed = perturb_rig(&reference, case.perturb_deg, case.perturb_cm, case.seed);
    let mut initial = drive.rig.clone();
    for s in &mut initial.sensors {
        if let Some(p) = perturbed.sensor(&s.name) {
            s.vehicle_from_sensor = p.vehicle_from_sensor;
        }
    }
    match &case.method {
        Method::Pipeline(config) => {
            let drive = std::sync::Arc::new(drive);
            let plan = crate::pipeline::Plan::build(
                &drive,
                &initial,
                &crate::pipeline::PlanRequest::default(),
                &crate::pipeline::PipelineConfig {
                    seed: case.seed,
                    ..(**config).clone()
                },
            )
            .map_err(|e| e.to_string())?;
            let optimised: Vec<String> = initial.sensors.iter().map(|s| s.name.clone()).collect();
            let mut run = crate::pipeline::calibrator::PipelineCalibrator::prepare(
                drive,
                initial.clone(),
                plan,
                started,
                &|_, _, _| {},
            )
            .map_err(|e| e.to_string())?;
            out.prepare_secs = started.elapsed().as_secs_f64();
            optimise(&mut run, &reference, &initial, &optimised, progress, out)?;
        }
        Method::UniCal(settings) => {
            let mut stage = unical_stage(&drive, &initial, settings, case.seed)?;
            let mut optimised: Vec<String> = Vec::new();
            if settings.lidar_supervision {
                optimised.extend(initial.lidars().map(|s| s.name.clone()));
            }
            if settings.camera_frames > 0 {
                optimised.extend(initial.cameras().map(|s| s.name.clone()));
            }
            out.prepare_secs = started.elapsed().as_secs_f64();
            optimise(&mut stage, &reference, &initial, &optimised, progress, out)?;
            if settings.camera_frames > 0 {
                out.photometric = held_out_photometric(&stage, &drive, settings.camera_frames);
            }
        }
        Method::Edge { frames, max_steps } => {
            let cameras: Vec<String> = initial
                .cameras()
                .filter(|c| c.camera.is_some())
                .map(|c| c.name.clone())
                .collect();
            let mut refiner = EdgeRefiner::new(
                &drive,
                &initial,
                (&out.root, &cameras),
                *frames,
                &[],
                drive.camera_readout,
            )
            .map_err(|e| e.to_string())?
            .with_max_steps(*max_steps);
            out.prepare_secs = started.elapsed().as_secs_f64();
            optimise(&mut refiner, &reference, &initial, &cameras, progress, out)?;
        }
    }
    Ok(())
}

/// Step `calibrator` to its end, measuring after every step.
fn optimise(
    calibrator: &mut dyn Calibrator,
    reference: &Rig,
    initial: &Rig,
    optimised: &[String],
    progress: &mut dyn FnMut(usize, usize),
    out: &mut CaseResult,
) -> Result<(), String> {
    // A NaN or an infinity ends the case with the best result before it, and fails it.
    let mut calibrator = crate::optim::divergence::Guarded::new(calibrator);
    let root = out.root.clone();
    let measure = |rig: &Rig| mean_errors(reference, rig, &root, optimised);
    out.initial = measure(initial)?;
    let steps = calibrator.max_steps();
    let run_started = Instant::now();
    out.curve.push(CurvePoint {
        step: 0,
        seconds: 0.0,
        errors: out.initial,
    });
    for step in 1..=steps {
        let report = calibrator.step();
        out.curve.push(CurvePoint {
            step,
            seconds: run_started.elapsed().as_secs_f64(),
            errors: measure(&calibrator.current())?,
        });
        out.steps = step;
        progress(step, steps);
        if report.done {
            break;
        }
    }
    out.run_secs = run_started.elapsed().as_secs_f64();
    let best = calibrator.best();
    out.result = measure(&best)?;
    out.sensors = sensor_results(reference, initial, &best, &root, optimised)?;
    match calibrator.diverged() {
        Some(why) => Err(why.to_owned()),
        None => Ok(()),
    }
}

fn unical_stage(
    drive: &Drive,
    rig: &Rig,
    s: &UnicalSettings,
    seed: u64,
) -> Result<UnicalLidarStage, String> {
    let lidar = s.lidar_supervision;
    let config = DepthCalibConfig {
        iterations: s.iterations,
        geometry_init_steps: if lidar { s.geometry_init_steps } else { 0 },
        geometry_init_rays: s.geometry_init_rays,
        pose_warmup: s.pose_warmup,
        pose_ramp: s.pose_ramp,
        rays_per_sensor: if lidar { s.rays_per_sensor } else { 0 },
        rays_per_camera: s.rays_per_camera,
        lidar_pose_update: if s.newton_lidar_poses {
            PoseUpdate::Newton(NewtonConfig::default())
        } else {
            PoseUpdate::Adam
        },
        alignment: s.alignment,
        seed,
        ..DepthCalibConfig::default()
    };
    let covered = training_stamps(drive, rig, s.camera_frames, &[]);
    UnicalLidarStage::from_drive_covering(drive, rig, s.sweeps_per_lidar, &[], &covered, config)
        .map_err(|e| e.to_string())?
        .with_cameras(drive, s.camera_frames, &[], s.camera_scale)
        .map_err(|e| e.to_string())
}

/// Mean errors of the optimised sensors (the root excluded) of `rig` against `reference`.
fn mean_errors(
    reference: &Rig,
    rig: &Rig,
    root: &str,
    optimised: &[String],
) -> Result<Errors, String> {
    let errors = rig_errors(&reference.extrinsics(), &rig.extrinsics(), root)
        .ok_or_else(|| format!("the root sensor {root} is missing"))?;
    let mean = |kind: SensorKind| {
        let picked: Vec<_> = errors
            .iter()
            .filter(|e| e.sensor != root && optimised.contains(&e.sensor))
            .filter(|e| reference.sensor(&e.sensor).is_some_and(|s| s.kind == kind))
            .collect();
        if picked.is_empty() {
            return (None, None);
        }
        let n = picked.len() as f64;
        (
            Some(picked.iter().map(|e| e.rotation_deg).sum::<f64>() / n),
            Some(picked.iter().map(|e| e.translation_m * 100.0).sum::<f64>() / n),
        )
    };
    let (camera_rotation_deg, camera_translation_cm) = mean(SensorKind::Camera);
    let (lidar_rotation_deg, lidar_translation_cm) = mean(SensorKind::Lidar);
    Ok(Errors {
        camera_rotation_deg,
        camera_translation_cm,
        lidar_rotation_deg,
        lidar_translation_cm,
    })
}

fn sensor_results(
    reference: &Rig,
    initial: &Rig,
    result: &Rig,
    root: &str,
    optimised: &[String],
) -> Result<Vec<SensorResult>, String> {
    let missing = || format!("the root sensor {root} is missing");
    let before =
        rig_errors(&reference.extrinsics(), &initial.extrinsics(), root).ok_or_else(missing)?;
    let after =
        rig_errors(&reference.extrinsics(), &result.extrinsics(), root).ok_or_else(missing)?;
    Ok(before
        .iter()
        .filter_map(|b| {
            let a = after.iter().find(|a| a.sensor == b.sensor)?;
            let (moved_rad, moved_m) = initial
                .sensor(&b.sensor)?
                .vehicle_from_sensor
                .difference(result.sensor(&b.sensor)?.vehicle_from_sensor);
            let kind = match reference.sensor(&b.sensor)?.kind {
                SensorKind::Camera => "camera",
                SensorKind::Lidar => "lidar",
            };
            Some(SensorResult {
                sensor: b.sensor.clone(),
                kind,
                optimised: b.sensor != root && optimised.contains(&b.sensor),
                initial_rotation_deg: b.rotation_deg,
                initial_translation_cm: b.translation_m * 100.0,
                final_rotation_deg: a.rotation_deg,
                final_translation_cm: a.translation_m * 100.0,
                moved_deg: moved_rad.to_degrees(),
                moved_cm: moved_m * 100.0,
            })
        })
        .collect())
}

/// Render the first camera's held-out frame (farthest from its training frames) with the fitted
/// scene and compare it with the recorded image.
pub fn held_out_photometric(
    stage: &UnicalLidarStage,
    drive: &Drive,
    frames_per_camera: usize,
) -> Option<Photometric> {
    let calib = stage.calibration();
    let (name, intrinsics) = drive
        .rig
        .cameras()
        .find_map(|c| Some((c.name.clone(), calib.camera_intrinsics(&c.name)?.clone())))?;
    let usable = drive.frames_within(&name, &[]);
    let training = spread_evenly(&usable, frames_per_camera);
    let distance = |i: usize| training.iter().map(|t| t.abs_diff(i)).min().unwrap_or(0);
    let mut candidates: Vec<usize> = usable
        .iter()
        .copied()
        .filter(|i| !training.contains(i))
        .collect();
    candidates.sort_by_key(|i| std::cmp::Reverse(distance(*i)));
    let stream = drive.stream(&name)?;
    for frame in candidates {
        let stamp = stream.frames.get(frame)?.stamp_nanos;
        let Some((w, h, rendered)) = calib.render_camera(&name, stamp) else {
            continue;
        };
        let Ok(img) = drive.load_image(&name, frame) else {
            continue;
        };
        // Against the sharp image, whatever blur the run's targets had.
        let observed =
            crate::unical::calibrator::working_image(img.as_ref(), &intrinsics).into_raw();
        return Some(Photometric {
            camera: name,
            frame,
            width: w,
            height: h,
            psnr_db: psnr(&rendered, &observed)?,
            ssim: ssim(&rendered, &observed, w as usize, h as usize, 3)?,
        });
    }
    None
}
