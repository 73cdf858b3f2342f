//! A camera's motion pairs read from a drive, and the hand-eye fit of its extrinsic
//! ([`super::hand_eye`]): the images, their keypoints and the trajectory at their stamps.
//!
//! How it works. `frames` images of the camera spread over the selected segments are decoded
//! and their keypoints found at up to 960 px wide (oriented FAST + steered BRIEF, as the
//! correspondence stage finds them), positions kept in the full image's pixels so the camera
//! model unprojects them. Every pair of them whose vehicle poses are 1–8 m apart is matched
//! and verified in parallel; the solve then fits the extrinsic from the camera's start.

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::hand_eye::{HandEyeFit, candidate_pairs, check_turns, motion_pairs, solve};
use crate::calib::Rig;
use crate::log::{Drive, spread_evenly};
use crate::unical::correspondences::training_keypoints;

/// Images per camera the CLI's `--camera-hand-eye` reads.
pub const DEFAULT_FRAMES: usize = 48;

/// How far (degrees) UniCal may turn a camera from its hand-eye fit
/// ([`crate::unical::depth_calib::DepthCalibConfig::camera_rotation_bounds_deg`]): the fit
/// brings rotations from 10° to within 0.7° on the simulator's drives (BENCHMARKS.md), so a
/// camera the scene pulls further than this has slid into a wrong basin.
pub const ROTATION_BOUND_DEG: f64 = 1.0;

/// Fit camera `name` of `rig` to its motion over `frames` images of `drive` within
/// `segments_nanos`, reporting `(done, total)` per phase name.
pub fn fit_camera(
    drive: &Drive,
    rig: &Rig,
    name: &str,
    frames: usize,
    segments_nanos: &[(i64, i64)],
    report: &(dyn Fn(&str, usize, usize) + Sync),
) -> Result<HandEyeFit, String> {
    let sensor = rig
        .sensor(name)
        .ok_or_else(|| format!("no camera '{name}' in the rig"))?;
    let intrinsics = sensor
        .camera
        .as_ref()
        .ok_or_else(|| format!("'{name}' has no intrinsics"))?;
    let stream = drive
        .stream(name)
        .ok_or_else(|| format!("the log has no images of '{name}'"))?;
    let picked = spread_evenly(&drive.frames_within(name, segments_nanos), frames);
    let stamps: Vec<i64> = picked
        .iter()
        .map(|&i| stream.frames[i].stamp_nanos)
        .collect();
    // A drive too straight for the fit is refused before any image is decoded.
    let candidates = candidate_pairs(&drive.trajectory, &stamps);
    check_turns(&candidates).map_err(|e| e.to_string())?;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let keypoints = picked
        .par_iter()
        .map(|&i| {
            let img = drive.load_image(name, i).map_err(|e| e.to_string())?;
            let found = training_keypoints(img.as_ref(), img.width());
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            report("camera keypoints", n, picked.len());
            Ok(found)
        })
        .collect::<Result<Vec<_>, String>>()?;
    let unproject = |x: f64, y: f64| -> Option<DVec3> { intrinsics.unproject(DVec2::new(x, y)) };
    let pairs = motion_pairs(&keypoints, &candidates, &unproject, &|d, t| {
        report("camera motion", d, t)
    });
    solve(&pairs, sensor.vehicle_from_sensor).map_err(|e| e.to_string())
}

/// What the hand-eye did to one camera of a rig.
#[derive(Clone, Debug)]
pub struct CameraOutcome {
    pub name: String,
    /// The fit, or why the camera kept its start.
    pub fit: Result<HandEyeFit, String>,
    /// How far the fit moved the camera (rad, m); zero when it was kept.
    pub moved: (f64, f64),
}

impl CameraOutcome {
    /// One line for a log or a status bar.
    pub fn summary(&self) -> String {
        let name = &self.name;
        match &self.fit {
            Ok(fit) => {
                let kept = if fit.unobserved.is_empty() {
                    String::new()
                } else {
                    format!(
                        " ({} not observed by the drive: kept)",
                        fit.unobserved.join(", ")
                    )
                };
                format!(
                    "camera hand-eye: {name} moved {:.3}° / {:.1} cm to fit its motion{kept}; \
                     {} of {} image pairs, median residuals {:.2}° (rotation) and {:.2}° \
                     (direction)",
                    self.moved.0.to_degrees(),
                    self.moved.1 * 100.0,
                    fit.pairs_used,
                    fit.pairs_given,
                    fit.rotation_residual_deg,
                    fit.direction_residual_deg,
                )
            }
            Err(e) => format!("camera hand-eye: {name} kept: {e}"),
        }
    }
}

/// Fit each camera of `names` in `rig` to its own motion ([`fit_camera`], `frames` images
/// each), one after the other (each fit is parallel inside). Returns the rig with every fitted
/// camera moved, and each camera's outcome; a camera that cannot be fitted keeps its start.
/// `report` gets phase names prefixed with the camera's.
pub fn fit_rig_cameras(
    drive: &Drive,
    rig: &Rig,
    names: &[String],
    frames: usize,
    segments_nanos: &[(i64, i64)],
    report: &(dyn Fn(&str, usize, usize) + Sync),
) -> (Rig, Vec<CameraOutcome>) {
    let mut out = rig.clone();
    let mut outcomes = Vec::with_capacity(names.len());
    for name in names {
        let fit = fit_camera(drive, rig, name, frames, segments_nanos, &|phase, d, t| {
            report(&format!("{name}: {phase}"), d, t)
        });
        let mut moved = (0.0, 0.0);
        if let (Ok(fit), Some(sensor)) = (&fit, out.sensor_mut(name)) {
            moved = sensor
                .vehicle_from_sensor
                .difference(fit.vehicle_from_camera);
            sensor.vehicle_from_sensor = fit.vehicle_from_camera;
        }
        outcomes.push(CameraOutcome {
            name: name.clone(),
            fit,
            moved,
        });
    }
    (out, outcomes)
}
