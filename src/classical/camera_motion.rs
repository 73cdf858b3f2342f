//! A camera's motion pairs read from a drive, and the hand-eye fit of its extrinsic
//! ([`super::hand_eye`]): the images, their keypoints and the trajectory at their stamps (at
//! their middle row's time with a rolling shutter, [`Drive::camera_readout`]).
//!
//! How it works. `frames` images of the camera spread over the selected segments are decoded
//! and their keypoints found at up to 960 px wide (oriented FAST + steered BRIEF, as the
//! correspondence stage finds them), positions kept in the full image's pixels so the camera
//! model unprojects them. Every pair of them whose vehicle poses are 1–8 m apart is matched
//! and verified in parallel; the solve then fits the extrinsic from the camera's start.

use crate::error::RunError;
use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::hand_eye::{HandEyeFit, MotionPair, candidate_pairs, check_turns, motion_pairs, solve};
use super::lidar_translation::{LidarMap, MapFit, fit_translation_and_turns};
use crate::calib::Rig;
use crate::geometry::Rigid;
use crate::log::{Drive, spread_evenly};
use crate::unical::correspondences::training_keypoints;

/// Images per camera the CLI's `--camera-hand-eye` reads.
pub const DEFAULT_FRAMES: usize = 48;

/// How far (degrees) UniCal may turn a camera from its hand-eye fit
/// ([`crate::unical::depth_calib::DepthCalibConfig::camera_rotation_bounds_deg`]): the fit
/// brings rotations from 10° to within 0.7° on the simulator's drives (47 of 54 fits within
/// 0.2°; docs/experiments/hand-eye-start.md), so a camera the scene pulls further than this has slid into a wrong
/// basin. At 1° drive 7's back camera reached such a basin (0.5° / 18 cm) and stayed; at 0.5°
/// it holds within 0.07°, and the worst fit measured still leaves the truth within reach of
/// 0.2° (docs/experiments/correspondence-term.md, "A tighter rotation bound").
pub const ROTATION_BOUND_DEG: f64 = 0.5;

/// One camera's image pairs with verified motion, and the vehicle pose of each of its frames
/// (what [`MotionPair::first_image`] indexes).
pub struct CameraPairs {
    /// The camera's extrinsic in the rig it was read with: where a fit starts.
    pub start: Rigid,
    pub pairs: Vec<MotionPair>,
    /// `None` for a frame outside the trajectory (no candidate pair uses one).
    pub world_from_vehicle: Vec<Option<Rigid>>,
}

/// The images of camera `name` the hand-eye reads: `frames` of them spread evenly over
/// `segments_nanos` (a check of its fit keeps off them).
pub fn picked_images(
    drive: &Drive,
    name: &str,
    frames: usize,
    segments_nanos: &[(i64, i64)],
) -> Vec<usize> {
    spread_evenly(&drive.frames_within(name, segments_nanos), frames)
}

/// The motion pairs of camera `name` of `rig` over `frames` images of `drive` within
/// `segments_nanos`, reporting `(done, total)` per phase name. With `require_turns`, a drive too
/// straight for the hand-eye is refused before any image is decoded (the map fits of
/// [`super::lidar_translation`] need no turns).
pub fn camera_pairs(
    drive: &Drive,
    rig: &Rig,
    name: &str,
    frames: usize,
    segments_nanos: &[(i64, i64)],
    require_turns: bool,
    report: &(dyn Fn(&str, usize, usize) + Sync),
) -> Result<CameraPairs, RunError> {
    let sensor = rig
        .sensor(name)
        .ok_or_else(|| RunError::no_sensor("camera", name))?;
    let intrinsics = sensor
        .camera
        .as_ref()
        .ok_or_else(|| RunError::Invalid(format!("'{name}' has no intrinsics")))?;
    let stream = drive
        .stream(name)
        .ok_or_else(|| RunError::NotEnoughData(format!("the log has no images of '{name}'")))?;
    let picked = picked_images(drive, name, frames, segments_nanos);
    // A rolling-shutter image stands at its middle row's time.
    let stamps: Vec<i64> = picked
        .iter()
        .map(|&i| stream.frames[i].stamp_nanos + drive.camera_readout.middle_nanos())
        .collect();
    let candidates = candidate_pairs(&drive.trajectory, &stamps);
    if require_turns {
        check_turns(&candidates)?;
    }
    let done = std::sync::atomic::AtomicUsize::new(0);
    let keypoints = picked
        .par_iter()
        .map(|&i| {
            // An image that does not decode has no keypoints (the drive reports it).
            let found = match drive.image_or_skip(name, i) {
                Some(img) => training_keypoints(img.as_ref(), img.width()),
                None => Default::default(),
            };
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            report("camera keypoints", n, picked.len());
            found
        })
        .collect::<Vec<_>>();
    let unproject = |x: f64, y: f64| -> Option<DVec3> { intrinsics.unproject(DVec2::new(x, y)) };
    let pairs = motion_pairs(&keypoints, &candidates, &unproject, &|d, t| {
        report("camera motion", d, t)
    });
    let world_from_vehicle = stamps
        .iter()
        .map(|&t| drive.trajectory.world_from_vehicle(t).ok())
        .collect();
    Ok(CameraPairs {
        start: sensor.vehicle_from_sensor,
        pairs,
        world_from_vehicle,
    })
}

