//! Running a [`Plan`]'s stages: the classical LiDAR registration, the cameras' hand-eye start,
//! and the UniCal calibrator they lead to. The CLI, the studio and `bench` call these; each
//! reports what it did as lines of text (for a terminal or a status bar) and through
//! `progress(phase, done, total)`.

use crate::calib::Rig;
use crate::classical::camera_motion::{self, CameraOutcome};
use crate::classical::icp::IcpConfig;
use crate::classical::icp_calibrator::IcpCalibrator;
use crate::classical::trajectory_icp::{
    MIN_STRAIGHT_DISTANCE_M, MIN_TURN_DEG, TrajectoryFit, register_to_trajectory,
};
use crate::error::RunError;
use crate::log::Drive;
use crate::optim::runner::Calibrator;
use crate::unical::calibrator::{UnicalLidarStage, training_stamps};

use super::plan::{Plan, Stage, too_sparse_why};

/// Frames of each camera the hand-eye's fit is checked on against its start.
const HAND_EYE_CHECK_FRAMES: usize = 6;

/// `(phase, done, total)`.
pub type Progress<'a> = &'a (dyn Fn(&str, usize, usize) + Sync);

/// What the LiDAR stages found, for the report.
#[derive(Clone, Debug, Default)]
pub struct LidarEvidence {
    /// The reference's fit to the trajectory: the directions it did not observe (vehicle
    /// axes: roll, pitch, yaw, x, y, z), or why it was not fitted.
    pub reference_fit: Option<Result<Vec<&'static str>, String>>,
    /// Each registered LiDAR's ICP information at its result (vehicle frame, left
    /// perturbation, rotation first; [`crate::classical::icp::IcpProblem::information`]).
    pub icp_information: Vec<(String, [f64; 36])>,
}

/// Register the reference LiDAR to the trajectory by its own sweeps (unless `root` is it, or
/// `fit_reference` is off) and every LiDAR of `others` to it by point-to-plane ICP, each run
/// to convergence. Returns the rig, one line per result, and the evidence for the report.
pub fn register_lidars(
    drive: &Drive,
    rig: &Rig,
    reference: &str,
    fit_reference: bool,
    others: &[String],
    sweeps: (usize, usize),
    segments_nanos: &[(i64, i64)],
    progress: Progress,
) -> Result<(Rig, Vec<String>, LidarEvidence), RunError> {
    let (trajectory_sweeps, icp_sweeps) = sweeps;
    let mut rig = rig.clone();
    let mut notes = Vec::new();
    let mut evidence = LidarEvidence::default();
    if fit_reference {
        let fit = register_to_trajectory(
            drive,
            &rig,
            reference,
            trajectory_sweeps,
            segments_nanos,
            IcpConfig::default(),
            &mut |done, total| progress("lidar to trajectory", done, total),
        )?;
        match (fit, rig.sensor_mut(reference)) {
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
                notes.push(format!(
                    "lidar icp: {reference} moved {:.3}° / {:.1} cm to fit the trajectory{kept}",
                    rot.to_degrees(),
                    trans * 100.0
                ));
                s.vehicle_from_sensor = vehicle_from_lidar;
                evidence.reference_fit = Some(Ok(unobserved));
            }
            (
                TrajectoryFit::TooStraight {
                    turn_deg,
                    distance_m,
                },
                _,
            ) => {
                let why = format!(
                    "the drive turns {turn_deg:.1}° and travels {distance_m:.0} m between its sweeps, too little to fit it to the trajectory (at least {MIN_TURN_DEG}°, or {MIN_STRAIGHT_DISTANCE_M} m)"
                );
                notes.push(format!("lidar icp: {reference} kept: {why}"));
                evidence.reference_fit = Some(Err(why));
            }
            (TrajectoryFit::TooSparse { pairs }, _) => {
                let why = too_sparse_why(pairs);
                notes.push(format!("lidar icp: {reference} kept: {why}"));
                evidence.reference_fit = Some(Err(why));
            }
            (TrajectoryFit::Fitted { .. }, None) => {}
        }
    }
    let others: Vec<&String> = others.iter().filter(|l| *l != reference).collect();
    if others.is_empty() || rig.lidars().count() < 2 {
        return Ok((rig, notes, evidence));
    }
    let mut icp = IcpCalibrator::from_drive(
        drive,
        &rig,
        reference,
        icp_sweeps,
        segments_nanos,
        IcpConfig::default(),
    )
    .map_err(|e| e.within("lidar icp"))?;
    let total = icp.max_steps();
    for step in 1..=total {
        progress("lidar icp", step, total);
        if icp.step().done {
            break;
        }
    }
    let best = icp.best();
    for lidar in best.lidars() {
        if !others.contains(&&lidar.name) {
            continue;
        }
        if let Some(s) = rig.sensor_mut(&lidar.name) {
            let (rot, trans) = s.vehicle_from_sensor.difference(lidar.vehicle_from_sensor);
            if rot + trans > 0.0 {
                notes.push(format!(
                    "lidar icp: {} moved {:.3}° / {:.1} cm against {reference}",
                    lidar.name,
                    rot.to_degrees(),
                    trans * 100.0
                ));
            }
            s.vehicle_from_sensor = lidar.vehicle_from_sensor;
        }
    }
    for (name, problem) in icp.problems() {
        if others.contains(&name) {
            evidence
                .icp_information
                .push((name.clone(), problem.information()));
        }
    }
    Ok((rig, notes, evidence))
}

