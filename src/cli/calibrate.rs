//! `rigcal calibrate`: run a calibrator on a drive without the studio and write the native
//! calibration file (atomically), with provenance and the final losses as metrics.
//!
//! Methods available now: `edge` (cameras against a reference LiDAR by edge alignment,
//! rotation) and `unical` (UniCal: the scene and every LiDAR extrinsic from LiDAR depth,
//! intensity and the regulariser; with `--camera-frames N` the cameras join through the colour
//! term; `--root` keeps one sensor fixed).
//! `icp`: every LiDAR against the reference LiDAR (`--root`, default the first) by
//! point-to-plane ICP on three sweeps each. `mi`: every camera against the reference LiDAR by
//! mutual information. `target`: every camera against the reference LiDAR by checkerboard
//! edges and planes. `pose-graph`: every LiDAR pair by ICP and every camera–LiDAR pair by
//! checkerboards (or mutual information where there are none), unified by a pose graph with the
//! reference LiDAR fixed.

use std::path::PathBuf;

use crate::calib::{CalibrationFile, Rig, SensorKind};
use crate::classical::camera_motion;
use crate::classical::icp::IcpConfig;
use crate::classical::icp_calibrator::IcpCalibrator;
use crate::classical::mi_calibrator::MiCalibrator;
use crate::classical::mutual_info::MiConfig;
use crate::classical::pose_graph_calibrator::{PoseGraphCalibrator, PoseGraphConfig};
use crate::classical::target::TargetConfig;
use crate::classical::target_calibrator::TargetCalibrator;
use crate::classical::trajectory_icp::{MIN_TURN_DEG, TrajectoryFit, register_to_trajectory};
use crate::geometry::Rigid;
use crate::log::Drive;
use crate::optim::edge_refine::EdgeRefiner;
use crate::optim::runner::Calibrator;
use crate::unical::calibrator::UnicalLidarStage;
use crate::unical::depth_calib::{CoarseToFine, DepthCalibConfig};
use crate::unical::field::FieldConfig;
use crate::unical::hash_grid::HashGridConfig;
use crate::unical::surface_align::AlignmentLoss;

/// `--lidar-sweeps`, `--camera-scale` and `--camera-rays` when not given.
pub const DEFAULT_LIDAR_SWEEPS: usize = 4;
pub const DEFAULT_CAMERA_SCALE: f64 = 0.125;
pub const DEFAULT_CAMERA_RAYS: usize = 512;

/// What `rigcal calibrate` was asked to do.
#[derive(Clone, Debug)]
pub struct CalibrateArgs {
    pub log: PathBuf,
    pub method: String,
    pub init: Option<PathBuf>,
    /// Seconds from the start of the log, `START..END`.
    pub segment: Option<String>,
    /// Sensors to optimise (edge: cameras; default all).
    pub sensors: Vec<String>,
    pub iterations: Option<usize>,
    pub seed: u64,
    /// unical: images per camera for the colour term (0: LiDAR depth stage only).
    pub camera_frames: usize,
    /// unical: sweeps per LiDAR that shape the scene (at least 1).
    pub lidar_sweeps: usize,
    /// unical: drop LiDAR returns farther than this (m) from the drive before the scene box
    /// is formed.
    pub scene_radius_m: Option<f64>,
    /// unical: the sensor whose extrinsic stays fixed (default: none; the trajectory fixes the
    /// gauge).
    pub root: Option<String>,
    /// unical: the correspondence term between cameras (with `camera_frames` > 0).
    pub alignment: AlignmentLoss,
    /// unical: register the reference LiDAR (the root, else the first) to the trajectory by
    /// its own sweeps unless it is the root, and every other LiDAR to it by point-to-plane
    /// ICP, first; then hold the LiDARs (UniCal's joint objective moves a registered LiDAR
    /// pair centimetres off the truth; BENCHMARKS.md) while the cameras are calibrated.
    pub lidar_icp: bool,
    /// unical with cameras: fit each camera's extrinsic to its own motion first (hand-eye
    /// against the trajectory: the rotation, and the translation the drive's turns observe),
    /// for starts too far off for the scene (10°, a metre).
    pub camera_hand_eye: bool,
    /// unical with cameras: the scale images are used at, in (0, 1].
    pub camera_scale: f64,
    /// unical with cameras: rays per camera and step.
    pub camera_rays: usize,
    /// unical with cameras: the camera pose rate (default: [`DepthCalibConfig::default`]'s).
    pub camera_lr: Option<f32>,
    /// unical with cameras: the cameras' translation rate as a multiple of their rotation's
    /// (default: [`DepthCalibConfig::default`]'s).
    pub camera_translation_rate: Option<f32>,
    /// unical with cameras: what the cameras' translation rate decays to by the end, as a
    /// fraction of its start (default: as the rotation's;
    /// [`DepthCalibConfig::camera_translation_final_fraction`]).
    pub camera_translation_final: Option<f32>,
    /// unical with cameras: `ITER[,RATE]`, the cameras follow the correspondence term from
    /// iteration ITER of the geometry initialisation at RATE (default 0.1) times their rate
    /// ([`DepthCalibConfig::alignment_release`]); `None`: they wait for the warm-up.
    pub camera_early_release: Option<String>,
    /// unical: rounds of `iterations` each, every one with a fresh scene formed at the
    /// extrinsics the previous round reached (1: one run).
    pub rounds: usize,
    /// unical: `LEVELS,FRACTION` of a coarse-to-fine hash grid, or `off` (`None`: the CPU
    /// preset's).
    pub coarse_to_fine: Option<String>,
    /// unical with cameras: one translation shared by every camera besides their own
    /// ([`DepthCalibConfig::shared_camera_translation`]).
    pub shared_camera_translation: bool,
    /// unical with cameras: a camera's translation coordinates share Adam's step scale
    /// ([`DepthCalibConfig::grouped_camera_translation`]).
    pub grouped_camera_translation: bool,
    /// unical with cameras: camera rays only up to the LiDARs' highest beam
    /// ([`DepthCalibConfig::camera_rays_below_lidar_top`]).
    pub camera_rays_below_lidar_top: bool,
    /// unical with cameras: hold the directions the correspondence term hardly observes
    /// ([`DepthCalibConfig::camera_hold_unobserved`]); in (0, 1).
    pub camera_hold_unobserved: Option<f64>,
    /// unical with cameras: hold each camera's translation along its optical axis
    /// ([`DepthCalibConfig::camera_hold_axial`]).
    pub camera_hold_axial: bool,
    /// unical with cameras: share of the camera ray draws (heat maps on) centred on LiDAR silhouettes
    /// ([`DepthCalibConfig::silhouette_share`]; default the preset's); in [0, 1].
    pub silhouette_share: Option<f64>,
    /// unical with cameras: σ (working pixels) the images are blurred by before they become
    /// the colour term's target ([`DepthCalibConfig::camera_target_blur_px`]; default the
    /// preset's).
    pub camera_blur: Option<f64>,
    /// unical with cameras: the hash grids' coarsest levels the colour term's camera-pose
    /// gradient flows through ([`DepthCalibConfig::colour_pose_levels`]; default the preset's).
    pub colour_pose_levels: Option<f64>,
    /// unical: entries per level of the scene's hash table as a power of two
    /// ([`crate::unical::hash_grid::HashGridConfig::log2_table_size`]; default the preset's).
    pub hash_table_log2: Option<u32>,
    /// unical: the fraction of the run, the latest steps, whose poses the result averages
    /// ([`DepthCalibConfig::pose_average_fraction`]; default the preset's; 0: the last step's).
    pub pose_average: Option<f64>,
    /// unical: map the scene box to the hash grid's unit cube by its largest extent
    /// ([`crate::unical::field::FieldConfig::cubic_box`]).
    pub cubic_scene_box: bool,
    /// unical: drop moving traffic and mask the vehicle's own body
    /// ([`DepthCalibConfig::transient_returns`], [`DepthCalibConfig::mask_own_vehicle`]).
    pub drop_moving: bool,
    /// Added to every camera image's stamp (ms; [`crate::log::DriveOptions::camera_time_offset_nanos`]).
    pub camera_time_offset_ms: f64,
    /// unical with cameras: `FIRST..LAST`, the milliseconds after each image's stamp its first
    /// and last rows were exposed ([`crate::log::DriveOptions::camera_readout`]); `None`: a
    /// global shutter.
    pub camera_readout_ms: Option<String>,
    /// UniCal's options with a default that were typed at it (`--lidar-sweeps` for
    /// `--lidar-sweeps 4`), which the values alone cannot tell from options not given.
    pub given_at_default: Vec<String>,
    /// Degrees and centimetres every sensor of the initial guess is moved by (random axis and
    /// direction drawn from `seed`; (0, 0) leaves it), to measure recovery from a known start.
    pub perturb: (f64, f64),
    pub out: PathBuf,
    /// The pipeline (`auto`): the quality preset (`None`: the configuration's).
    pub quality: Option<crate::pipeline::Quality>,
    /// The pipeline: the wall-time budget in seconds (`None`: the quality's).
    pub budget_secs: Option<f64>,
    /// The pipeline: a configuration file (a `--print-config` output or an earlier output).
    pub config_file: Option<PathBuf>,
    /// Whether `--seed` was typed (over a `--config` file's seed).
    pub seed_given: bool,
}

