//! What the pipeline will do with a drive, decided from the data: the stages, each with the
//! reason it was chosen or skipped, and the settings it resolved (images, scale, steps) from the
//! quality preset and the time budget.
//!
//! The decisions, in order:
//! - a log that hardly moves (under a metre) is a stationary one: its cameras are calibrated
//!   against the reference LiDAR by checkerboards where boards are found, else by edge
//!   alignment, and no neural scene is learned;
//! - LiDARs: the reference (the root, else the first) is fitted to the trajectory where the
//!   drive turns enough ([`MIN_TURN_DEG`]), in pitch and yaw only where it drives straight far
//!   enough ([`MIN_STRAIGHT_DISTANCE_M`]), otherwise left (and always left where its frame is
//!   the vehicle frame, or where its sweeps are too far apart to share surfaces:
//!   [`trajectory_sweeps`]); every other LiDAR is registered to
//!   it by point-to-plane ICP; then UniCal holds them;
//! - cameras: where the drive turns enough, each camera is fitted to its own motion (hand-eye)
//!   and the fit kept where the camera's edges align with the reference LiDAR's at least as well
//!   as at the start (where it does not, the report marks each camera's position along the
//!   travel, which a straight drive hardly pins); then UniCal with every camera, on the
//!   quality's images at its scale, for as many steps as the budget allows.
//!
//! The same [`Plan`] runs from the CLI, the studio and `bench` ([`super::run`]).

use crate::calib::{Rig, SensorKind};
use crate::classical::trajectory_icp::{MIN_STRAIGHT_DISTANCE_M, MIN_TURN_DEG};
use crate::classical::trajectory_sweeps::{self, MIN_PAIRS, OVERLAP_M, Picked};
use crate::geometry::so3;
use crate::log::Drive;
use crate::unical::depth_calib::DepthCalibConfig;
use glam::DVec3;

use super::config::{HandEye, PipelineConfig};

/// A log whose vehicle moves less than this (m) is a stationary one.
const STATIONARY_M: f64 = 1.0;

/// Seconds a UniCal step is planned at per camera ray and per LiDAR ray, and the preparation
/// per camera image (measured on a 2-core Xeon with AVX-512; BENCHMARKS.md, "The pipeline").
/// The run stops at the budget whatever the estimate said.
const SECS_PER_CAMERA_RAY: f64 = 1.3e-4;
const SECS_PER_LIDAR_RAY: f64 = 6.0e-5;
const PREPARE_SECS_PER_IMAGE: f64 = 0.4;
const PREPARE_SECS: f64 = 30.0;
/// Preparation per sweep added to the scene for the cameras' images (decoded, placed in the
/// occupancy grid and fitted by the geometry initialisation; about 2.7 s an HDL-64 sweep).
const PREPARE_SECS_PER_ADDED_SWEEP: f64 = 2.5;

/// The sensors and times a plan is made for, besides the configuration.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlanRequest {
    /// The sensor whose extrinsic stays fixed (a LiDAR: also the reference).
    pub root: Option<String>,
    /// The sensors to calibrate (empty: all).
    pub sensors: Vec<String>,
    /// Time ranges (ns) to use (empty: the whole drive).
    pub segments_nanos: Vec<(i64, i64)>,
}

/// One stage of a plan.
#[derive(Clone, Debug, PartialEq)]
pub enum Stage {
    /// Fit the reference LiDAR to the trajectory by its own sweeps.
    LidarToTrajectory { lidar: String },
    /// Register each LiDAR to the reference by point-to-plane ICP.
    LidarIcp {
        reference: String,
        lidars: Vec<String>,
    },
    /// Fit each camera to its own motion (and its translation to the LiDAR map); with
    /// `checked`, a fit is kept only where the camera's edges align with the reference LiDAR's
    /// at least as well as at the start.
    CameraHandEye { cameras: Vec<String>, checked: bool },
    /// UniCal: one scene with every sensor; the held ones stay.
    Unical {
        cameras: Vec<String>,
        images_per_camera: usize,
        image_scale: f64,
        iterations: usize,
    },
    /// A stationary log: checkerboards where boards are found, else edge alignment.
    StationaryCameras {
        reference: String,
        cameras: Vec<String>,
    },
}

