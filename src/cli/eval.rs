//! `rigcal eval`: measure a calibration against a reference (method.md §13).
//!
//! Always: every sensor's rotation (°) and translation (cm) error after aligning the root
//! sensor ([`crate::geometry::rig_errors`]). With a log, also measured on the data, for the
//! calibration and for the reference side by side (so a user sees how far the data itself
//! can tell them apart): the LiDAR–LiDAR point-to-plane error of every LiDAR pair
//! ([`crate::eval::registration`], cm, 30 cm inliers), the target-free edge-alignment score of
//! every camera–LiDAR pair ([`crate::optim::edge_align`], px), and with `--checkerboard` the
//! checkerboard corner re-projection error ([`crate::eval::checkerboard`], px, scaled to a
//! 1920-pixel-wide image as the paper reports it). With `--photometric`, for every camera also the texture-free
//! photometric consistency of its images over the LiDAR map
//! ([`crate::optim::photo_consistency`]: the mean variance of each LiDAR point's normalised grey
//! over the images that see it, ×1000) and the delay of the images (ms, −60 to +60 in 10 ms
//! steps) at which that consistency is best: a delay far from 0 says the images are stamped
//! late or early, or (the same thing while the vehicle drives at one speed) that the camera
//! sits off along the drive; and the focal-length scale (0.98 to 1.02) at which it is best: a
//! scale away from 1 says the intrinsics' focal length is off, or (the same thing to one
//! camera's images) that the camera sits off along its optical axis. With
//! `--camera-readout-ms` the edge-alignment and photometric metrics place each image row at its
//! own time (a rolling shutter); the checkerboard metric still projects at the stamp.

use super::CliError;
use std::path::PathBuf;

use serde::Serialize;

use crate::calib::dataset_json::load_reference;
use crate::calib::{CalibrationFile, Rig, SensorKind};
use crate::eval::checkerboard::{BoardSpec, pair_corner_error};
use crate::eval::registration::{RegistrationError, pair_registration_errors};
use crate::geometry::{RigError, RowTimes, rig_errors};
use crate::log::Drive;
use crate::optim::edge_align::EdgeAlignment;
use crate::optim::photo_consistency::{PhotoConfig, PhotoProblem, lidar_map};

/// The most frames per sensor pair `--frames` takes: each frame costs a sweep's registration
/// or an image's edge search, so more is hours of work, and a larger number is a slip.
pub const MAX_FRAMES: usize = 1000;