/// UniCal's options that act on the camera images it trains on (`--camera-frames`).
const IMAGE_OPTIONS: &[&str] = &[
    "--alignment",
    "--camera-scale",
    "--camera-rays",
    "--camera-lr",
    "--camera-translation-rate",
    "--camera-translation-final",
    "--camera-early-release",
    "--shared-camera-translation",
    "--grouped-camera-translation",
    "--camera-rays-below-lidar-top",
    "--camera-hold-unobserved",
    "--camera-hold-axial",
    "--silhouette-share",
    "--camera-blur",
    "--colour-pose-levels",
    "--camera-readout-ms",
];

impl CalibrateArgs {
    /// The UniCal options given, each by its flag and its value: with another method they
    /// would be ignored (so they are refused), and the provenance records them. An option at
    /// its default is given only when it is in `given_at_default`.
    fn unical_options(&self) -> Vec<(&'static str, serde_yaml::Value)> {
        use serde_yaml::Value;
        let flag = |on: bool| on.then_some(Value::Bool(true));
        let number = |v: Option<f64>| v.map(Value::from);
        // An f32 as the number it was typed as (1e-3, not 0.0010000000474974513).
        let short =
            |v: Option<f32>| v.map(|v| Value::from(v.to_string().parse().unwrap_or(f64::from(v))));
        let text = |v: &Option<String>| v.clone().map(Value::String);
        let alignment = match self.alignment {
            AlignmentLoss::None => "none",
            AlignmentLoss::ProjectedRayDistance => "ray-distance",
            AlignmentLoss::SurfaceAlignment => "surface",
        };
        // Whether an option with a default was given: off its default, or typed at it.
        let given = |name: &str, off_default: bool| {
            off_default || self.given_at_default.iter().any(|g| g == name)
        };
        let options = [
            (
                "--camera-frames",
                given("--camera-frames", self.camera_frames != 0)
                    .then(|| Value::from(self.camera_frames as u64)),
            ),
            (
                "--lidar-sweeps",
                given("--lidar-sweeps", self.lidar_sweeps != DEFAULT_LIDAR_SWEEPS)
                    .then(|| Value::from(self.lidar_sweeps as u64)),
            ),
            ("--scene-radius", number(self.scene_radius_m)),
            (
                "--alignment",
                given(
                    "--alignment",
                    self.alignment != AlignmentLoss::SurfaceAlignment,
                )
                .then(|| Value::String(alignment.into())),
            ),
            ("--lidar-icp", flag(self.lidar_icp)),
            ("--camera-hand-eye", flag(self.camera_hand_eye)),
            (
                "--camera-scale",
                given("--camera-scale", self.camera_scale != DEFAULT_CAMERA_SCALE)
                    .then(|| Value::from(self.camera_scale)),
            ),
            (
                "--camera-rays",
                given("--camera-rays", self.camera_rays != DEFAULT_CAMERA_RAYS)
                    .then(|| Value::from(self.camera_rays as u64)),
            ),
            ("--camera-lr", short(self.camera_lr)),
            (
                "--camera-translation-rate",
                short(self.camera_translation_rate),
            ),
            (
                "--camera-translation-final",
                short(self.camera_translation_final),
            ),
            ("--camera-early-release", text(&self.camera_early_release)),
            (
                "--rounds",
                given("--rounds", self.rounds != 1).then(|| Value::from(self.rounds as u64)),
            ),
            ("--coarse-to-fine", text(&self.coarse_to_fine)),
            (
                "--shared-camera-translation",
                flag(self.shared_camera_translation),
            ),
            (
                "--grouped-camera-translation",
                flag(self.grouped_camera_translation),
            ),
            (
                "--camera-rays-below-lidar-top",
                flag(self.camera_rays_below_lidar_top),
            ),
            (
                "--camera-hold-unobserved",
                number(self.camera_hold_unobserved),
            ),
            ("--camera-hold-axial", flag(self.camera_hold_axial)),
            ("--silhouette-share", number(self.silhouette_share)),
            ("--camera-blur", number(self.camera_blur)),
            ("--colour-pose-levels", number(self.colour_pose_levels)),
            ("--hash-table-log2", self.hash_table_log2.map(Value::from)),
            ("--pose-average", number(self.pose_average)),
            ("--cubic-scene-box", flag(self.cubic_scene_box)),
            ("--drop-moving", flag(self.drop_moving)),
            ("--camera-readout-ms", text(&self.camera_readout_ms)),
        ];
        options
            .into_iter()
            .filter_map(|(name, value)| Some((name, value?)))
            .collect()
    }