/// What the pipeline will do, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    pub stages: Vec<Stage>,
    /// One line per decision, with its reason.
    pub decisions: Vec<String>,
    /// The LiDAR others are registered to and cameras checked against.
    pub reference_lidar: Option<String>,
    /// The configuration with every choice resolved (images, scale, steps, budget), as the
    /// output's provenance records it.
    pub config: PipelineConfig,
    /// UniCal's configuration for this drive (steps, seed, root, held sensors); the run gives
    /// the cameras the hand-eye fitted its schedule ([`DepthCalibConfig::after_hand_eye`]).
    pub unical: DepthCalibConfig,
    pub request: PlanRequest,
    /// Where the drive is too straight to pin a camera's position along it: the direction of
    /// travel in the vehicle frame (the report marks the camera axes along it).
    pub straight_travel: Option<DVec3>,
}

/// A drive the pipeline cannot plan for.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PlanError {
    #[error("{0}")]
    Config(#[from] super::config::ConfigError),
    #[error("--sensors: no sensor '{name}' in {log}")]
    UnknownSensor { name: String, log: String },
    #[error("--root: no sensor '{name}' in {log}")]
    UnknownRoot { name: String, log: String },
    #[error("{log} has no LiDAR with sweeps: the pipeline needs one to calibrate against")]
    NoLidar { log: String },
}

/// How the vehicle moves within the request's time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion {
    pub distance_m: f64,
    /// The largest heading change from the first pose (degrees).
    pub turn_deg: f64,
    /// The mean direction of travel in the vehicle frame (unit; zero when it does not move):
    /// the vehicle's x for a car driving forward.
    pub travel_vehicle: DVec3,
}

impl Motion {
    /// The motion over `segments_nanos` (empty: the whole trajectory), poses every 0.25 s.
    pub fn of(drive: &Drive, segments_nanos: &[(i64, i64)]) -> Motion {
        let Some((lo, hi)) = drive.trajectory.time_range_nanos() else {
            return Motion {
                distance_m: 0.0,
                turn_deg: 0.0,
                travel_vehicle: DVec3::ZERO,
            };
        };
        let ranges = if segments_nanos.is_empty() {
            vec![(lo, hi)]
        } else {
            segments_nanos.to_vec()
        };
        let (mut distance_m, mut turn_deg) = (0.0, 0.0f64);
        let mut travel = DVec3::ZERO;
        let mut first = None;
        for (a, b) in ranges {
            let stamps =
                crate::geometry::Trajectory::sample_stamps(a.max(lo), b.min(hi), 250_000_000, 4000);
            let poses: Vec<_> = stamps
                .iter()
                .filter_map(|&t| drive.trajectory.world_from_vehicle(t).ok())
                .collect();
            for w in poses.windows(2) {
                let step = w[1].translation - w[0].translation;
                distance_m += step.length();
                travel += w[0].rotation.inverse() * step;
            }
            for p in &poses {
                let f = *first.get_or_insert(p.rotation);
                // The heading: the vehicle's x axis on the ground plane.
                let heading = |q: glam::DQuat| {
                    let x = q * glam::DVec3::X;
                    x.y.atan2(x.x)
                };
                let d = so3::angle_rad(glam::DQuat::from_rotation_z(
                    heading(p.rotation) - heading(f),
                ));
                turn_deg = turn_deg.max(d.to_degrees());
            }
        }
        Motion {
            distance_m,
            turn_deg,
            travel_vehicle: travel.normalize_or_zero(),
        }
    }
}