/// Fit each camera of `cameras` to its own motion and its translation to the map of `rig`'s
/// LiDARs ([`camera_motion::fit_rig_cameras`]); a camera the drive cannot fit keeps its pose,
/// and its line says why. Returns the rig, the cameras fitted and one line per camera.
pub fn fit_cameras(
    drive: &Drive,
    rig: &Rig,
    cameras: &[String],
    segments_nanos: &[(i64, i64)],
    progress: Progress,
) -> (Rig, Vec<String>, Vec<String>) {
    let mut notes = Vec::new();
    let map = match camera_motion::lidar_map(drive, rig) {
        Ok(map) => Some(map),
        Err(e) => {
            notes.push(format!(
                "camera hand-eye: no LiDAR map to measure translations against: {e}"
            ));
            None
        }
    };
    let (out, outcomes): (Rig, Vec<CameraOutcome>) = camera_motion::fit_rig_cameras(
        drive,
        rig,
        cameras,
        camera_motion::DEFAULT_FRAMES,
        segments_nanos,
        map.as_ref(),
        progress,
    );
    notes.extend(outcomes.iter().map(|o| o.summary()));
    let fitted = outcomes
        .iter()
        .filter(|o| o.fit.is_ok())
        .map(|o| o.name.clone())
        .collect();
    (out, fitted, notes)
}

/// The sweeps of the reference (spread over the log) a stationary log's edge alignment fits
/// each camera on, with the image nearest each ([`crate::optim::edge_align::sweep_image_pairs`]).
pub const STATIONARY_EDGE_FRAMES: usize = 4;

/// A log that stands still: calibrate `cameras` against `reference` by checkerboards where
/// boards are found, else by edge alignment, each run to its end. Returns the rig and one line
/// per decision or result.
pub fn stationary_cameras(
    drive: &Drive,
    rig: &Rig,
    reference: &str,
    cameras: &[String],
    segments_nanos: &[(i64, i64)],
    progress: Progress,
) -> (Rig, Vec<String>) {
    use crate::classical::target::TargetConfig;
    use crate::classical::target_calibrator::TargetCalibrator;
    let mut notes = Vec::new();
    let run = |calibrator: &mut dyn Calibrator, phase: &str| {
        let total = calibrator.max_steps();
        for step in 1..=total {
            progress(phase, step, total);
            if calibrator.step().done {
                break;
            }
        }
        calibrator.best()
    };
    let targets = TargetCalibrator::from_drive(
        drive,
        rig,
        reference,
        cameras,
        segments_nanos,
        TargetConfig::default(),
        &Default::default(),
    );
    let (result, how) = match targets {
        Ok(mut t) => (run(&mut t, "checkerboards"), "checkerboards"),
        Err(e) => {
            notes.push(format!(
                "stationary cameras: no checkerboards to use ({e}): edge alignment instead"
            ));
            match crate::optim::edge_refine::EdgeRefiner::new(
                drive,
                rig,
                (reference, cameras),
                STATIONARY_EDGE_FRAMES,
                segments_nanos,
                drive.camera_readout,
            ) {
                Ok(mut edge) => (run(&mut edge, "edge alignment"), "edge alignment"),
                Err(e) => {
                    notes.push(format!(
                        "stationary cameras: kept: no edge alignment either ({e})"
                    ));
                    return (rig.clone(), notes);
                }
            }
        }
    };
    let mut out = rig.clone();
    for name in cameras {
        if let (Some(s), Some(r)) = (out.sensor_mut(name), result.sensor(name)) {
            let (rot, trans) = s.vehicle_from_sensor.difference(r.vehicle_from_sensor);
            notes.push(format!(
                "stationary cameras: {name} moved {:.3}° / {:.1} cm by {how} against {reference}",
                rot.to_degrees(),
                trans * 100.0
            ));
            s.vehicle_from_sensor = r.vehicle_from_sensor;
        }
    }
    (out, notes)
}