    /// The UniCal options given that act on camera images only (`--camera-scale`,
    /// `--camera-readout-ms`, …): without `--camera-frames` no image joins the run, so they
    /// would be ignored. The hand-eye is not among them: it fits the cameras from their own
    /// images before UniCal, with or without images in UniCal, and places each image at its
    /// middle row's time, so the readout acts on it too.
    fn image_options_without_images(&self) -> Vec<&'static str> {
        if self.camera_frames > 0 {
            return Vec::new();
        }
        self.unical_options()
            .into_iter()
            .map(|(flag, _)| flag)
            .filter(|flag| IMAGE_OPTIONS.contains(flag))
            .filter(|&flag| !(self.camera_hand_eye && flag == "--camera-readout-ms"))
            .collect()
    }

    /// What the run was asked to do, for the file's provenance: the method as `--method` names
    /// it, the seed, and every option given, keyed by the option's name with underscores
    /// (`camera_lr` for `--camera-lr`), so the run can be repeated from its output.
    pub fn config(&self) -> serde_yaml::Mapping {
        use serde_yaml::Value;
        let mut m = serde_yaml::Mapping::new();
        let mut put = |flag: &str, value: Value| {
            let key = flag.trim_start_matches('-').replace('-', "_");
            m.insert(Value::String(key), value);
        };
        put("method", Value::String(self.method.clone()));
        put("seed", Value::from(self.seed));
        if let Some(n) = self.iterations {
            put("iterations", Value::from(n as u64));
        }
        if !self.sensors.is_empty() {
            put("sensors", Value::String(self.sensors.join(",")));
        }
        if let Some(root) = &self.root {
            put("root", Value::String(root.clone()));
        }
        if self.camera_time_offset_ms != 0.0 {
            put(
                "camera_time_offset_ms",
                Value::from(self.camera_time_offset_ms),
            );
        }
        for (flag, value) in self.unical_options() {
            put(flag, value);
        }
        m
    }

    /// The perturbation of the initial guess when there is a valid one.
    pub(crate) fn perturb_given(&self) -> Option<(f64, f64)> {
        self.perturbation().ok().flatten()
    }

    /// The perturbation of the initial guess, `None` when there is none; an error for
    /// negative, non-finite or too large values.
    fn perturbation(&self) -> Result<Option<(f64, f64)>, String> {
        let (deg, cm) = self.perturb;
        crate::sim::synth::check_perturbation(deg, cm)?;
        Ok((deg > 0.0 || cm > 0.0).then_some((deg, cm)))
    }
}

/// Sweeps of the reference LiDAR registered to the trajectory (spread over the drive: the
/// turns between them are what observes its extrinsic).
const TRAJECTORY_SWEEPS: usize = 10;

/// The reference LiDAR: `--root`, else the rig's first LiDAR.
fn reference_lidar(args: &CalibrateArgs, rig: &Rig) -> Result<String, String> {
    match &args.root {
        Some(r) if rig.lidars().any(|l| &l.name == r) => Ok(r.clone()),
        Some(r) => Err(format!(
            "--root: '{r}' is not a LiDAR of {}; --method {} registers against a LiDAR",
            args.log.display(),
            args.method
        )),
        None => rig
            .lidars()
            .next()
            .map(|l| l.name.clone())
            .ok_or_else(|| "the log has no LiDAR".to_string()),
    }
}

/// The sensors UniCal keeps fixed besides the root: those `--sensors` leaves out, and with
/// `--lidar-icp` every LiDAR (registered already).
fn held_sensors(args: &CalibrateArgs, rig: &Rig) -> Vec<String> {
    rig.sensors
        .iter()
        .filter(|s| {
            (!args.sensors.is_empty() && !args.sensors.contains(&s.name))
                || (args.lidar_icp && s.kind == SensorKind::Lidar)
        })
        .map(|s| s.name.clone())
        .collect()
}

/// `rig` with the reference LiDAR registered to the trajectory by its own sweeps (unless it
/// is the `--root`, which stays where it is) and every other LiDAR (of those `--sensors`
/// selects) registered to the reference by point-to-plane ICP, each run to convergence; the
/// result of each is printed.
fn register_lidars(
    drive: &Drive,
    rig: &Rig,
    args: &CalibrateArgs,
    segments: &[(i64, i64)],
) -> Result<Rig, String> {
    let reference = match &args.root {
        Some(r) if rig.lidars().any(|l| &l.name == r) => r.clone(),
        _ => rig
            .lidars()
            .next()
            .map(|l| l.name.clone())
            .ok_or("--lidar-icp: the log has no LiDAR")?,
    };
    let bars = super::progress::PhasedProgress::default();
    let mut rig = rig.clone();
    let asked = args.sensors.is_empty() || args.sensors.contains(&reference);
    if args.root.is_none() && asked {
        let fit = register_to_trajectory(
            drive,
            &rig,
            &reference,
            TRAJECTORY_SWEEPS,
            segments,
            IcpConfig::default(),
            &mut |done, total| bars.report("lidar to trajectory", done, total),
        )
        .map_err(|e| format!("--lidar-icp: {e}"))?;
        match (fit, rig.sensor_mut(&reference)) {
            (
                TrajectoryFit::Fitted {
                    vehicle_from_lidar,
                    unobserved,
                },
                Some(s),
            ) => {
                let (rot, trans) = s.vehicle_from_sensor.difference(vehicle_from_lidar);
                let kept = if unobserved.is_empty() {
                    String::new()
                } else {
                    format!(
                        " ({} not observed by the drive: kept)",
                        unobserved.join(", ")
                    )
                };
                eprintln!(
                    "lidar icp: {reference} moved {:.3}° / {:.1} cm to fit the trajectory{kept}",
                    rot.to_degrees(),
                    trans * 100.0
                );
                s.vehicle_from_sensor = vehicle_from_lidar;
            }
            (TrajectoryFit::TooStraight { turn_deg }, _) => eprintln!(
                "lidar icp: {reference} kept: the drive turns {turn_deg:.1}°, too little to fit \
                 it to the trajectory (at least {MIN_TURN_DEG}°)"
            ),
            (TrajectoryFit::Fitted { .. }, None) => {}
        }
    }
    if rig.lidars().count() < 2 {
        bars.finish();
        return Ok(rig);
    }
    let rig = &rig;
    let mut icp =
        IcpCalibrator::from_drive(drive, rig, &reference, 3, segments, IcpConfig::default())
            .map_err(|e| format!("--lidar-icp: {e}"))?;
    let total = icp.max_steps();
    for step in 1..=total {
        bars.report("lidar icp", step, total);
        if icp.step().done {
            break;
        }
    }
    bars.finish();
    let mut out = rig.clone();
    for lidar in icp.best().lidars() {
        let asked = args.sensors.is_empty() || args.sensors.contains(&lidar.name);
        if let Some(s) = out.sensor_mut(&lidar.name)
            && asked
        {
            let (rot, trans) = s.vehicle_from_sensor.difference(lidar.vehicle_from_sensor);
            if rot + trans > 0.0 {
                eprintln!(
                    "lidar icp: {} moved {:.3}° / {:.1} cm against {reference}",
                    lidar.name,
                    rot.to_degrees(),
                    trans * 100.0
                );
            }
            s.vehicle_from_sensor = lidar.vehicle_from_sensor;
        }
    }
    Ok(out)
}