impl Plan {
    /// Decide the stages for `rig` on `drive` (from its motion and its sensors: no image is
    /// read).
    pub fn build(
        drive: &Drive,
        rig: &Rig,
        request: &PlanRequest,
        config: &PipelineConfig,
    ) -> Result<Plan, PlanError> {
        config.check()?;
        let log = drive.path().display().to_string();
        for name in &request.sensors {
            if rig.sensor(name).is_none() {
                return Err(PlanError::UnknownSensor {
                    name: name.clone(),
                    log,
                });
            }
        }
        if let Some(root) = &request.root
            && rig.sensor(root).is_none()
        {
            return Err(PlanError::UnknownRoot {
                name: root.clone(),
                log,
            });
        }
        let asked =
            |name: &str| request.sensors.is_empty() || request.sensors.iter().any(|s| s == name);
        let with_data = |name: &str| drive.stream(name).is_some_and(|s| !s.frames.is_empty());
        let lidars: Vec<String> = rig
            .lidars()
            .filter(|l| with_data(&l.name))
            .map(|l| l.name.clone())
            .collect();
        let reference = match &request.root {
            Some(r) if lidars.contains(r) => r.clone(),
            _ => lidars.first().cloned().ok_or(PlanError::NoLidar { log })?,
        };
        let cameras: Vec<String> = rig
            .cameras()
            .filter(|c| c.camera.is_some() && with_data(&c.name) && asked(&c.name))
            // A root camera stays where it is: no stage moves it.
            .filter(|c| request.root.as_deref() != Some(c.name.as_str()))
            .map(|c| c.name.clone())
            .collect();
        let motion = Motion::of(drive, &request.segments_nanos);
        let preset = config.quality.preset();
        let mut resolved = config.clone();
        resolved.budget_secs = config.budget_secs.or(preset.budget_secs);
        let mut stages = Vec::new();
        let mut decisions = vec![format!(
            "drive: {:.0} m, turning {:.0}° at most from its first heading; {} LiDAR(s), {} camera(s) to calibrate; quality {}{}",
            motion.distance_m,
            motion.turn_deg,
            lidars.len(),
            cameras.len(),
            config.quality.name(),
            match resolved.budget_secs {
                Some(b) => format!(", budget {}", format_secs(b)),
                None => ", no time budget".into(),
            }
        )];
        let stationary = motion.distance_m < STATIONARY_M;
        // LiDARs.
        let root_is_reference = request.root.as_deref() == Some(reference.as_str());
        if config.lidars.register {
            if root_is_reference {
                decisions.push(format!(
                    "lidars: {reference} is the root: it stays where the initial guess puts it"
                ));
            } else if !asked(&reference) {
                decisions.push(format!(
                    "lidars: {reference} (the reference) is not among --sensors: it stays"
                ));
            } else if stationary {
                decisions.push(format!(
                    "lidars: {reference} (the reference) stays: the vehicle does not move, so the trajectory cannot place it"
                ));
            } else if rig
                .sensor(&reference)
                .is_some_and(|s| s.frame_id == rig.vehicle_frame)
            {
                decisions.push(format!(
                    "lidars: {reference} (the reference) stays: its frame is the vehicle frame, so its pose is the identity by definition"
                ));
            } else if let Picked::TooSparse { pairs } = trajectory_sweeps::pick(
                drive,
                &reference,
                config.lidars.trajectory_sweeps,
                &request.segments_nanos,
            ) {
                decisions.push(format!(
                    "lidars: {reference} (the reference) stays where the initial guess puts it: {}",
                    too_sparse_why(pairs)
                ));
            } else if motion.turn_deg < MIN_TURN_DEG && motion.distance_m < MIN_STRAIGHT_DISTANCE_M
            {
                decisions.push(format!(
                    "lidars: {reference} (the reference) stays where the initial guess puts it: the drive turns {:.0}° and travels {:.0} m, too little to fit it to the trajectory (at least {MIN_TURN_DEG:.0}°, or {MIN_STRAIGHT_DISTANCE_M:.0} m)",
                    motion.turn_deg, motion.distance_m
                ));
            } else if motion.turn_deg < MIN_TURN_DEG {
                stages.push(Stage::LidarToTrajectory {
                    lidar: reference.clone(),
                });
                decisions.push(format!(
                    "lidars: {reference} (the reference) fitted to the trajectory only where the drive observes it: it turns {:.0}° (under {MIN_TURN_DEG:.0}°), so its travel fixes the LiDAR's pitch and yaw; its roll about the drive and its position stay where the initial guess puts them",
                    motion.turn_deg
                ));
            } else {
                stages.push(Stage::LidarToTrajectory {
                    lidar: reference.clone(),
                });
                decisions.push(format!(
                    "lidars: {reference} (the reference) fitted to the trajectory by its own sweeps: the drive turns {:.0}°",
                    motion.turn_deg
                ));
            }
            let others: Vec<String> = lidars
                .iter()
                .filter(|l| **l != reference && asked(l))
                .cloned()
                .collect();
            if !others.is_empty() {
                decisions.push(format!(
                    "lidars: {} registered to {reference} by point-to-plane ICP, then held",
                    others.join(", ")
                ));
                stages.push(Stage::LidarIcp {
                    reference: reference.clone(),
                    lidars: others,
                });
            }
        } else if stationary {
            // One vehicle pose: a LiDAR's pose on the vehicle moves its whole scene with it, so
            // nothing observes the reference's; the others are placed against it by the scene.
            let others = lidars.iter().any(|l| *l != reference && asked(l));
            decisions.push(format!(
                "lidars: not registered first (lidars.register off){}; {reference} (the reference) stays: the vehicle does not move, so nothing places it on the vehicle",
                if others { ": UniCal moves the others" } else { "" }
            ));
        } else {
            decisions.push(
                "lidars: not registered first (lidars.register off): UniCal moves them".into(),
            );
        }
        // Cameras.
        let mut hand_eye = Vec::new();
        let mut straight_travel = None;
        if cameras.is_empty() {
            decisions.push("cameras: none with intrinsics and images to calibrate".into());
        } else if stationary {
            decisions.push(format!(
                "cameras: the vehicle does not move ({:.1} m): {} calibrated against {reference} by checkerboards where boards are found, else by edge alignment",
                motion.distance_m,
                cameras.join(", ")
            ));
            stages.push(Stage::StationaryCameras {
                reference: reference.clone(),
                cameras: cameras.clone(),
            });
        } else {
            match config.cameras.hand_eye {
                HandEye::Never => decisions.push("cameras: no hand-eye start (cameras.hand_eye: never)".into()),
                _ if motion.turn_deg < MIN_TURN_DEG => decisions.push(format!(
                    "cameras: no hand-eye start: the drive turns {:.0}°, too little for the cameras' own motion to place them",
                    motion.turn_deg
                )),
                HandEye::Always => {
                    hand_eye = cameras.clone();
                    decisions.push("cameras: every camera fitted to its own motion first (cameras.hand_eye: always)".into());
                }
                HandEye::Auto => {
                    hand_eye = cameras.clone();
                    decisions.push(format!(
                        "cameras: each camera fitted to its own motion first (the drive turns {:.0}°), the fit kept where the camera's edges align with {reference}'s better than at the start",
                        motion.turn_deg
                    ));
                }
            }
            if motion.turn_deg < MIN_TURN_DEG && motion.travel_vehicle != DVec3::ZERO {
                let d = motion.travel_vehicle;
                decisions.push(format!(
                    "cameras: the drive turns {:.0}° (under {MIN_TURN_DEG:.0}°): on a drive this straight a camera's position along the travel (vehicle ({:.2}, {:.2}, {:.2})) is weakly observed and confounded with an image delay (the paper's trajectory study, Table A8); UniCal moves it, and the report marks it",
                    motion.turn_deg, d.x, d.y, d.z
                ));
                straight_travel = Some(d);
            }
            if !hand_eye.is_empty() {
                stages.push(Stage::CameraHandEye {
                    cameras: hand_eye.clone(),
                    checked: config.cameras.hand_eye == HandEye::Auto,
                });
            }
        }
        // UniCal.
        let images = config
            .cameras
            .images_per_camera
            .unwrap_or(preset.images_per_camera);
        let scale = config.cameras.image_scale.unwrap_or(preset.image_scale);
        let unical_cameras: Vec<String> = if stationary {
            Vec::new()
        } else {
            cameras.clone()
        };
        // Without motion UniCal holds the reference LiDAR (above), and runs at all only for
        // another LiDAR or a camera.
        let hold_reference = !config.lidars.register && stationary;
        let lidars_move = !config.lidars.register
            && lidars
                .iter()
                .any(|l| asked(l) && !(hold_reference && *l == reference));
        let mut iterations = config.iterations.unwrap_or(preset.iterations);
        let run_unical = !unical_cameras.is_empty() || lidars_move;
        if run_unical {
            // The sweeps that shape the scene, as the stage will pick them.
            let stamps = crate::unical::calibrator::training_stamps(
                drive,
                rig,
                if unical_cameras.is_empty() { 0 } else { images },
                &request.segments_nanos,
            );
            let sweeps: Vec<(&String, usize)> = lidars
                .iter()
                .map(|l| {
                    let picked = crate::unical::scene_sweeps::pick(
                        drive,
                        l,
                        config.lidars.scene_sweeps,
                        &request.segments_nanos,
                        &stamps,
                    );
                    (l, picked.len())
                })
                .collect();
            let added: usize = sweeps
                .iter()
                .map(|(_, n)| n.saturating_sub(config.lidars.scene_sweeps))
                .sum();
            let camera_rays = (unical_cameras.len() as f64) * config.unical.rays_per_camera as f64;
            let lidar_rays = (lidars.len() as f64) * config.unical.rays_per_sensor as f64;
            let step_secs = camera_rays * SECS_PER_CAMERA_RAY + lidar_rays * SECS_PER_LIDAR_RAY;
            let prepare = PREPARE_SECS
                + PREPARE_SECS_PER_IMAGE * images as f64 * unical_cameras.len() as f64
                + PREPARE_SECS_PER_ADDED_SWEEP * added as f64;
            if let (None, Some(budget)) = (config.iterations, resolved.budget_secs) {
                let fits = ((budget - prepare) / step_secs.max(1e-6)).floor().max(0.0) as usize;
                // Fewer steps than the poses' warm-up and ramp would leave them unmoved.
                let least = config
                    .unical
                    .pose_warmup
                    .saturating_add(config.unical.pose_ramp);
                let cut = fits.max(least).min(iterations);
                if cut < iterations {
                    decisions.push(format!(
                        "unical: {cut} steps instead of the quality's {iterations} to fit the budget (about {:.2} s a step planned; the run stops at the budget)",
                        step_secs
                    ));
                    iterations = cut;
                }
            }
            let what = if unical_cameras.is_empty() {
                "every LiDAR".to_string()
            } else {
                format!(
                    "{} camera(s) on {images} image(s) each at scale {scale}",
                    unical_cameras.len()
                )
            };
            let shaped: Vec<String> = sweeps
                .iter()
                .map(|(l, n)| format!("{n} sweep(s) of {l}"))
                .collect();
            let nearest = if stamps.is_empty() {
                ""
            } else {
                ", and the nearest to each image a camera is fitted on"
            };
            decisions.push(format!(
                "unical: one scene from {} ({} spread over the drive{nearest}), {what}, {iterations} steps (about {} planned){}",
                shaped.join(", "),
                config.lidars.scene_sweeps,
                format_secs(prepare + iterations as f64 * step_secs),
                if lidars_move { "" } else { "; the LiDARs held" }
            ));
            stages.push(Stage::Unical {
                cameras: unical_cameras,
                images_per_camera: images,
                image_scale: scale,
                iterations,
            });
        }
        resolved.iterations = Some(iterations);
        resolved.cameras.images_per_camera = Some(images);
        resolved.cameras.image_scale = Some(scale);
        let held: Vec<String> = rig
            .sensors
            .iter()
            .filter(|s| {
                !asked(&s.name)
                    || (config.lidars.register && s.kind == SensorKind::Lidar)
                    || (hold_reference && s.name == reference)
            })
            .map(|s| s.name.clone())
            .collect();
        let unical = DepthCalibConfig {
            iterations,
            seed: config.seed,
            frozen_sensor: request.root.clone(),
            held_sensors: held,
            ..config.unical.clone()
        };
        Ok(Plan {
            stages,
            decisions,
            reference_lidar: Some(reference),
            config: resolved,
            unical,
            request: request.clone(),
            straight_travel,
        })
    }