/// Fit camera `name` of `rig` to its motion over `frames` images of `drive` within
/// `segments_nanos`, reporting `(done, total)` per phase name.
pub fn fit_camera(
    drive: &Drive,
    rig: &Rig,
    name: &str,
    frames: usize,
    segments_nanos: &[(i64, i64)],
    report: &(dyn Fn(&str, usize, usize) + Sync),
) -> Result<HandEyeFit, RunError> {
    let found = camera_pairs(drive, rig, name, frames, segments_nanos, true, report)?;
    Ok(solve(&found.pairs, found.start)?)
}

/// What the hand-eye did to one camera of a rig.
#[derive(Clone, Debug)]
pub struct CameraOutcome {
    pub name: String,
    /// The fit, or why the camera kept its start.
    pub fit: Result<HandEyeFit, String>,
    /// The translation (and the turns [`weak_turns`] names) then measured against the LiDAR
    /// map ([`super::lidar_translation`]), or why not; `None` without a map or a fit.
    pub translation: Option<Result<MapFit, String>>,
    /// How far the fits moved the camera (rad, m); zero when it was kept.
    pub moved: (f64, f64),
    /// Rounds of hand-eye fit and map fit ([`fit_with_map`]); 0 when no fit was made.
    pub rounds: usize,
}

impl CameraOutcome {
    /// One line for a log or a status bar.
    pub fn summary(&self) -> String {
        let name = &self.name;
        let fit = match &self.fit {
            Ok(fit) => fit,
            Err(e) => return format!("camera hand-eye: {name} kept: {e}"),
        };
        let kept = match (fit.unobserved.is_empty(), &self.translation) {
            (true, _) => String::new(),
            (false, Some(Ok(_))) => format!(
                " ({} not observed by the drive: measured against the LiDAR map)",
                fit.unobserved.join(", ")
            ),
            (false, _) => format!(
                " ({} not observed by the drive: kept)",
                fit.unobserved.join(", ")
            ),
        };
        let weak = weak_turns(fit);
        let turns = if weak.is_empty() {
            String::new()
        } else {
            let named: Vec<String> = weak
                .iter()
                .map(|&k| {
                    format!(
                        "{} (σ {:.2}°)",
                        ["x", "y", "z"][k],
                        fit.rotation_sigma_deg[k]
                    )
                })
                .collect();
            format!(
                " and its turn about its own {}, which its motion observes weakly,",
                named.join(", ")
            )
        };
        let lidar = match &self.translation {
            None => String::new(),
            Some(Ok(t)) => format!(
                "; translation{turns} against the LiDAR map: {} points, median {:.1} cm off it{}",
                t.points,
                t.median_residual_m * 100.0,
                if t.unobserved.is_empty() {
                    String::new()
                } else {
                    format!(" ({} not observed: kept)", t.unobserved.join(", "))
                }
            ),
            Some(Err(e)) => format!("; translation against the LiDAR map not measured: {e}"),
        };
        let rounds = if self.rounds > 1 {
            format!(
                "; fitted {} times, each from the map's translation of the round before",
                self.rounds
            )
        } else {
            String::new()
        };
        format!(
            "camera hand-eye: {name} moved {:.3}° / {:.1} cm to fit its motion{kept}; {} of {} \
             image pairs, median residuals {:.2}° (rotation) and {:.2}° (direction){lidar}{rounds}",
            self.moved.0.to_degrees(),
            self.moved.1 * 100.0,
            fit.pairs_used,
            fit.pairs_given,
            fit.rotation_residual_deg,
            fit.direction_residual_deg,
        )
    }
}

/// A turn of the hand-eye fit about a camera axis whose 1-σ is above this (degrees) is left to
/// the LiDAR map. On the simulator's figure-8 drives a side camera whose motion barely observes
/// its tilt comes with σ 0.37–0.45° about its x axis (and was 0.39–0.75° off); every other
/// turn of every camera had σ ≤ 0.07° (docs/experiments/pipeline.md).
pub const WEAK_TURN_DEG: f64 = 0.1;

/// The camera axes (0 = x, 1 = y, 2 = z) about which `fit`'s rotation is weakly observed. An
/// infinite σ (a fit without matches to measure it on) is unknown, not weak: none is freed.
pub fn weak_turns(fit: &HandEyeFit) -> Vec<usize> {
    (0..3)
        .filter(|&k| {
            let sigma = fit.rotation_sigma_deg[k];
            sigma.is_finite() && sigma > WEAK_TURN_DEG
        })
        .collect()
}