/// `rig` with every selected camera fitted to its own motion and its translation to the map of
/// `rig`'s LiDARs, and the cameras it fitted ([`camera_motion::fit_rig_cameras`]); a camera the
/// drive cannot fit is kept where it is, and the output says why.
fn register_cameras(
    drive: &Drive,
    rig: &Rig,
    args: &CalibrateArgs,
    segments: &[(i64, i64)],
) -> (Rig, Vec<String>) {
    let map = match camera_motion::lidar_map(drive, rig) {
        Ok(map) => Some(map),
        Err(e) => {
            eprintln!("camera hand-eye: no LiDAR map to measure translations against: {e}");
            None
        }
    };
    let bars = super::progress::PhasedProgress::default();
    let (out, outcomes) = camera_motion::fit_rig_cameras(
        drive,
        rig,
        &selected_cameras(args, rig),
        camera_motion::DEFAULT_FRAMES,
        segments,
        map.as_ref(),
        &|phase, done, total| bars.report(phase, done, total),
    );
    bars.finish();
    for outcome in &outcomes {
        eprintln!("{}", outcome.summary());
    }
    let fitted = outcomes
        .iter()
        .filter(|o| o.fit.is_ok())
        .map(|o| o.name.clone())
        .collect();
    (out, fitted)
}

/// The cameras with intrinsics that `--sensors` selects (all when empty).
fn selected_cameras(args: &CalibrateArgs, rig: &Rig) -> Vec<String> {
    rig.cameras()
        .filter(|c| c.camera.is_some())
        .map(|c| c.name.clone())
        .filter(|c| args.sensors.is_empty() || args.sensors.contains(c))
        .collect()
}

/// A note when a camera has fewer usable images (inside the trajectory and the segments;
/// `held`: name and count) than `--camera-frames` asks for: it trains on every one it has.
fn fewer_images_note(asked: usize, held: &[(String, usize)], segmented: bool) -> Option<String> {
    let short: Vec<String> = held
        .iter()
        .filter(|(_, n)| *n < asked)
        .map(|(name, n)| format!("{name} {n}"))
        .collect();
    (!short.is_empty()).then(|| {
        format!(
            "camera images: --camera-frames {asked}, but the log holds fewer inside the trajectory{}: {}; each of these trains on all it has",
            if segmented { " and the segments" } else { "" },
            short.join(", ")
        )
    })
}

/// An optional numeric option, checked: finite and `ok`, else an error naming the option and
/// what it expects.
fn checked<T: Copy + std::fmt::Display + Into<f64>>(
    value: Option<T>,
    option: &str,
    expected: &str,
    ok: impl Fn(T) -> bool,
) -> Result<Option<T>, String> {
    match value {
        Some(v) if !(v.into().is_finite() && ok(v)) => {
            Err(format!("{option} {v}: expected {expected}"))
        }
        v => Ok(v),
    }
}

/// `ITER[,RATE[,translations]]` of `--camera-early-release`: the iteration, the fraction of the
/// cameras' rate, in (0, 1] (default 0.1, [`DepthCalibConfig::alignment_release_rate`]), and
/// whether only the translations move before the warm-up's end
/// ([`DepthCalibConfig::alignment_release_rotates`] off).
fn parse_early_release(s: &str) -> Result<(usize, f32, bool), String> {
    let bad = |why: &str| format!("--camera-early-release '{s}': {why}");
    let mut parts = s.split(',');
    let iter = parts
        .next()
        .unwrap_or_default()
        .trim()
        .parse::<usize>()
        .map_err(|_| bad("expected ITER[,RATE[,translations]] with ITER an iteration"))?;
    let rate = match parts.next() {
        None => DepthCalibConfig::default().alignment_release_rate,
        Some(r) => r
            .trim()
            .parse::<f32>()
            .ok()
            .filter(|r| r.is_finite() && *r > 0.0 && *r <= 1.0)
            .ok_or_else(|| bad("RATE must be a fraction in (0, 1]"))?,
    };
    let translations_only = match parts.next().map(str::trim) {
        None => false,
        Some("translations") => true,
        Some(other) => return Err(bad(&format!("'{other}': expected 'translations'"))),
    };
    if parts.next().is_some() {
        return Err(bad("expected at most ITER,RATE,translations"));
    }
    Ok((iter, rate, translations_only))
}

/// Parse `--coarse-to-fine LEVELS,FRACTION` or `off` ([`CoarseToFine::parse_setting`]).
fn parse_coarse_to_fine(s: &str) -> Result<Option<CoarseToFine>, String> {
    CoarseToFine::parse_setting(s).map_err(|e| format!("--coarse-to-fine: {e}"))
}

/// Parse `--camera-readout-ms FIRST..LAST`: when a rolling shutter exposed the first and the
/// last image rows, in milliseconds after the stamp (each within ±1000; LAST below FIRST is a
/// readout from the bottom up).
pub(crate) fn parse_readout(text: &str) -> Result<crate::geometry::RowTimes, String> {
    crate::geometry::RowTimes::parse_millis(text).map_err(|e| format!("--camera-readout-ms {e}"))
}

/// Parse `START..END` (seconds from `t0`) into nanoseconds.
pub fn parse_segment(text: &str, t0_nanos: i64) -> Result<(i64, i64), String> {
    let (a, b) = text
        .split_once("..")
        .ok_or_else(|| format!("--segment '{text}': expected START..END in seconds"))?;
    let parse = |s: &str| {
        s.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0)
            .ok_or_else(|| format!("--segment '{text}': '{s}' is not a time in seconds"))
    };
    let (a, b) = (parse(a)?, parse(b)?);
    if b <= a {
        return Err(format!("--segment '{text}': END must be after START"));
    }
    Ok((t0_nanos + (a * 1e9) as i64, t0_nanos + (b * 1e9) as i64))
}

/// The values `--method` takes.
const METHODS: [&str; 7] = [
    "auto",
    "unical",
    "icp",
    "mi",
    "target",
    "pose-graph",
    "edge",
];

fn unknown_method(method: &str) -> String {
    format!(
        "unknown --method '{method}' (expected auto, unical, icp, mi, target, pose-graph or edge)"
    )
}

/// `--sensors` naming a sensor the method does not calibrate (a camera for ICP, a LiDAR for
/// mutual information) would be written back unchanged; it is refused instead.
fn check_sensor_kinds(args: &CalibrateArgs, rig: &Rig) -> Result<(), String> {
    use crate::calib::SensorKind;
    let calibrates = match args.method.as_str() {
        "icp" => Some((SensorKind::Lidar, "LiDARs")),
        "mi" | "edge" | "target" => Some((SensorKind::Camera, "cameras")),
        // unical and pose-graph calibrate every sensor.
        _ => None,
    };
    let Some((kind, what)) = calibrates else {
        return Ok(());
    };
    match args
        .sensors
        .iter()
        .find(|s| rig.sensor(s).is_some_and(|s| s.kind != kind))
    {
        Some(s) => Err(format!(
            "--sensors: --method {} calibrates {what}; '{s}' is not one",
            args.method
        )),
        None => Ok(()),
    }
}

/// A segment must overlap the log's time range; else the error says where the log lies.
fn check_segment_in_log(
    text: &str,
    (start, end): (i64, i64),
    (first, last): (i64, i64),
    log: &std::path::Path,
) -> Result<(), String> {
    if start < last && end > first {
        return Ok(());
    }
    Err(format!(
        "--segment '{text}' lies outside {}, which spans 0..{:.1} s",
        log.display(),
        (last - first) as f64 * 1e-9
    ))
}