// What `rigcal eval` was asked to do: its options, defined once (clap derives the flags; a
// plain comment, as clap would take a doc comment for the subcommand's description).
#[derive(Clone, Debug, clap::Args)]
pub struct EvalArgs {
    /// The reference: a native calibration file or a dataset's ground_truth.json.
    #[arg(long)]
    pub ground_truth: PathBuf,
    /// The calibration to measure (native file).
    #[arg(long)]
    pub calibration: PathBuf,
    /// A log to measure the alignment on.
    pub log: Option<PathBuf>,
    /// Root sensor for the alignment (default: the reference's first LiDAR).
    #[arg(long)]
    pub root: Option<String>,
    /// Frames per sensor pair for the data metrics (1–1000).
    #[arg(long, default_value_t = 3)]
    pub frames: usize,
    /// Also measure the checkerboard corner re-projection error (logs with boards).
    #[arg(long)]
    pub checkerboard: bool,
    /// Also measure every camera's photometric consistency over the LiDAR map (texture-free)
    /// and the image delay at which it is best
    #[arg(long)]
    pub photometric: bool,
    /// With a log: the cameras have a rolling shutter whose readout began FIRST and ended
    /// LAST milliseconds after each image's stamp (as calibrate's option of that name), for
    /// the edge-alignment and photometric metrics
    #[arg(long, value_name = "FIRST..LAST", allow_hyphen_values = true)]
    pub camera_readout_ms: Option<String>,
    /// Also write the report as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

impl Default for EvalArgs {
    /// The CLI's defaults: 3 frames per pair, no log.
    fn default() -> Self {
        Self {
            ground_truth: PathBuf::new(),
            calibration: PathBuf::new(),
            log: None,
            root: None,
            frames: 3,
            checkerboard: false,
            photometric: false,
            camera_readout_ms: None,
            json: None,
        }
    }
}

/// `rigcal eval`: the report as Markdown on standard output (a progress bar while the data
/// metrics run), and as JSON where `--json` asks.
pub fn run(args: &EvalArgs) -> anyhow::Result<()> {
    use anyhow::Context;
    let mut bar = super::progress::Progress::new("eval", 1);
    let report = evaluate(args, &mut |done, total| bar.report(done, total))
        .map_err(anyhow::Error::msg)
        .context("cannot evaluate")?;
    bar.finish();
    super::print_stdout(&report.to_markdown())?;
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report)?;
        crate::util::write_atomic(path, text.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

/// One metric of one sensor pair, for the calibration and for the reference.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct PairMetric {
    pub a: String,
    pub b: String,
    pub calibration: Option<f64>,
    pub reference: Option<f64>,
    /// Why a value is missing, if one is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct EvalReport {
    pub reference: PathBuf,
    pub calibration: PathBuf,
    pub root: String,
    pub poses: Vec<RigError>,
    /// With a log: the same errors for the log's own extrinsics (the initial guess a
    /// calibration starts from), so each axis can be compared with where it began.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub initial: Vec<RigError>,
    /// Reference sensors the calibration does not have.
    pub missing: Vec<String>,
    /// LiDAR–LiDAR point-to-plane error (cm).
    pub registration_cm: Vec<PairMetric>,
    /// Camera–LiDAR edge-alignment score (px).
    pub edge_px: Vec<PairMetric>,
    /// Camera–LiDAR checkerboard corner error (px at 1920 wide).
    pub corners_px: Vec<PairMetric>,
    /// Camera × LiDAR map: photometric inconsistency (×1000, lower is better).
    pub photo_inconsistency: Vec<PairMetric>,
    /// Camera × LiDAR map: the image delay (ms) at which the images agree best.
    pub photo_delay_ms: Vec<PairMetric>,
    /// Camera × LiDAR map: the focal-length scale at which the images agree best
    /// ([`PhotoProblem::best_focal_scale`]).
    pub photo_focal_scale: Vec<PairMetric>,
}

/// Run the evaluation; `progress(done, total)` after each data metric.
pub fn evaluate(
    args: &EvalArgs,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<EvalReport, CliError> {
    if !(1..=MAX_FRAMES).contains(&args.frames) {
        return Err(format!("--frames must be 1–{MAX_FRAMES}, got {}", args.frames).into());
    }
    let reference = load_reference(&args.ground_truth)?;
    let calibration = CalibrationFile::load_rig(&args.calibration)?;
    let common = |name: &str| calibration.sensor(name).is_some();
    let root = match &args.root {
        Some(r) if reference.sensor(r).is_some() && common(r) => r.clone(),
        Some(r) => {
            return Err(format!(
                "--root '{r}' is not a sensor of both {} and {}",
                args.ground_truth.display(),
                args.calibration.display()
            )
            .into());
        }
        None => reference
            .lidars()
            .chain(reference.cameras())
            .map(|s| s.name.clone())
            .find(|n| common(n))
            .ok_or_else(|| {
                format!(
                    "{} and {} have no sensor in common",
                    args.ground_truth.display(),
                    args.calibration.display()
                )
            })?,
    };
    let poses = rig_errors(&reference.extrinsics(), &calibration.extrinsics(), &root)
        .ok_or("the root sensor vanished")?;
    let missing = reference
        .sensors
        .iter()
        .filter(|s| !common(&s.name))
        .map(|s| s.name.clone())
        .collect();
    let mut report = EvalReport {
        reference: args.ground_truth.clone(),
        calibration: args.calibration.clone(),
        root,
        poses,
        initial: Vec::new(),
        missing,
        registration_cm: Vec::new(),
        edge_px: Vec::new(),
        corners_px: Vec::new(),
        photo_inconsistency: Vec::new(),
        photo_delay_ms: Vec::new(),
        photo_focal_scale: Vec::new(),
    };
    let camera_readout = match &args.camera_readout_ms {
        None => RowTimes::GLOBAL,
        Some(_) if args.log.is_none() => {
            return Err(
                "--camera-readout-ms applies to the metrics measured on a log: give one".into(),
            );
        }
        Some(text) => super::calibrate::parse_readout(text)?,
    };
    if let Some(log) = &args.log {
        // The readout places each image row of the edge-alignment and photometric metrics at
        // its own time, and leaves out of them the images with rows outside the trajectory.
        let options = crate::log::DriveOptions {
            camera_readout,
            ..crate::log::DriveOptions::default()
        };
        let drive = Drive::open_with(log, &options)?;
        if !calibration
            .sensors
            .iter()
            .any(|s| drive.stream(&s.name).is_some())
        {
            let in_log: Vec<&str> = drive.rig.sensors.iter().map(|s| s.name.as_str()).collect();
            return Err(format!(
                "{} has none of the sensors of {} (the log's: {}); is it the right log?",
                log.display(),
                args.calibration.display(),
                if in_log.is_empty() {
                    "none".to_string()
                } else {
                    in_log.join(", ")
                }
            )
            .into());
        }
        // The log's extrinsics against the reference, with the same root (when the log has it).
        report.initial = rig_errors(
            &reference.extrinsics(),
            &drive.rig.extrinsics(),
            &report.root,
        )
        .unwrap_or_default();
        measure_on_data(
            args,
            &drive,
            &reference,
            &calibration,
            &mut report,
            progress,
        );
        // Frames that did not decode were left out of the metrics.
        if let Some(line) = drive.skipped_summary() {
            eprintln!("{line}");
        }
    }
    Ok(report)
}

/// The data metrics of every pair, with the calibration and with the reference (its
/// extrinsics placed into the calibration's rig, so intrinsics are the same on both sides).
fn measure_on_data(
    args: &EvalArgs,
    drive: &Drive,
    reference: &Rig,
    calibration: &Rig,
    report: &mut EvalReport,
    progress: &mut dyn FnMut(usize, usize),
) {
    let mut reference_rig = calibration.clone();
    for s in &mut reference_rig.sensors {
        if let Some(r) = reference.sensor(&s.name) {
            s.vehicle_from_sensor = r.vehicle_from_sensor;
        }
    }
    let names = |kind| -> Vec<String> {
        calibration
            .sensors
            .iter()
            .filter(|s| s.kind == kind && drive.stream(&s.name).is_some())
            .map(|s| s.name.clone())
            .collect()
    };
    let (lidars, cameras) = (names(SensorKind::Lidar), names(SensorKind::Camera));
    let lidar_pairs: Vec<(String, String)> = lidars
        .iter()
        .enumerate()
        .flat_map(|(i, a)| lidars[i + 1..].iter().map(move |b| (a.clone(), b.clone())))
        .collect();
    let camera_pairs: Vec<(String, String)> = cameras
        .iter()
        .flat_map(|c| lidars.iter().map(move |l| (c.clone(), l.clone())))
        .collect();
    let per_pair = 1 + args.checkerboard as usize;
    let total = lidar_pairs.len()
        + camera_pairs.len() * per_pair
        + cameras.len() * args.photometric as usize;
    let mut done = 0;
    let frames = args.frames.max(1);
    for (a, b) in lidar_pairs {
        let rigs = [calibration, &reference_rig];
        let cm = |e: &Option<_>| e.as_ref().map(|e: &RegistrationError| e.mean_cm);
        let (c, r) = match pair_registration_errors(drive, &rigs, &a, &b, frames, 4) {
            Ok(v) => (Ok(cm(&v[0])), Ok(cm(&v[1]))),
            Err(e) => (Err(e.to_string()), Err(e.to_string())),
        };
        report
            .registration_cm
            .push(metric(&a, &b, c, r, "no planar overlap within 30 cm"));
        done += 1;
        progress(done, total);
    }
    for (cam, lidar) in &camera_pairs {
        let run = |rig: &Rig| {
            EdgeAlignment::score_rig(drive, rig, (cam, lidar), frames, &[], drive.camera_readout)
                .map(|(px, _)| Some(px))
                .map_err(|e| e.to_string())
        };
        report.edge_px.push(metric(
            cam,
            lidar,
            run(calibration),
            run(&reference_rig),
            "no silhouette in view",
        ));
        done += 1;
        progress(done, total);
    }
    if args.photometric {
        let config = PhotoConfig {
            images: frames.max(8),
            sweeps_per_lidar: frames.max(8),
            ..PhotoConfig::default()
        };
        // Each rig's LiDAR map once, for all its cameras.
        let rigs = [calibration, &reference_rig];
        let maps = rigs.map(|rig| lidar_map(drive, rig, &config).map_err(|e| e.to_string()));
        for cam in &cameras {
            let measure = |i: usize| match &maps[i] {
                Ok(map) => photo_metrics(drive, rigs[i], cam, map, &config),
                Err(e) => Err(e.clone()),
            };
            let (c, r) = (measure(0), measure(1));
            let part = |v: &Result<PhotoMetrics, String>, f: fn(&PhotoMetrics) -> Option<f64>| {
                v.as_ref().map(f).map_err(Clone::clone)
            };
            for (rows, f) in [
                (
                    &mut report.photo_inconsistency,
                    (|m| Some(m.inconsistency)) as fn(&PhotoMetrics) -> Option<f64>,
                ),
                (&mut report.photo_delay_ms, |m| Some(m.delay_ms)),
                (&mut report.photo_focal_scale, |m| m.focal_scale),
            ] {
                rows.push(metric(cam, "LiDAR map", part(&c, f), part(&r, f), ""));
            }
            done += 1;
            progress(done, total);
        }
    }
    if args.checkerboard {
        let spec = BoardSpec::default();
        for (cam, lidar) in &camera_pairs {
            let width = calibration
                .sensor(cam)
                .and_then(|s| s.camera.as_ref())
                .map_or(1920, |c| c.width);
            let to_1920 = 1920.0 / width.max(1) as f64;
            let run = |rig: &Rig| {
                pair_corner_error(drive, rig, cam, lidar, frames, &spec)
                    .map(|e| e.map(|e| e.mean_px * to_1920))
                    .map_err(|e| e.to_string())
            };
            report.corners_px.push(metric(
                cam,
                lidar,
                run(calibration),
                run(&reference_rig),
                "no board found in both",
            ));
            done += 1;
            progress(done, total);
        }
    }
}

/// Delays tried for [`photo_metrics`] (ms).
const PHOTO_DELAYS_MS: [i64; 13] = [-60, -50, -40, -30, -20, -10, 0, 10, 20, 30, 40, 50, 60];

/// What [`photo_metrics`] measures of one camera over the LiDAR map.
struct PhotoMetrics {
    /// Photometric inconsistency (×1000).
    inconsistency: f64,
    /// The image delay (ms) that minimises it.
    delay_ms: f64,
    /// The focal-length scale that minimises it ([`PhotoProblem::best_focal_scale`]).
    focal_scale: Option<f64>,
}

/// The photometric inconsistency of `camera`'s images over `map` (the LiDAR map of `rig`),
/// and the image delay and focal-length scale that minimise it.
fn photo_metrics(
    drive: &Drive,
    rig: &Rig,
    camera: &str,
    map: &[glam::DVec3],
    config: &PhotoConfig,
) -> Result<PhotoMetrics, String> {
    let problem =
        PhotoProblem::from_drive(drive, rig, camera, map, config).map_err(|e| e.to_string())?;
    let Some(vehicle_from_camera) = rig.sensor(camera).map(|s| s.vehicle_from_sensor) else {
        return Err(format!("no sensor '{camera}' in the rig"));
    };
    if problem.point_count() == 0 {
        return Err("no LiDAR point seen by three images".into());
    }
    let at = problem.cost(vehicle_from_camera);
    let mut best = (at, 0.0);
    for delay_ms in PHOTO_DELAYS_MS {
        let Some(delayed) = problem.delayed(&drive.trajectory, delay_ms * 1_000_000) else {
            continue;
        };
        let cost = delayed.cost(vehicle_from_camera);
        if cost < best.0 {
            best = (cost, delay_ms as f64);
        }
    }
    Ok(PhotoMetrics {
        inconsistency: at * 1000.0,
        delay_ms: best.1,
        focal_scale: problem.best_focal_scale(vehicle_from_camera),
    })
}

fn metric(
    a: &str,
    b: &str,
    calibration: Result<Option<f64>, String>,
    reference: Result<Option<f64>, String>,
    absent: &str,
) -> PairMetric {
    let note = match (&calibration, &reference) {
        (Err(e), _) | (_, Err(e)) => Some(e.clone()),
        (Ok(None), _) | (_, Ok(None)) => Some(absent.to_string()),
        _ => None,
    };
    PairMetric {
        a: a.to_string(),
        b: b.to_string(),
        calibration: calibration.ok().flatten(),
        reference: reference.ok().flatten(),
        note,
    }
}

impl EvalReport {
    /// The errors per axis of each sensor's own frame, with the log's initial guess beside
    /// them when a log was given.
    fn axes_markdown(&self) -> String {
        let mut out = String::from(
            "\nPer axis: rotation (°) about the sensor's own x, y, z; translation (cm) along its own x, y, z and along the vehicle's:\n\n\
             | sensor | of | rot x | rot y | rot z | x | y | z | vehicle x | vehicle y | vehicle z |\n\
             |---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        let row = |e: &RigError, of: &str| {
            let r = e.rotation_axes_deg;
            let t = e.translation_axes_m.map(|v| v * 100.0);
            let v = e.translation_vehicle_m.map(|v| v * 100.0);
            format!(
                "| {} | {of} | {:.3} | {:.3} | {:.3} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |\n",
                e.sensor, r[0], r[1], r[2], t[0], t[1], t[2], v[0], v[1], v[2]
            )
        };
        for e in self.poses.iter().filter(|e| e.sensor != self.root) {
            out += &row(e, "calibration");
            if let Some(i) = self.initial.iter().find(|i| i.sensor == e.sensor) {
                out += &row(i, "the log's initial guess");
            }
        }
        out
    }

    /// The report as Markdown tables.
    pub fn to_markdown(&self) -> String {
        let mut out = format!(
            "# {} against {}\n\nPose error after aligning the root sensor `{}`:\n\n\
             | sensor | rotation (°) | translation (cm) |\n|---|---:|---:|\n",
            self.calibration.display(),
            self.reference.display(),
            self.root
        );
        for e in &self.poses {
            out += &format!(
                "| {} | {:.4} | {:.2} |\n",
                e.sensor,
                e.rotation_deg,
                e.translation_m * 100.0
            );
        }
        let (n, r, t) = self
            .poses
            .iter()
            .filter(|e| e.sensor != self.root)
            .fold((0, 0.0, 0.0), |(n, r, t), e| {
                (n + 1, r + e.rotation_deg, t + e.translation_m)
            });
        if n > 0 {
            out += &format!(
                "| **mean (without root)** | **{:.4}** | **{:.2}** |\n",
                r / n as f64,
                t / n as f64 * 100.0
            );
        }
        out += &self.axes_markdown();
        if !self.missing.is_empty() {
            out += &format!("\nNot in the calibration: {}\n", self.missing.join(", "));
        }
        for (title, unit, rows) in [
            (
                "LiDAR–LiDAR point-to-plane error",
                "cm",
                &self.registration_cm,
            ),
            ("Camera–LiDAR edge-alignment score", "px", &self.edge_px),
            (
                "Camera–LiDAR checkerboard corner error (at 1920 px wide)",
                "px",
                &self.corners_px,
            ),
            (
                "Camera photometric inconsistency over the LiDAR map (×1000, texture-free; lower agrees better)",
                "×1000",
                &self.photo_inconsistency,
            ),
            (
                "Camera image delay at which the images agree best over the LiDAR map (or the camera sits off along the drive)",
                "ms",
                &self.photo_delay_ms,
            ),
            (
                "Camera focal-length scale at which the images agree best over the LiDAR map (or the camera sits off along its optical axis: 0.99 ≈ 10 cm back at 10 m)",
                "×",
                &self.photo_focal_scale,
            ),
        ] {
            if rows.is_empty() {
                continue;
            }
            out += &format!(
                "\n{title}:\n\n| pair | calibration ({unit}) | reference ({unit}) | note |\n|---|---:|---:|---|\n"
            );
            let digits = if unit == "×" { 4 } else { 2 };
            let cell = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.digits$}"));
            for m in rows {
                out += &format!(
                    "| {} × {} | {} | {} | {} |\n",
                    m.a,
                    m.b,
                    cell(m.calibration),
                    cell(m.reference),
                    m.note.as_deref().unwrap_or("")
                );
            }
        }
        out
    }
}