    /// The UniCal stage, if the plan has one.
    pub fn unical_stage(&self) -> Option<&Stage> {
        self.stages
            .iter()
            .find(|s| matches!(s, Stage::Unical { .. }))
    }

    /// The cameras the hand-eye fits first.
    pub fn hand_eye_cameras(&self) -> &[String] {
        self.stages
            .iter()
            .find_map(|s| match s {
                Stage::CameraHandEye { cameras, .. } => Some(cameras.as_slice()),
                _ => None,
            })
            .unwrap_or(&[])
    }

    /// Whether `camera` is fitted by the stationary stage (checkerboards or edge alignment),
    /// whose result the report also checks by mutual information.
    pub fn stationary_camera(&self, camera: &str) -> bool {
        self.stages.iter().any(|s| {
            matches!(s, Stage::StationaryCameras { cameras, .. } if cameras.iter().any(|c| c == camera))
        })
    }

    /// The images of `camera` that the last stage fitting it (UniCal, else the hand-eye, else a
    /// stationary log's edge alignment) uses,
    /// so that the check of its result can keep to others.
    pub fn fitted_images(&self, drive: &Drive, camera: &str) -> Vec<usize> {
        let has = |cameras: &[String]| cameras.iter().any(|c| c == camera);
        let segments = &self.request.segments_nanos;
        self.stages
            .iter()
            .rev()
            .find_map(|s| match s {
                Stage::Unical {
                    cameras,
                    images_per_camera,
                    ..
                } if has(cameras) => Some(crate::unical::calibrator::training_images(
                    drive,
                    camera,
                    *images_per_camera,
                    segments,
                )),
                // The edge alignment's frames (the checkerboards' are whichever show boards).
                Stage::StationaryCameras { reference, cameras } if has(cameras) => {
                    Some(crate::optim::edge_align::picked_images(
                        drive,
                        (camera, reference),
                        super::run::STATIONARY_EDGE_FRAMES,
                        segments,
                    ))
                }
                Stage::CameraHandEye { cameras, .. } if has(cameras) => {
                    Some(crate::classical::camera_motion::picked_images(
                        drive,
                        camera,
                        crate::classical::camera_motion::DEFAULT_FRAMES,
                        segments,
                    ))
                }
                _ => None,
            })
            .unwrap_or_default()
    }

    /// Whether the hand-eye keeps only the fits its edge check prefers to the start.
    pub fn hand_eye_checked(&self) -> bool {
        self.stages
            .iter()
            .any(|s| matches!(s, Stage::CameraHandEye { checked: true, .. }))
    }
}

/// `9 min 30 s`, `45 s`.
pub fn format_secs(secs: f64) -> String {
    let s = secs.max(0.0).round() as u64;
    match (s / 3600, (s % 3600) / 60, s % 60) {
        (0, 0, s) => format!("{s} s"),
        (0, m, 0) => format!("{m} min"),
        (0, m, s) => format!("{m} min {s} s"),
        (h, m, _) => format!("{h} h {m} min"),
    }
}

/// Why a LiDAR whose sweeps share no surfaces is not fitted to the trajectory.
pub fn too_sparse_why(pairs: usize) -> String {
    format!(
        "its sweeps are too far apart to share the surfaces the fit compares: {pairs} consecutive pair(s) within {OVERLAP_M:.0} m of each other, at least {MIN_PAIRS} needed"
    )
}