/// The drive, the initial guess (after `--init` and `--perturb-*`) and the segments of a run,
/// each checked against the log.
pub(crate) fn open_inputs(
    args: &CalibrateArgs,
    options: &crate::log::DriveOptions,
    perturbation: Option<(f64, f64)>,
) -> Result<(Drive, Rig, Vec<(i64, i64)>), String> {
    let drive = Drive::open_with(&args.log, options).map_err(|e| e.to_string())?;
    let mut rig = drive.rig.clone();
    if let Some(init) = &args.init {
        let imported = crate::interop::import::load_initial_guess(init, &rig)
            .map_err(|e| format!("--init: {e}"))?;
        let kept: Vec<&str> = rig
            .sensors
            .iter()
            .map(|s| s.name.as_str())
            .filter(|name| !imported.matched.iter().any(|m| m == name))
            .collect();
        if !kept.is_empty() {
            // Not an error (a file may hold only some sensors), but never silent.
            eprintln!(
                "--init {} ({}) gives {} of {} sensors; from the log's /tf_static: {}",
                init.display(),
                imported.format,
                rig.sensors.len() - kept.len(),
                rig.sensors.len(),
                kept.join(", ")
            );
        }
        rig = imported.rig;
    }
    if let Some((deg, cm)) = perturbation {
        rig = crate::sim::synth::perturb_rig(&rig, deg, cm, args.seed);
    }
    let asked = args.sensors.iter().map(|s| ("--sensors", s));
    for (option, s) in asked.chain(args.root.iter().map(|s| ("--root", s))) {
        if rig.sensor(s).is_none() {
            return Err(format!(
                "{option}: '{s}' is not a sensor of {}",
                args.log.display()
            ));
        }
    }
    let range = drive.time_range_nanos();
    let t0 = range.map_or(0, |r| r.0);
    let segments: Vec<(i64, i64)> = match &args.segment {
        Some(s) => {
            let segment = parse_segment(s, t0)?;
            if let Some(range) = range {
                check_segment_in_log(s, segment, range, &args.log)?;
            }
            vec![segment]
        }
        None => Vec::new(),
    };
    Ok((drive, rig, segments))
}

