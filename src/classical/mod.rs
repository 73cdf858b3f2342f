//! The classical calibrators of the paper's comparison (supplementary A2.1): `icp`
//! (point-to-plane ICP for LiDAR–LiDAR pairs) and `icp_calibrator` (it as a runner
//! `Calibrator`: every LiDAR against a reference LiDAR); `mutual_info` (LiDAR reflectivity
//! against image grey level, Pandey et al.) and `mi_calibrator` (every camera against a
//! reference LiDAR); `target` (checkerboard edge-and-plane: boards found in images by
//! `features::chessboard` and posed by planar PnP, the same boards' planes and ring-end edge
//! points in LiDAR, one robust solve per camera over many board views) and
//! `target_calibrator` (every camera against a reference LiDAR); `pose_graph` (pairwise
//! results as edges with information matrices, one robust Levenberg–Marquardt solve) and
//! `pose_graph_calibrator` (every LiDAR pair by ICP, every camera–LiDAR pair by checkerboards
//! or mutual information, unified by the graph). `hand_eye` and `camera_motion` fit a camera to
//! its own motion; `lidar_translation` then measures its translation against the LiDAR map.

pub mod camera_motion;
pub mod hand_eye;
pub mod icp;
pub mod icp_calibrator;
pub mod lidar_translation;
pub mod mi_calibrator;
pub mod mutual_info;
pub mod pose_graph;
pub mod pose_graph_calibrator;
pub mod target;
pub mod target_calibrator;
#[cfg(test)]
mod test_fixtures;
pub mod trajectory_icp;
pub mod trajectory_sweeps;

use crate::error::RunError;

/// The cameras' problems that could be set up, and a reason for each that could not (no
/// overlap with the LiDAR, no boards); an error only when no camera was asked for or none
/// could be set up.
pub(crate) fn per_camera<T>(
    results: Vec<Result<T, RunError>>,
) -> Result<(Vec<T>, Vec<String>), RunError> {
    if results.is_empty() {
        return Err(RunError::Invalid("no camera selected".into()));
    }
    let mut skipped = Vec::new();
    let problems: Vec<T> = results
        .into_iter()
        .filter_map(|r| r.map_err(|e| skipped.push(e.to_string())).ok())
        .collect();
    if problems.is_empty() {
        return Err(RunError::NotEnoughData(skipped.join("; ")));
    }
    Ok((problems, skipped))
}
