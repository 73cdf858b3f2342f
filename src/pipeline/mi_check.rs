//! A camera's second target-free check against a LiDAR, for the report: the mutual information
//! of the LiDAR's reflectivity and the image's grey values ([`MiProblem::mi`], the measure of
//! the `mi` method) at the initial guess and at the result, on frames spread over the drive
//! that the fit did not use (where the log has others; the edge check's frames).
//!
//! Why a second measure: edge alignment scores silhouettes, so a rotation that makes up for a
//! translation error every frame shares, or a fit of one frame's clutter, also scores better on
//! frames it did not fit. Reflectivity against grey weighs the surfaces' texture instead. On the
//! real logs it ranked edge alignment's results the way the reference does on every camera of
//! KITTI 000008 and KITTI-360 that ended worse, and on half of PandaSet's
//! (docs/experiments/real-camera-methods.md, "A second check"). Both points and frames are
//! fixed once (the points the result keeps in view, with a margin), so the two poses are
//! scored on the same data.

use crate::calib::Rig;
use crate::classical::mutual_info::{MiConfig, MiProblem};
use crate::error::RunError;
use crate::geometry::Rigid;
use crate::log::Drive;
use crate::optim::edge_align::{AlignError, held_out_pairs};

/// Mutual information (nats) at the start and at the result.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MiCheck {
    /// Frames with points in view.
    pub frames: usize,
    pub before: f64,
    pub after: f64,
}

impl MiCheck {
    /// Score `camera` against `lidar` (its extrinsic from `rig`) at `start` and at `end` on
    /// `frames` frames within `segments_nanos`, away from `fitted_images` (the camera's images
    /// the fit used) where the log has others, as the edge check chooses them. Fails where the
    /// LiDAR has no reflectivity or no point is in view.
    pub fn new(
        drive: &Drive,
        rig: &Rig,
        (camera, lidar): (&str, &str),
        (frames, segments_nanos, fitted_images): (usize, &[(i64, i64)], &[usize]),
        (start, end): (Rigid, Rigid),
    ) -> Result<Self, RunError> {
        let context = |e: AlignError| RunError::from(e).within(format!("{camera} × {lidar}"));
        let (pairs, _) = held_out_pairs(
            drive,
            (camera, lidar),
            frames,
            segments_nanos,
            fitted_images,
        )
        .map_err(context)?;
        let mut problem =
            MiProblem::from_pairs(drive, rig, (camera, lidar), pairs, &MiConfig::default())
                .map_err(context)?;
        problem.keep_visible(end);
        let frames = problem
            .frames
            .iter()
            .filter(|f| !f.points_in_vehicle.is_empty())
            .count();
        if frames == 0 {
            return Err(RunError::NotEnoughData(format!(
                "{camera} × {lidar}: no LiDAR point inside the image"
            )));
        }
        Ok(Self {
            frames,
            before: problem.mi(start),
            after: problem.mi(end),
        })
    }

    /// Whether the result matches the image worse than the start.
    pub fn worse(&self) -> bool {
        self.after < self.before
    }
}