/// What the stages before UniCal did.
#[derive(Clone, Debug, Default)]
pub struct Prepared {
    /// The rig UniCal starts from.
    pub rig: Rig,
    /// The cameras the hand-eye fitted.
    pub fitted: Vec<String>,
    pub notes: Vec<String>,
    pub lidars: LidarEvidence,
}

/// Run the plan's stages before UniCal on `rig`.
pub fn prepare(
    drive: &Drive,
    rig: &Rig,
    plan: &Plan,
    progress: Progress,
) -> Result<Prepared, RunError> {
    let segments = &plan.request.segments_nanos;
    let mut out = Prepared {
        rig: rig.clone(),
        ..Prepared::default()
    };
    let fit_reference = plan
        .stages
        .iter()
        .any(|s| matches!(s, Stage::LidarToTrajectory { .. }));
    let icp = plan.stages.iter().find_map(|s| match s {
        Stage::LidarIcp { reference, lidars } => Some((reference.clone(), lidars.clone())),
        _ => None,
    });
    if let Some(reference) = &plan.reference_lidar
        && (fit_reference || icp.is_some())
    {
        let others = icp.map(|(_, l)| l).unwrap_or_default();
        let sweeps = (
            plan.config.lidars.trajectory_sweeps,
            plan.config.lidars.icp_sweeps,
        );
        let (rig, notes, evidence) = register_lidars(
            drive,
            &out.rig,
            reference,
            fit_reference,
            &others,
            sweeps,
            segments,
            progress,
        )?;
        out.rig = rig;
        out.notes.extend(notes);
        out.lidars = evidence;
    }
    if let Some(Stage::StationaryCameras { reference, cameras }) = plan
        .stages
        .iter()
        .find(|s| matches!(s, Stage::StationaryCameras { .. }))
    {
        let (rig, notes) =
            stationary_cameras(drive, &out.rig, reference, cameras, segments, progress);
        out.rig = rig;
        out.notes.extend(notes);
    }
    let cameras = plan.hand_eye_cameras();
    if !cameras.is_empty() {
        let (mut rig, mut fitted, notes) =
            fit_cameras(drive, &out.rig, cameras, segments, progress);
        out.notes.extend(notes);
        if plan.hand_eye_checked() {
            // A fit is kept where the images agree with it at least as well as with the start:
            // edge alignment against the reference LiDAR, now registered.
            let reference = plan.reference_lidar.clone().unwrap_or_default();
            fitted.retain(|name| {
                let (Some(before), Some(after)) = (out.rig.sensor(name), rig.sensor(name)) else {
                    return false;
                };
                let fitted = camera_motion::picked_images(
                    drive,
                    name,
                    camera_motion::DEFAULT_FRAMES,
                    segments,
                );
                let check = super::edge_check::EdgeCheck::new(
                    drive,
                    &out.rig,
                    (name, &reference),
                    HAND_EYE_CHECK_FRAMES,
                    segments,
                    &fitted,
                );
                let (start, fit) = match &check {
                    Ok(c) => (c.score(before.vehicle_from_sensor), c.score(after.vehicle_from_sensor)),
                    Err(e) => {
                        out.notes.push(format!(
                            "camera hand-eye: {name}: its fit is not checked ({e}): kept"
                        ));
                        return true;
                    }
                };
                let keep = fit <= start;
                out.notes.push(format!(
                    "camera hand-eye: {name}: its edges align with {reference}'s {} at its fit ({fit:.2} px) than at the start ({start:.2} px): {}",
                    if keep { "better" } else { "worse" },
                    if keep { "the fit is kept" } else { "the start is kept" }
                ));
                keep
            });
            for s in &mut rig.sensors {
                if cameras.contains(&s.name)
                    && !fitted.contains(&s.name)
                    && let Some(before) = out.rig.sensor(&s.name)
                {
                    s.vehicle_from_sensor = before.vehicle_from_sensor;
                }
            }
        }
        out.rig = rig;
        out.fitted = fitted;
    }
    Ok(out)
}

