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

use super::hand_eye::{HandEyeFit, candidate_pairs, motion_pairs, solve};
use crate::calib::Rig;
use crate::log::{Drive, spread_evenly};
use crate::unical::correspondences::training_keypoints;

/// Images per camera the CLI's `--camera-hand-eye` reads.
pub const DEFAULT_FRAMES: usize = 48;

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
    let candidates = candidate_pairs(&drive.trajectory, &stamps);
    let unproject = |x: f64, y: f64| -> Option<DVec3> { intrinsics.unproject(DVec2::new(x, y)) };
    let pairs = motion_pairs(&keypoints, &candidates, &unproject, &|d, t| {
        report("camera motion", d, t)
    });
    solve(&pairs, sensor.vehicle_from_sensor).map_err(|e| e.to_string())
}