/// Run the calibration; `progress(step, max_steps)` is called after every step. Returns the
/// written document and how far each sensor moved from the initial guess ([`moves_report`]).
pub fn calibrate(
    args: &CalibrateArgs,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(CalibrationFile, String), String> {
    let perturbation = args.perturbation()?;
    if !METHODS.contains(&args.method.as_str()) {
        return Err(unknown_method(&args.method));
    }
    if matches!(args.method.as_str(), "icp" | "pose-graph") && args.iterations.is_some() {
        return Err(format!(
            "--iterations: --method {} runs until it converges",
            args.method
        ));
    }
    let pipeline_only = [
        ("--quality", args.quality.is_some()),
        ("--budget", args.budget_secs.is_some()),
        ("--config", args.config_file.is_some()),
    ];
    let pipeline_only: Vec<&str> = pipeline_only
        .iter()
        .filter(|(_, given)| *given)
        .map(|(f, _)| *f)
        .collect();
    if args.method != "auto" && !pipeline_only.is_empty() {
        return Err(format!(
            "{} appl{} to the pipeline (no --method, or --method auto) only",
            pipeline_only.join(", "),
            if pipeline_only.len() == 1 { "ies" } else { "y" }
        ));
    }
    let unical_only: Vec<&str> = args
        .unical_options()
        .into_iter()
        .map(|(f, _)| f)
        .filter(|f| !(args.method == "auto" && *f == "--camera-readout-ms"))
        .collect();
    if args.method == "auto" && !unical_only.is_empty() {
        return Err(format!(
            "{} {} UniCal's own: the pipeline reads its UniCal settings from --config FILE (see --print-config), or give --method unical",
            unical_only.join(", "),
            if unical_only.len() == 1 { "is" } else { "are" }
        ));
    }
    if args.method != "unical" && !unical_only.is_empty() {
        return Err(format!(
            "{} appl{} to --method unical only",
            unical_only.join(", "),
            if unical_only.len() == 1 { "ies" } else { "y" }
        ));
    }
    if let Ok(crate::util::OutputTarget::Direct(_)) = crate::util::output_target(&args.out) {
        return Err(format!(
            "--out {} is not a regular file (a device or pipe); calibrate writes its file at the start and replaces it every 30 s",
            args.out.display()
        ));
    }
    if crate::util::same_file(&args.out, &args.log) {
        return Err(format!(
            "--out {} is the log itself; the calibration would overwrite it",
            args.out.display()
        ));
    }
    if matches!(args.method.as_str(), "unical" | "auto") && args.iterations == Some(0) {
        return Err("--iterations 0: UniCal needs at least one step".into());
    }
    if args.method == "auto" {
        return super::pipeline::calibrate_auto(args, perturbation, progress);
    }
    if !args.camera_time_offset_ms.is_finite() || args.camera_time_offset_ms.abs() > 1000.0 {
        return Err(format!(
            "--camera-time-offset-ms must be a number of milliseconds within ±1000, not {}",
            args.camera_time_offset_ms
        ));
    }
    let camera_readout = match args.camera_readout_ms.as_deref() {
        Some(s) => parse_readout(s)?,
        None => crate::geometry::RowTimes::GLOBAL,
    };
    let options = crate::log::DriveOptions {
        camera_time_offset_nanos: (args.camera_time_offset_ms * 1e6).round() as i64,
        camera_readout,
        ..crate::log::DriveOptions::default()
    };
    let (drive, mut rig, segments) = open_inputs(args, &options, perturbation)?;
    // What the user gave (after --init and --perturb-*), to say at the end how far each sensor
    // moved from it.
    let initial_guess = rig.clone();
    check_sensor_kinds(args, &rig)?;
    let mut calibrator: Box<dyn Calibrator> = match args.method.as_str() {
        "edge" => {
            let lidar = reference_lidar(args, &rig)?;
            let cameras = selected_cameras(args, &rig);
            Box::new(
                EdgeRefiner::new(&drive, &rig, &lidar, &cameras, 4, &segments)
                    .map_err(|e| e.to_string())?,
            )
        }
        "unical" => {
            // Options are checked before the LiDARs are registered (seconds of work).
            if args.rounds == 0 {
                return Err("--rounds 0: expected at least one round".into());
            }
            let camera_lr = checked(args.camera_lr, "--camera-lr", "a rate above 0", |lr| {
                lr > 0.0
            })?;
            let camera_translation_rate = checked(
                args.camera_translation_rate,
                "--camera-translation-rate",
                "a multiple of 0 or more",
                |r| r >= 0.0,
            )?;
            let camera_translation_final = checked(
                args.camera_translation_final,
                "--camera-translation-final",
                "a fraction in (0, 1]",
                |f| f > 0.0 && f <= 1.0,
            )?;
            let camera_hold_unobserved = checked(
                args.camera_hold_unobserved,
                "--camera-hold-unobserved",
                "a fraction in (0, 1)",
                |r| r > 0.0 && r < 1.0,
            )?;
            let silhouette_share = checked(
                args.silhouette_share,
                "--silhouette-share",
                "a fraction from 0 to 1",
                |r| (0.0..=1.0).contains(&r),
            )?;
            let camera_blur = checked(
                args.camera_blur,
                "--camera-blur",
                "a σ in pixels from 0 to 10",
                |b| (0.0..=10.0).contains(&b),
            )?;
            let colour_pose_levels = checked(
                args.colour_pose_levels,
                "--colour-pose-levels",
                "a number of levels from 0 to 64",
                |l| (0.0..=64.0).contains(&l),
            )?;
            let hash_table_log2 = checked(
                args.hash_table_log2,
                "--hash-table-log2",
                "a power of two from 12 to 24",
                |b| (12..=24).contains(&b),
            )?;
            let pose_average = checked(
                args.pose_average,
                "--pose-average",
                "a fraction of the run from 0 to 1",
                |f| (0.0..=1.0).contains(&f),
            )?;
            let scene_radius_m = checked(
                args.scene_radius_m,
                "--scene-radius",
                "a distance of 5 m or more",
                |r| r >= 5.0,
            )?;
            if args.lidar_sweeps == 0 {
                return Err("--lidar-sweeps 0: expected at least one sweep per LiDAR".into());
            }
            if args.camera_frames > 0 && args.camera_rays == 0 {
                return Err(
                    "--camera-rays 0: expected at least one ray per camera and step".into(),
                );
            }
            let early_release = args
                .camera_early_release
                .as_deref()
                .map(parse_early_release)
                .transpose()?;
            let idle = args.image_options_without_images();
            if !idle.is_empty() {
                return Err(format!(
                    "{} act{} on camera images, which join UniCal only with --camera-frames N",
                    idle.join(", "),
                    if idle.len() == 1 { "s" } else { "" }
                ));
            }
            if args.lidar_icp {
                rig = register_lidars(&drive, &rig, args, &segments)?;
            }
            let mut fitted = Vec::new();
            if args.camera_hand_eye {
                (rig, fitted) = register_cameras(&drive, &rig, args, &segments);
            }
            // Cameras the hand-eye fitted get its schedule and bound; the options override.
            let iterations = args.iterations.unwrap_or(300);
            let preset = DepthCalibConfig {
                iterations,
                ..DepthCalibConfig::default()
            }
            .after_hand_eye(&fitted, camera_motion::ROTATION_BOUND_DEG);
            let config = DepthCalibConfig {
                iterations,
                seed: args.seed,
                frozen_sensor: args.root.clone(),
                // Sensors not asked for stay where they are while the others move.
                held_sensors: held_sensors(args, &rig),
                rays_per_camera: args.camera_rays.max(1),
                lr_camera_pose: camera_lr.unwrap_or(preset.lr_camera_pose),
                camera_translation_rate: camera_translation_rate
                    .unwrap_or(preset.camera_translation_rate),
                camera_translation_final_fraction: camera_translation_final
                    .or(preset.camera_translation_final_fraction),
                alignment_release: early_release
                    .map(|(i, _, _)| i)
                    .or(preset.alignment_release),
                alignment_release_rate: early_release
                    .map_or(preset.alignment_release_rate, |(_, r, _)| r),
                alignment_release_rotates: match early_release {
                    Some((_, _, true)) => false,
                    _ => preset.alignment_release_rotates,
                },
                coarse_to_fine: match args.coarse_to_fine.as_deref() {
                    Some(s) => parse_coarse_to_fine(s)?,
                    None => preset.coarse_to_fine,
                },
                alignment: args.alignment,
                shared_camera_translation: args.shared_camera_translation,
                grouped_camera_translation: args.grouped_camera_translation,
                camera_rays_below_lidar_top: args.camera_rays_below_lidar_top,
                camera_hold_unobserved,
                camera_hold_axial: args.camera_hold_axial || preset.camera_hold_axial,
                silhouette_share: silhouette_share.unwrap_or(preset.silhouette_share),
                camera_target_blur_px: camera_blur.unwrap_or(preset.camera_target_blur_px),
                colour_pose_levels: colour_pose_levels
                    .map(|l| l as f32)
                    .or(preset.colour_pose_levels),
                field: FieldConfig {
                    grid: HashGridConfig {
                        log2_table_size: hash_table_log2
                            .unwrap_or(preset.field.grid.log2_table_size),
                        ..preset.field.grid.clone()
                    },
                    cubic_box: args.cubic_scene_box || preset.field.cubic_box,
                    ..preset.field.clone()
                },
                pose_average_fraction: pose_average
                    .map_or(preset.pose_average_fraction, |f| f as f32),
                transient_returns: args
                    .drop_moving
                    .then(crate::unical::transient::TransientSettings::default),
                mask_own_vehicle: args.drop_moving,
                scene_radius_m,
                correspondence_cache: Some(crate::session::state_dir().join("matches")),
                ..preset
            };
            let bars = super::progress::PhasedProgress::default();
            let stage =
                UnicalLidarStage::from_drive(&drive, &rig, args.lidar_sweeps, &segments, config)?
                    .with_cameras_reporting(
                    &drive,
                    args.camera_frames,
                    &segments,
                    args.camera_scale,
                    &|phase, done, total| bars.report(phase, done, total),
                )?;
            bars.finish();
            if args.camera_frames > 0 {
                let held: Vec<(String, usize)> = rig
                    .cameras()
                    .filter(|c| c.camera.is_some() && drive.stream(&c.name).is_some())
                    .map(|c| {
                        (
                            c.name.clone(),
                            drive.frames_within(&c.name, &segments).len(),
                        )
                    })
                    .collect();
                if let Some(note) =
                    fewer_images_note(args.camera_frames, &held, !segments.is_empty())
                {
                    eprintln!("{note}");
                }
            }
            if args.camera_rays_below_lidar_top {
                match stage.calibration().camera_ray_top_elevation_rad() {
                    Some(top) => eprintln!(
                        "camera rays: only up to {:.1}° above the vehicle's horizon (the LiDARs' highest returns)",
                        top.to_degrees()
                    ),
                    None => {
                        eprintln!("camera rays: no LiDAR returns to bound them, every ray is drawn")
                    }
                }
            }
            let scene = stage.calibration();
            let size = scene.field.box_size;
            eprintln!(
                "scene: {:.0} × {:.0} × {:.0} m, {} occupied voxels of {} m; hash grid: {}",
                size.x,
                size.y,
                size.z,
                scene.occupancy.occupied_boxes().count(),
                scene.occupancy.voxel_m,
                crate::unical::hash_load::summary(
                    &scene.hash_loads(),
                    scene.field.grid.config.log2_table_size
                )
            );
            if let (Some(kept), Some(r)) = (stage.scene_bounds(), scene_radius_m) {
                eprintln!(
                    "scene radius {r} m: {} LiDAR returns beyond it left to the background, {} kept",
                    kept.dropped, kept.kept
                );
            }
            if let Some(stats) = stage.transient_stats() {
                eprintln!(
                    "moving traffic: {} of {} LiDAR returns seen through by other sweeps, dropped ({:.1} %)",
                    stats.dropped(),
                    stats.examined(),
                    100.0 * stats.dropped() as f64 / stats.examined().max(1) as f64
                );
            }
            Box::new(stage.in_rounds(args.rounds))
        }
        "icp" => {
            let reference = reference_lidar(args, &rig)?;
            Box::new(IcpCalibrator::from_drive(
                &drive,
                &rig,
                &reference,
                3,
                &segments,
                IcpConfig::default(),
            )?)
        }
        "mi" => {
            let reference = reference_lidar(args, &rig)?;
            let cameras = selected_cameras(args, &rig);
            let config = MiConfig {
                iterations: args.iterations.unwrap_or(MiConfig::default().iterations),
                ..MiConfig::default()
            };
            Box::new(MiCalibrator::from_drive(
                &drive, &rig, &reference, &cameras, 3, &segments, config,
            )?)
        }
        "target" => {
            let reference = reference_lidar(args, &rig)?;
            let cameras = selected_cameras(args, &rig);
            let config = TargetConfig {
                iterations: args
                    .iterations
                    .unwrap_or(TargetConfig::default().iterations),
                ..TargetConfig::default()
            };
            Box::new(TargetCalibrator::from_drive(
                &drive,
                &rig,
                &reference,
                &cameras,
                &segments,
                config,
                &Default::default(),
            )?)
        }
        "pose-graph" => {
            let reference = reference_lidar(args, &rig)?;
            let cal = PoseGraphCalibrator::from_drive(
                &drive,
                &rig,
                &reference,
                &segments,
                PoseGraphConfig::default(),
            )?;
            for s in cal.skipped() {
                eprintln!("pose-graph: skipped {s}");
            }
            Box::new(cal)
        }
        m => return Err(unknown_method(m)),
    };
    let max_steps = match (args.method.as_str(), args.iterations) {
        ("edge", Some(n)) => n.min(calibrator.max_steps()),
        _ => calibrator.max_steps(),
    };
    // The output is written before the first step (an unwritable path fails now, not after
    // the run) and again every CHECKPOINT_SECS, atomically: a run that is killed or crashes
    // leaves its latest result, marked as unfinished.
    let mut last = Vec::new();
    let checkpoint = |calibrator: &dyn Calibrator, last: &[(String, f64)], status: String| {
        document(args, &rig, calibrator, last, status)
            .save(&args.out)
            .map_err(|e| e.to_string())
    };
    checkpoint(
        calibrator.as_ref(),
        &last,
        format!("running: step 0 of {max_steps}"),
    )?;
    let mut saved_at = std::time::Instant::now();
    let optimising_since = std::time::Instant::now();
    let mut first_update_seen = false;
    for step in 1..=max_steps {
        let r = calibrator.step();
        last = r.losses;
        if !first_update_seen && rig_moved(&rig, &calibrator.current()) {
            first_update_seen = true;
            report_first_update(step, optimising_since.elapsed().as_secs_f64());
        }
        progress(step, max_steps);
        if r.done {
            break;
        }
        if saved_at.elapsed().as_secs_f64() >= CHECKPOINT_SECS {
            checkpoint(
                calibrator.as_ref(),
                &last,
                format!("running: step {step} of {max_steps}"),
            )?;
            saved_at = std::time::Instant::now();
        }
    }
    let result = result_rig(args, &rig, calibrator.as_ref());
    let doc = document_of(args, &result, calibrator.as_ref(), &last, "complete".into());
    if args.camera_hand_eye {
        warn_at_bound(&rig, &calibrator.best());
    }
    doc.save(&args.out).map_err(|e| e.to_string())?;
    Ok((doc, moves_report(&initial_guess, &result)))
}

/// How far each sensor of `result` lies from the initial guess, one line each, the largest
/// rotation first; sensors that did not move are named together. A camera far from a guess
/// the user trusts is the one to look at in the studio.
pub fn moves_report(initial: &Rig, result: &Rig) -> String {
    let mut moved: Vec<(String, f64, f64)> = Vec::new();
    let mut kept: Vec<&str> = Vec::new();
    for s in &initial.sensors {
        let Some(r) = result.sensor(&s.name) else {
            continue;
        };
        match moved_by(s.vehicle_from_sensor, r.vehicle_from_sensor) {
            Some((rot, trans)) => moved.push((s.name.clone(), rot.to_degrees(), trans * 100.0)),
            None => kept.push(&s.name),
        }
    }
    moved.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut out = String::from("moved from the initial guess:\n");
    let width = moved.iter().map(|m| m.0.len()).max().unwrap_or(0);
    for (name, deg, cm) in &moved {
        out.push_str(&format!("  {name:width$}  {deg:6.3}° {cm:7.2} cm\n"));
    }
    if !kept.is_empty() {
        out.push_str(&format!("  where they were: {}\n", kept.join(", ")));
    }
    out
}

/// Whether any sensor of `now` differs from `start` (by more than rounding).
fn rig_moved(start: &Rig, now: &Rig) -> bool {
    start.sensors.iter().any(|s| {
        now.sensor(&s.name)
            .is_some_and(|n| moved_by(s.vehicle_from_sensor, n.vehicle_from_sensor).is_some())
    })
}

/// The rotation (rad) and translation (m) between two poses of a sensor, if it moved by more
/// than rounding.
fn moved_by(from: Rigid, to: Rigid) -> Option<(f64, f64)> {
    let (rot, trans) = from.difference(to);
    (rot + trans > 1e-9).then_some((rot, trans))
}

/// The step and the time into the optimisation at which the extrinsics first changed: what a
/// user watching the run waits for (issue 5 asks for it within 5 s).
fn report_first_update(step: usize, seconds: f64) {
    use std::io::IsTerminal;
    let lead = if std::io::stderr().is_terminal() {
        "\n"
    } else {
        ""
    };
    eprintln!("{lead}first extrinsic update: step {step}, {seconds:.1} s into the optimisation");
}

/// Cameras that end at the rotation bound around their hand-eye fit: the scene pulled them
/// further, so either the fit or the result is off by about the bound; the user should look.
fn warn_at_bound(start: &Rig, result: &Rig) {
    for s in start.cameras() {
        let Some(r) = result.sensor(&s.name) else {
            continue;
        };
        let (rot, _) = s.vehicle_from_sensor.difference(r.vehicle_from_sensor);
        if rot.to_degrees() >= camera_motion::ROTATION_BOUND_DEG - 0.01 {
            eprintln!(
                "warning: {} ends {:.2}° from its hand-eye fit, at the bound UniCal may move it \
                 within: check its overlay",
                s.name,
                rot.to_degrees()
            );
        }
    }
}

/// Seconds between checkpoints of a running calibration.
const CHECKPOINT_SECS: f64 = 30.0;

/// The native file for the calibrator's best rig: sensors not asked for keep their initial
/// extrinsics; provenance (input, method, time range, init, version, status) and the latest
/// losses as metrics.
fn document(
    args: &CalibrateArgs,
    initial: &Rig,
    calibrator: &dyn Calibrator,
    losses: &[(String, f64)],
    status: String,
) -> CalibrationFile {
    let result = result_rig(args, initial, calibrator);
    document_of(args, &result, calibrator, losses, status)
}

/// The calibrator's best rig, with the sensors `--sensors` leaves out where `initial` has them.
fn result_rig(args: &CalibrateArgs, initial: &Rig, calibrator: &dyn Calibrator) -> Rig {
    let mut result: Rig = calibrator.best();
    if !args.sensors.is_empty() {
        for s in &mut result.sensors {
            if !args.sensors.contains(&s.name)
                && let Some(r) = initial.sensor(&s.name)
            {
                s.vehicle_from_sensor = r.vehicle_from_sensor;
            }
        }
    }
    result
}

/// The native file of `result`, with the run's provenance and losses.
fn document_of(
    args: &CalibrateArgs,
    result: &Rig,
    calibrator: &dyn Calibrator,
    losses: &[(String, f64)],
    status: String,
) -> CalibrationFile {
    let mut doc = CalibrationFile::from_rig(result);
    let v = |s: String| serde_yaml::Value::String(s);
    let input = std::path::absolute(&args.log).unwrap_or_else(|_| args.log.clone());
    doc.provenance
        .insert("input".into(), v(input.display().to_string()));
    doc.provenance
        .insert("method".into(), v(calibrator.name().to_string()));
    doc.provenance
        .insert("config".into(), serde_yaml::Value::Mapping(args.config()));
    doc.provenance
        .insert("date".into(), v(crate::util::now_utc()));
    if let Some(s) = &args.segment {
        doc.provenance
            .insert("time_range".into(), v(format!("{s} s")));
    }
    if let Some(i) = &args.init {
        doc.provenance
            .insert("init".into(), v(i.display().to_string()));
    }
    if let Ok(Some((deg, cm))) = args.perturbation() {
        doc.provenance.insert(
            "init_perturbed".into(),
            v(format!("{deg}° and {cm} cm per sensor, seed {}", args.seed)),
        );
    }
    doc.provenance.insert(
        "version".into(),
        v(format!("rigcal {}", env!("CARGO_PKG_VERSION"))),
    );
    doc.provenance.insert("status".into(), v(status));
    for (name, value) in losses {
        doc.metrics
            .insert(name.clone(), serde_yaml::Value::from(*value));
    }
    doc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_moves_report_names_each_sensor_largest_turn_first_and_the_ones_kept() {
        use crate::calib::{Sensor, SensorKind};
        use crate::geometry::so3;
        use glam::DVec3;
        let sensor = |name: &str| Sensor {
            name: name.into(),
            kind: SensorKind::Lidar,
            frame_id: name.into(),
            topics: Vec::new(),
            vehicle_from_sensor: Rigid::IDENTITY,
            camera: None,
        };
        let initial = Rig {
            vehicle_frame: "base_link".into(),
            sensors: vec![sensor("top"), sensor("front"), sensor("rear")],
        };
        let mut result = initial.clone();
        result.sensors[1].vehicle_from_sensor = Rigid::new(
            so3::exp(DVec3::new(0.0, 0.0, 0.5f64.to_radians())),
            DVec3::new(0.03, 0.0, 0.04),
        );
        result.sensors[2].vehicle_from_sensor = Rigid::new(
            so3::exp(DVec3::new(2f64.to_radians(), 0.0, 0.0)),
            DVec3::ZERO,
        );
        let report = moves_report(&initial, &result);
        let lines: Vec<&str> = report.lines().collect();
        assert_eq!(lines.len(), 4, "{report}");
        assert!(
            lines[1].contains("rear") && lines[1].contains("2.000°"),
            "{report}"
        );
        assert!(
            lines[2].contains("front") && lines[2].contains("0.500°"),
            "{report}"
        );
        assert!(lines[2].contains("5.00 cm"), "{report}");
        assert_eq!(lines[3], "  where they were: top");
    }

    #[test]
    fn segments_parse_in_seconds_from_the_start() {
        assert_eq!(
            parse_segment("1.5..4", 100),
            Ok((1_500_000_100, 4_000_000_100))
        );
        assert!(parse_segment("4..1", 0).unwrap_err().contains("after"));
        assert!(parse_segment("a..1", 0).unwrap_err().contains("'a'"));
        assert!(parse_segment("3", 0).unwrap_err().contains("START..END"));
        // A segment must overlap the log: 100..200 s of an 8-second log is refused by name.
        let log = std::path::Path::new("drive.mcap");
        let range = (1_000, 1_000 + 8_000_000_000);
        let far = parse_segment("100..200", 1_000).unwrap();
        let err = check_segment_in_log("100..200", far, range, log).unwrap_err();
        assert!(
            err.contains("drive.mcap") && err.contains("0..8.0 s"),
            "{err}"
        );
        let inside = parse_segment("7..20", 1_000).unwrap();
        assert!(check_segment_in_log("7..20", inside, range, log).is_ok());
    }

    #[test]
    fn cameras_with_fewer_images_than_asked_for_are_named() {
        let held = [("front".to_string(), 16), ("back".to_string(), 9)];
        assert_eq!(
            fewer_images_note(16, &held, false).as_deref(),
            Some(
                "camera images: --camera-frames 16, but the log holds fewer inside the trajectory: back 9; each of these trains on all it has"
            )
        );
        let note = fewer_images_note(32, &held, true).unwrap();
        assert!(
            note.contains("trajectory and the segments: front 16, back 9"),
            "{note}"
        );
        assert_eq!(fewer_images_note(9, &held, true), None);
    }

    #[test]
    fn a_readout_parses_the_first_and_last_rows_milliseconds() {
        use crate::geometry::RowTimes;
        assert_eq!(
            parse_readout("-30..10"),
            Ok(RowTimes {
                first_row_nanos: -30_000_000,
                last_row_nanos: 10_000_000
            })
        );
        // Bottom up, and fractions of a millisecond.
        assert_eq!(
            parse_readout(" 12.5 .. -2.25 "),
            Ok(RowTimes::from_millis(12.5, -2.25))
        );
        for (bad, says) in [
            ("30", "FIRST..LAST"),
            ("a..10", "'a'"),
            ("-30..2000", "'2000'"),
            ("nan..0", "'nan'"),
        ] {
            let err = parse_readout(bad).unwrap_err();
            assert!(err.contains(says) && err.contains(bad), "{err}");
        }
    }

    #[test]
    fn an_early_release_parses_its_iteration_rate_and_what_moves() {
        let rate = DepthCalibConfig::default().alignment_release_rate;
        assert_eq!(parse_early_release("30"), Ok((30, rate, false)));
        assert_eq!(parse_early_release("30,0.2"), Ok((30, 0.2, false)));
        assert_eq!(
            parse_early_release("30, 0.05, translations"),
            Ok((30, 0.05, true))
        );
        for bad in ["", "x", "30,0", "30,0.1,rotations", "30,0.1,translations,1"] {
            let err = parse_early_release(bad).unwrap_err();
            assert!(err.contains(&format!("'{bad}'")), "{err}");
        }
    }

    #[test]
    fn coarse_to_fine_parses_levels_and_fraction() {
        assert_eq!(
            parse_coarse_to_fine("4,0.6"),
            Ok(Some(CoarseToFine {
                start_levels: 4.0,
                end_fraction: 0.6
            }))
        );
        assert_eq!(parse_coarse_to_fine("off"), Ok(None));
        for bad in ["4", "0,0.5", "4,0", "4,1.5", "a,0.5"] {
            assert!(parse_coarse_to_fine(bad).is_err(), "{bad}");
        }
    }
}