/// The plan's UniCal calibrator, started from `prepared`'s rig.
pub fn unical(
    drive: &Drive,
    plan: &Plan,
    prepared: &Prepared,
    progress: Progress,
) -> Result<Option<UnicalLidarStage>, RunError> {
    let Some(Stage::Unical {
        cameras,
        images_per_camera,
        image_scale,
        ..
    }) = plan.unical_stage()
    else {
        return Ok(None);
    };
    let config = plan
        .unical
        .clone()
        .after_hand_eye(&prepared.fitted, camera_motion::ROTATION_BOUND_DEG);
    let config = crate::unical::depth_calib::DepthCalibConfig {
        correspondence_cache: Some(crate::session::state_dir().join("matches")),
        // Cameras left out of UniCal's stage stay where they are.
        held_sensors: {
            let mut held = config.held_sensors.clone();
            held.extend(
                prepared
                    .rig
                    .cameras()
                    .filter(|c| !cameras.contains(&c.name))
                    .map(|c| c.name.clone()),
            );
            held
        },
        ..config
    };
    let frames = if cameras.is_empty() {
        0
    } else {
        *images_per_camera
    };
    let stage = UnicalLidarStage::from_drive_covering(
        drive,
        &prepared.rig,
        plan.config.lidars.scene_sweeps,
        &plan.request.segments_nanos,
        &training_stamps(drive, &prepared.rig, frames, &plan.request.segments_nanos),
        config,
    )?
    .with_cameras_reporting(
        drive,
        frames,
        &plan.request.segments_nanos,
        *image_scale,
        progress,
    )?;
    Ok(Some(stage))
}

/// Whether every pose has settled: over the last `window` samples (one per 25 steps) no
/// sensor turned more than `rotation_deg` or moved more than `translation_m`.
#[derive(Clone, Debug, Default)]
pub struct Settling {
    samples: Vec<Rig>,
}

/// Steps between the samples [`Settling`] compares.
pub const SETTLE_EVERY: usize = 25;
const SETTLE_SAMPLES: usize = 5;
const SETTLE_ROTATION_DEG: f64 = 0.005;
const SETTLE_TRANSLATION_M: f64 = 0.0005;

impl Settling {
    /// Add the rig at a sample step; true once the last samples agree within the thresholds.
    pub fn push(&mut self, rig: Rig) -> bool {
        self.samples.push(rig);
        if self.samples.len() > SETTLE_SAMPLES {
            self.samples.remove(0);
        }
        if self.samples.len() < SETTLE_SAMPLES {
            return false;
        }
        let last = &self.samples[SETTLE_SAMPLES - 1];
        self.samples[..SETTLE_SAMPLES - 1].iter().all(|earlier| {
            earlier.sensors.iter().all(|s| {
                last.sensor(&s.name).is_none_or(|l| {
                    let (rot, trans) = s.vehicle_from_sensor.difference(l.vehicle_from_sensor);
                    rot.to_degrees() <= SETTLE_ROTATION_DEG && trans <= SETTLE_TRANSLATION_M
                })
            })
        })
    }

    /// The criterion, for the output.
    pub fn describe() -> String {
        format!(
            "every pose within {SETTLE_ROTATION_DEG}° and {:.1} mm over {} steps",
            SETTLE_TRANSLATION_M * 1000.0,
            SETTLE_EVERY * (SETTLE_SAMPLES - 1)
        )
    }
}