/// Fit each camera of `names` in `rig` to its own motion (the hand-eye of [`fit_camera`],
/// `frames` images each), then, with a `map`, its translation and its [`weak_turns`] to the
/// LiDAR map; one camera after the other (each fit is parallel inside). Returns the rig with
/// every fitted camera moved, and each camera's outcome; a camera that cannot be fitted keeps
/// its start. `report` gets phase names prefixed with the camera's.
pub fn fit_rig_cameras(
    drive: &Drive,
    rig: &Rig,
    names: &[String],
    frames: usize,
    segments_nanos: &[(i64, i64)],
    map: Option<&LidarMap>,
    report: &(dyn Fn(&str, usize, usize) + Sync),
) -> (Rig, Vec<CameraOutcome>) {
    let mut out = rig.clone();
    let mut outcomes = Vec::with_capacity(names.len());
    for name in names {
        let found = camera_pairs(
            drive,
            rig,
            name,
            frames,
            segments_nanos,
            true,
            &|phase, d, t| report(&format!("{name}: {phase}"), d, t),
        );
        let (fit, translation, rounds) = match &found {
            Ok(found) => fit_with_map(found, map),
            Err(e) => (Err(e.to_string()), None, 0),
        };
        let mut moved = (0.0, 0.0);
        let fitted = match &translation {
            Some(Ok(t)) => Some(t.vehicle_from_camera),
            _ => fit.as_ref().ok().map(|f| f.vehicle_from_camera),
        };
        if let (Some(fitted), Some(sensor)) = (fitted, out.sensor_mut(name)) {
            moved = sensor.vehicle_from_sensor.difference(fitted);
            sensor.vehicle_from_sensor = fitted;
        }
        outcomes.push(CameraOutcome {
            name: name.clone(),
            fit,
            translation,
            moved,
            rounds,
        });
    }
    (out, outcomes)
}

/// At most this many rounds of hand-eye fit and map fit per camera ([`fit_with_map`]); on the
/// simulator's drives (seeds 50, 952, 961, 971, 972) the second round settles the fits: the
/// third changes no camera's error by more than 0.005° or 3 mm (docs/experiments/pipeline.md,
/// "The hand-eye's pull to its start").
const MAX_ROUNDS: usize = 3;

/// A round changes the camera by less than this (degrees, metres): the fits have settled.
const SETTLED: (f64, f64) = (0.005, 0.001);

/// The hand-eye fit of `found` from its start and, with a `map`, the translation (and the
/// [`weak_turns`]) measured against it; then, while that moves the camera, the hand-eye fitted
/// again from the map's pose and the map fit repeated. Why: the fit holds the directions of
/// the translation its drive does not observe at the start and pulls the rest toward it, and a
/// turning pair's predicted camera motion depends on that lever arm, so a start a metre off
/// biases the rotation (seed 50 of the simulator: a side camera's tilt 0.99° off with a 1-σ of
/// 0.09°, so not freed for the map). Fitted again from the map's translation the same camera
/// ends 0.05° off, and every start of a drive ends at one fit.
/// Returns the last round's fit and map fit, and the number of rounds.
pub fn fit_with_map(
    found: &CameraPairs,
    map: Option<&LidarMap>,
) -> (
    Result<HandEyeFit, String>,
    Option<Result<MapFit, String>>,
    usize,
) {
    let measure = |fit: &HandEyeFit| {
        map.map(|map| {
            fit_translation_and_turns(
                map,
                &found.pairs,
                &found.world_from_vehicle,
                fit.vehicle_from_camera,
                &weak_turns(fit),
            )
            .map_err(|e| e.to_string())
        })
    };
    let mut fit = solve(&found.pairs, found.start).map_err(|e| e.to_string());
    let mut translation = fit.as_ref().ok().and_then(measure);
    let mut rounds = usize::from(fit.is_ok());
    while rounds < MAX_ROUNDS {
        let Some(Ok(measured)) = &translation else {
            break;
        };
        let from = measured.vehicle_from_camera;
        let Ok(next) = solve(&found.pairs, from) else {
            break;
        };
        let Some(Ok(next_measured)) = measure(&next) else {
            break;
        };
        let (turned, shifted) = from.difference(next_measured.vehicle_from_camera);
        fit = Ok(next);
        translation = Some(Ok(next_measured));
        rounds += 1;
        if turned.to_degrees() < SETTLED.0 && shifted < SETTLED.1 {
            break;
        }
    }
    (fit, translation, rounds)
}

/// The LiDAR map [`fit_rig_cameras`] measures translations against: every LiDAR of `rig`
/// (at its extrinsic there), 16 sweeps each spread over the drive, one point per 10 cm voxel.
pub fn lidar_map(drive: &Drive, rig: &Rig) -> Result<LidarMap, RunError> {
    let config = crate::optim::photo_consistency::PhotoConfig::default();
    Ok(crate::optim::photo_consistency::lidar_map(drive, rig, &config).map(LidarMap::new)?)
}

#[cfg(test)]
mod tests;
