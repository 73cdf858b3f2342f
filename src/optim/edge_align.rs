//! Target-free camera refinement by edge alignment: the studio's small real optimiser, and the
//! alignment score of the reprojection checks.
//!
//! How it works. For a camera and a reference LiDAR, a few frames are prepared once: the image's
//! edge map becomes an exact distance transform (pixels to the nearest edge), and the sweep's depth
//! discontinuities (silhouette points, [`crate::eval::edges::depth_discontinuities`]) are moved
//! into the *vehicle frame at the image's stamp*, through the trajectory at each point's own firing
//! time: `q = world_from_vehicle(t_img)⁻¹ · world_from_vehicle(t_pt) · vehicle_from_lidar · p`.
//! The camera extrinsic is then the only unknown: `p_cam = vehicle_from_camera⁻¹ · q`. The cost is
//! the mean truncated distance `min(DT(π(p_cam)), τ)` (bilinear, so sub-pixel moves change it;
//! points leaving the image cost τ). A compass (pattern) search over the six right-perturbation
//! coordinates of `vehicle_from_camera` minimises it: try ±step on each coordinate, keep the best
//! improvement, halve the steps when none improves.
//!
//! A rolling-shutter camera ([`RowTimes`]): the points are moved into the vehicle frame at the
//! image's middle row's time, and each frame keeps the vehicle's motion from there to 33 rows
//! spread from its top edge to its bottom edge; a point is projected through the middle row's
//! pose, then again through the pose of the row it fell on. Frames with rows outside the
//! trajectory are left out. (Mutual information and the checkerboard method, which share
//! [`points_in_vehicle_at`], still project each image at its stamp.)

use glam::DVec3;

use crate::calib::Rig;
use crate::eval::edges;
use crate::geometry::camera::CameraIntrinsics;
use crate::geometry::{Rigid, RowTimes, SAMPLED_ROWS, Trajectory, TrajectoryError};
use crate::log::{Drive, LidarSweep, LogError};

/// One image with silhouettes ready for scoring.
#[derive(Clone, Debug)]
pub struct EdgeFrame {
    pub width: usize,
    pub height: usize,
    /// Distance (px) from each pixel to the nearest image edge.
    pub distance_px: Vec<f32>,
    /// Silhouette points in the vehicle frame at the image's stamp (its middle row's time
    /// with a rolling shutter).
    pub points_in_vehicle: Vec<DVec3>,
    /// Stamp of the LiDAR sweep the silhouettes come from (0 when unknown).
    pub sweep_stamp_nanos: i64,
    /// A rolling shutter: the vehicle frame at row k's time from the one at the middle row's,
    /// for rows spread from the top edge to the bottom edge; empty for a global shutter.
    pub rows_from_middle: Vec<Rigid>,
}

/// The edge-alignment problem of one camera against one reference LiDAR.
#[derive(Clone, Debug)]
pub struct EdgeAlignment {
    pub camera: String,
    pub lidar: String,
    pub intrinsics: CameraIntrinsics,
    pub frames: Vec<EdgeFrame>,
    /// Truncation τ of the per-point distance (px).
    pub truncation_px: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum AlignError {
    #[error(transparent)]
    Log(#[from] LogError),
    #[error("trajectory: {0}")]
    Trajectory(#[from] TrajectoryError),
    #[error("{0}")]
    Setup(String),
}

/// A LiDAR sweep and the image of a camera nearest to it in time.
pub struct SweepImagePair {
    pub sweep: LidarSweep,
    pub image_index: usize,
    pub image_stamp_nanos: i64,
}

/// Up to `frames` sweeps of `lidar`, evenly spread over `segments_nanos` (empty: the whole
/// drive), each with the image of `camera` nearest in time (within 200 ms, inside the
/// trajectory). Errors name what is missing.
pub fn sweep_image_pairs(
    drive: &Drive,
    camera: &str,
    lidar: &str,
    frames: usize,
    segments_nanos: &[(i64, i64)],
) -> Result<Vec<SweepImagePair>, AlignError> {
    Ok(held_out_pairs(drive, (camera, lidar), frames, segments_nanos, &[])?.0)
}

/// The image of `camera` nearest in time to `stamp_nanos` (by the log's index; nothing is
/// decoded).
pub fn nearest_image(drive: &Drive, camera: &str, stamp_nanos: i64) -> Option<usize> {
    // The stream is sorted by stamp: the nearest is one of the two either side (the earlier
    // on a tie).
    let frames = &drive.stream(camera)?.frames;
    let after = frames.partition_point(|f| f.stamp_nanos < stamp_nanos);
    (after.saturating_sub(1)..(after + 1).min(frames.len()))
        .min_by_key(|&j| (frames[j].stamp_nanos - stamp_nanos).abs())
}

/// The images of `camera` nearest to the sweeps `sweeps` of `lidar`: the ones a method that
/// fits those sweeps sees.
pub fn images_nearest(drive: &Drive, camera: &str, lidar: &str, sweeps: &[usize]) -> Vec<usize> {
    let Some(stream) = drive.stream(lidar) else {
        return Vec::new();
    };
    sweeps
        .iter()
        .filter_map(|&i| nearest_image(drive, camera, stream.frames.get(i)?.stamp_nanos))
        .collect()
}

/// The images of `camera` that [`sweep_image_pairs`] pairs with `frames` sweeps of `lidar`
/// (by the log's index; nothing is decoded): the ones an edge alignment on them fits.
pub fn picked_images(
    drive: &Drive,
    (camera, lidar): (&str, &str),
    frames: usize,
    segments_nanos: &[(i64, i64)],
) -> Vec<usize> {
    let sweeps = crate::log::spread_evenly(&drive.frames_within(lidar, segments_nanos), frames);
    images_nearest(drive, camera, lidar, &sweeps)
}

/// As [`sweep_image_pairs`], but spread over the sweeps whose nearest image is none of
/// `fitted_images` (the frames a fit used) nor within a quarter of their spacing of one (a
/// neighbour a tenth of a second on sees the same scene), so a check judges the fit on data it
/// did not see. Where no such sweep is left (a log of a few frames), or none of them makes a
/// pair, every sweep is a candidate;
/// the flag says whether the pairs are held out.
pub fn held_out_pairs(
    drive: &Drive,
    (camera, lidar): (&str, &str),
    frames: usize,
    segments_nanos: &[(i64, i64)],
    fitted_images: &[usize],
) -> Result<(Vec<SweepImagePair>, bool), AlignError> {
    let cam_stream = drive
        .stream(camera)
        .ok_or_else(|| AlignError::Setup(format!("no images for '{camera}' in the log")))?;
    let Some(lidar_stream) = drive.stream(lidar) else {
        return Err(AlignError::Setup(format!(
            "no sweeps for '{lidar}' in the log"
        )));
    };
    let usable = drive.frames_within(lidar, segments_nanos);
    if usable.is_empty() {
        return Err(AlignError::Setup(format!(
            "no sweep of '{lidar}' inside the trajectory and the selected segments"
        )));
    }
    let fitted_stamps: Vec<i64> = fitted_images
        .iter()
        .filter_map(|&j| Some(cam_stream.frames.get(j)?.stamp_nanos))
        .collect();
    let spacing_nanos = match (fitted_stamps.iter().min(), fitted_stamps.iter().max()) {
        (Some(first), Some(last)) if fitted_stamps.len() > 1 => {
            (last - first) / (fitted_stamps.len() as i64 - 1)
        }
        _ => 0,
    };
    // A fitted image's own stamp is always inside its window (one fitted image: only itself).
    let unfitted: Vec<usize> = if fitted_stamps.is_empty() {
        usable.clone()
    } else {
        usable
            .iter()
            .copied()
            .filter(|&i| {
                nearest_image(drive, camera, lidar_stream.frames[i].stamp_nanos).is_some_and(|j| {
                    let t = cam_stream.frames[j].stamp_nanos;
                    fitted_stamps
                        .iter()
                        .all(|&f| (t - f).abs() > spacing_nanos / 4)
                })
            })
            .collect()
    };
    // Held-out sweeps that make no pair (not decoded, no image near, outside the trajectory)
    // leave the check the fitted ones, as a log with no others does.
    let mut held_out = !unfitted.is_empty();
    let mut out = pairs_of(
        drive,
        (camera, lidar),
        frames,
        if held_out { &unfitted } else { &usable },
    );
    if out.is_empty() && held_out {
        held_out = false;
        out = pairs_of(drive, (camera, lidar), frames, &usable);
    }
    if out.is_empty() {
        return Err(AlignError::Setup(format!(
            "no image of '{camera}' within 200 ms of a sweep of '{lidar}'"
        )));
    }
    Ok((out, held_out))
}

/// Up to `frames` sweep–image pairs spread over the sweeps `candidates` of `lidar`: each with
/// the image of `camera` nearest in time, within 200 ms and inside the trajectory.
fn pairs_of(
    drive: &Drive,
    (camera, lidar): (&str, &str),
    frames: usize,
    candidates: &[usize],
) -> Vec<SweepImagePair> {
    let Some(cam_stream) = drive.stream(camera) else {
        return Vec::new();
    };
    let mut out = Vec::with_capacity(frames);
    for sweep_index in crate::log::spread_evenly(candidates, frames) {
        let Some(sweep) = drive.sweep_or_skip(lidar, sweep_index) else {
            continue;
        };
        let Some(image_index) = nearest_image(drive, camera, sweep.stamp_nanos) else {
            continue;
        };
        let image_stamp_nanos = cam_stream.frames[image_index].stamp_nanos;
        if (image_stamp_nanos - sweep.stamp_nanos).abs() > 200_000_000
            || drive
                .trajectory
                .world_from_vehicle(image_stamp_nanos)
                .is_err()
        {
            continue;
        }
        out.push(SweepImagePair {
            sweep,
            image_index,
            image_stamp_nanos,
        });
    }
    out
}

/// Silhouette points of `sweep` moved into the vehicle frame at `image_stamp_nanos`.
pub fn silhouettes_in_vehicle(
    sweep: &LidarSweep,
    drive_trajectory: &crate::geometry::Trajectory,
    vehicle_from_lidar: Rigid,
    image_stamp_nanos: i64,
) -> Result<Vec<DVec3>, TrajectoryError> {
    let indices = edges::depth_discontinuities(&sweep.points_in_sensor, 0.05);
    points_in_vehicle_at(
        sweep,
        &indices,
        drive_trajectory,
        vehicle_from_lidar,
        image_stamp_nanos,
    )
}

/// The points `indices` of `sweep`, each taken through the trajectory at its own firing time
/// into the vehicle frame at `image_stamp_nanos`:
/// `world_from_vehicle(t_img)⁻¹ · world_from_vehicle(t_pt) · vehicle_from_lidar · p`.
pub fn points_in_vehicle_at(
    sweep: &LidarSweep,
    indices: &[usize],
    drive_trajectory: &crate::geometry::Trajectory,
    vehicle_from_lidar: Rigid,
    image_stamp_nanos: i64,
) -> Result<Vec<DVec3>, TrajectoryError> {
    let vehicle_from_world = drive_trajectory
        .world_from_vehicle(image_stamp_nanos)?
        .inverse();
    let mut out = Vec::with_capacity(indices.len());
    // Poses cached per millisecond of firing time: a sweep spans ~100 ms.
    let mut cache: Vec<(i64, Rigid)> = Vec::new();
    for &i in indices {
        let t = sweep.stamp_nanos
            + sweep
                .time_offset_secs
                .as_ref()
                .and_then(|t| t.get(i))
                .map_or(0, |s| (*s as f64 * 1e9) as i64);
        let key = t / 1_000_000;
        let vehicle_now_from_vehicle_then = match cache.iter().find(|(k, _)| *k == key) {
            Some((_, r)) => *r,
            None => {
                let r =
                    vehicle_from_world * drive_trajectory.world_from_vehicle(key * 1_000_000)?;
                cache.push((key, r));
                r
            }
        };
        let p = sweep.points_in_sensor[i];
        out.push(
            (vehicle_now_from_vehicle_then * vehicle_from_lidar).transform_point(DVec3::new(
                p[0] as f64,
                p[1] as f64,
                p[2] as f64,
            )),
        );
    }
    Ok(out)
}

impl EdgeFrame {
    pub fn new(image: &image::RgbImage, points_in_vehicle: Vec<DVec3>) -> Self {
        let (w, h) = (image.width() as usize, image.height() as usize);
        Self {
            width: w,
            height: h,
            distance_px: edges::distance_transform(&edges::image_edges(image), w, h),
            points_in_vehicle,
            sweep_stamp_nanos: 0,
            rows_from_middle: Vec::new(),
        }
    }

    /// The frame of an image stamped `image_stamp_nanos` read out row by row (`readout`),
    /// its points already in the vehicle frame at the middle row's time.
    pub fn rolling(
        mut self,
        trajectory: &Trajectory,
        image_stamp_nanos: i64,
        readout: RowTimes,
    ) -> Result<Self, TrajectoryError> {
        self.rows_from_middle.clear();
        if readout.first_row_nanos == readout.last_row_nanos {
            return Ok(self);
        }
        let world_from_middle =
            trajectory.world_from_vehicle(image_stamp_nanos + readout.middle_nanos())?;
        for offset in readout.sampled_offsets_nanos(SAMPLED_ROWS) {
            let world_from_row = trajectory.world_from_vehicle(image_stamp_nanos + offset)?;
            self.rows_from_middle
                .push(world_from_row.inverse() * world_from_middle);
        }
        Ok(self)
    }

    /// The pixel of point `q` (vehicle frame, middle row's time), `None` within 10 cm of the
    /// camera's plane or behind it: through the middle row's pose, then, with a rolling
    /// shutter, through the pose of the row it fell on.
    fn pixel(
        &self,
        intrinsics: &CameraIntrinsics,
        camera_from_vehicle: Rigid,
        q: DVec3,
    ) -> Option<glam::DVec2> {
        let through = |q: DVec3| {
            let p = camera_from_vehicle.transform_point(q);
            if p.z > 0.1 {
                intrinsics.project(p)
            } else {
                None
            }
        };
        let px = through(q)?;
        if self.rows_from_middle.is_empty() {
            return Some(px);
        }
        let rows = self.rows_from_middle.len();
        let row = RowTimes::nearest_sample(px.y, self.height as u32, rows);
        through(self.rows_from_middle[row].transform_point(q))
    }

    /// Bilinear distance at a pixel centre coordinate; `None` outside the image.
    fn distance_at(&self, x: f64, y: f64) -> Option<f64> {
        if !(x >= 0.0 && y >= 0.0 && x <= (self.width - 1) as f64 && y <= (self.height - 1) as f64)
        {
            return None;
        }
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let d = |x: usize, y: usize| self.distance_px[y * self.width + x] as f64;
        Some(
            (d(x0, y0) * (1.0 - fx) + d(x1, y0) * fx) * (1.0 - fy)
                + (d(x0, y1) * (1.0 - fx) + d(x1, y1) * fx) * fy,
        )
    }
}

impl EdgeAlignment {
    /// Prepare `frames` evenly spaced frames of `camera` against `lidar` from a drive, using the
    /// extrinsics of `rig` for the LiDAR, with the cameras read out as `readout` (usually the
    /// drive's, [`Drive::camera_readout`]; the studio keeps its own). `segments_nanos` limits
    /// the frames to time ranges (empty: all).
    pub fn from_drive(
        drive: &Drive,
        rig: &Rig,
        (camera, lidar): (&str, &str),
        frames: usize,
        segments_nanos: &[(i64, i64)],
        readout: RowTimes,
    ) -> Result<Self, AlignError> {
        let pairs = sweep_image_pairs(drive, camera, lidar, frames, segments_nanos)?;
        Self::from_pairs(drive, rig, (camera, lidar), pairs, readout)
    }

    /// Prepare the frames of `pairs` (from [`sweep_image_pairs`] or [`held_out_pairs`]) as
    /// [`EdgeAlignment::from_drive`] does.
    pub fn from_pairs(
        drive: &Drive,
        rig: &Rig,
        (camera, lidar): (&str, &str),
        pairs: Vec<SweepImagePair>,
        readout: RowTimes,
    ) -> Result<Self, AlignError> {
        let cam = rig
            .sensor(camera)
            .ok_or_else(|| AlignError::Setup(format!("no sensor '{camera}' in the rig")))?;
        let intrinsics = cam
            .camera
            .clone()
            .ok_or_else(|| AlignError::Setup(format!("'{camera}' has no camera intrinsics")))?;
        let vehicle_from_lidar = rig
            .sensor(lidar)
            .ok_or_else(|| AlignError::Setup(format!("no sensor '{lidar}' in the rig")))?
            .vehicle_from_sensor;
        let mut out = Vec::with_capacity(pairs.len());
        for pair in pairs {
            let Some(image) = drive.image_or_skip(camera, pair.image_index) else {
                continue;
            };
            let points = silhouettes_in_vehicle(
                &pair.sweep,
                &drive.trajectory,
                vehicle_from_lidar,
                pair.image_stamp_nanos + readout.middle_nanos(),
            )?;
            // A frame with rows outside the trajectory is left out (only a rolling shutter's
            // can be).
            let Ok(mut frame) = EdgeFrame::new(&image, points).rolling(
                &drive.trajectory,
                pair.image_stamp_nanos,
                readout,
            ) else {
                continue;
            };
            frame.sweep_stamp_nanos = pair.sweep.stamp_nanos;
            out.push(frame);
        }
        if out.is_empty() {
            return Err(AlignError::Setup(format!(
                "no image of '{camera}' near a sweep of '{lidar}' has every row (rolling shutter {:+.1}..{:+.1} ms) inside the trajectory",
                readout.first_row_nanos as f64 * 1e-6,
                readout.last_row_nanos as f64 * 1e-6
            )));
        }
        let mut problem = Self {
            camera: camera.into(),
            lidar: lidar.into(),
            intrinsics,
            frames: out,
            truncation_px: 20.0,
        };
        problem.keep_visible(cam.vehicle_from_sensor);
        Ok(problem)
    }

    /// The alignment score of one camera–LiDAR pair under `rig` with the cameras read out as
    /// `readout`: mean truncated edge distance (px) and every point's distance, on `frames`
    /// frames within `segments_nanos`.
    pub fn score_rig(
        drive: &Drive,
        rig: &Rig,
        (camera, lidar): (&str, &str),
        frames: usize,
        segments_nanos: &[(i64, i64)],
        readout: RowTimes,
    ) -> Result<(f64, Vec<f32>), AlignError> {
        let problem =
            Self::from_drive(drive, rig, (camera, lidar), frames, segments_nanos, readout)?;
        let t = rig
            .sensor(camera)
            .ok_or_else(|| AlignError::Setup(format!("no sensor '{camera}' in the rig")))?
            .vehicle_from_sensor;
        let d = problem.distances(t);
        if d.is_empty() {
            return Err(AlignError::Setup(format!(
                "{camera} × {lidar}: no LiDAR silhouette inside the image"
            )));
        }
        let mean = d.iter().map(|&x| x as f64).sum::<f64>() / d.len() as f64;
        Ok((mean, d))
    }

    /// Keep only the silhouette points that `vehicle_from_camera` puts inside the image (with a
    /// 5 % margin), so the cost is a mean over a fixed set: a point that later leaves the image
    /// costs τ instead of silently dropping out.
    pub fn keep_visible(&mut self, vehicle_from_camera: Rigid) {
        let camera_from_vehicle = vehicle_from_camera.inverse();
        let intr = &self.intrinsics;
        for f in &mut self.frames {
            // Where the cost will look: through the pose of each point's row.
            let keep: Vec<bool> = f
                .points_in_vehicle
                .iter()
                .map(|q| {
                    camera_from_vehicle.transform_point(*q).z > 0.5
                        && f.pixel(intr, camera_from_vehicle, *q)
                            .is_some_and(|px| inside_margin(intr, px))
                })
                .collect();
            let mut keep = keep.into_iter();
            f.points_in_vehicle.retain(|_| keep.next().unwrap_or(false));
        }
    }

    /// Number of silhouette points over all frames.
    pub fn point_count(&self) -> usize {
        self.frames.iter().map(|f| f.points_in_vehicle.len()).sum()
    }

    /// Mean truncated edge distance (px) of the silhouettes seen through `vehicle_from_camera`.
    pub fn cost(&self, vehicle_from_camera: Rigid) -> f64 {
        let d = self.distances(vehicle_from_camera);
        if d.is_empty() {
            self.truncation_px
        } else {
            d.iter().map(|&x| x as f64).sum::<f64>() / d.len() as f64
        }
    }

    /// Per silhouette point: its truncated distance (px) to the nearest image edge when seen
    /// through `vehicle_from_camera` (τ for points behind the camera or outside the image).
    pub fn distances(&self, vehicle_from_camera: Rigid) -> Vec<f32> {
        let camera_from_vehicle = vehicle_from_camera.inverse();
        let tau = self.truncation_px;
        let mut out = Vec::with_capacity(self.point_count());
        for f in &self.frames {
            for q in &f.points_in_vehicle {
                // Behind the camera (no pixel) or outside the image: τ.
                let d = f
                    .pixel(&self.intrinsics, camera_from_vehicle, *q)
                    .and_then(|px| f.distance_at(px.x, px.y))
                    .map_or(tau, |d| d.min(tau));
                out.push(d as f32);
            }
        }
        out
    }
}

/// Whether `px` lies inside the image with a 5 % margin on every side.
pub(crate) fn inside_margin(intr: &CameraIntrinsics, px: glam::DVec2) -> bool {
    let (w, h) = (intr.width as f64, intr.height as f64);
    let (mx, my) = (0.05 * w, 0.05 * h);
    px.x >= mx && px.y >= my && px.x <= w - mx && px.y <= h - my
}

/// Compass search state for one camera.
#[derive(Clone, Debug)]
pub struct CompassSearch {
    pub best: Rigid,
    pub best_cost: f64,
    pub step_rad: f64,
    pub step_m: f64,
    pub min_step_rad: f64,
    pub min_step_m: f64,
    /// Also search translation. Off by default: at street distances a few centimetres move a
    /// silhouette by well under a pixel, so edges constrain rotation, not translation.
    pub translate: bool,
    /// Trust region: the search never moves the rotation further than this from the start.
    /// Edges constrain pan and tilt sharply but roll about the optical axis only weakly, and a
    /// textured scene has distant spurious minima; this refiner is a local polish.
    pub max_rotation_rad: f64,
    /// Trust region for the translation (with `translate`).
    pub max_translation_m: f64,
    start: Rigid,
}

impl CompassSearch {
    pub fn new(problem: &EdgeAlignment, start: Rigid) -> Self {
        Self::from_cost(start, problem.cost(start))
    }

    /// A search from `start`, whose cost is `start_cost`, for any cost of the extrinsic.
    pub fn from_cost(start: Rigid, start_cost: f64) -> Self {
        Self {
            best: start,
            best_cost: start_cost,
            step_rad: 0.5f64.to_radians(),
            step_m: 0.05,
            min_step_rad: 0.005f64.to_radians(),
            min_step_m: 0.0005,
            translate: false,
            max_rotation_rad: 2f64.to_radians(),
            max_translation_m: f64::INFINITY,
            start,
        }
    }

    pub fn converged(&self) -> bool {
        self.step_rad < self.min_step_rad && (!self.translate || self.step_m < self.min_step_m)
    }

    /// One round of probes (±step on each searched axis); returns whether the pose improved.
    pub fn step(&mut self, problem: &EdgeAlignment) -> bool {
        self.step_with(|pose| problem.cost(pose))
    }

    /// [`Self::step`] for any cost of the extrinsic.
    pub fn step_with(&mut self, cost: impl Fn(Rigid) -> f64) -> bool {
        let mut best = None;
        let axes = if self.translate { 6 } else { 3 };
        for axis in 0..axes {
            for sign in [-1.0, 1.0] {
                let mut omega = DVec3::ZERO;
                let mut v = DVec3::ZERO;
                if axis < 3 {
                    omega[axis] = sign * self.step_rad;
                } else {
                    v[axis - 3] = sign * self.step_m;
                }
                let candidate = self.best.perturbed_right(omega, v);
                let (rotation, translation) = self.start.difference(candidate);
                if rotation > self.max_rotation_rad || translation > self.max_translation_m {
                    continue;
                }
                let c = cost(candidate);
                if c < best.map_or(self.best_cost, |(bc, _)| bc) {
                    best = Some((c, candidate));
                }
            }
        }
        match best {
            Some((c, pose)) => {
                self.best = pose;
                self.best_cost = c;
                true
            }
            None => {
                self.step_rad *= 0.5;
                self.step_m *= 0.5;
                false
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    /// A rolling shutter: a point placed along pixel (x, y)'s ray from where the vehicle was
    /// when row y was exposed lands on (x, y) within the rows' spacing; without the rows (the
    /// middle row's pose for the whole image) it misses.
    #[test]
    fn a_rolling_frame_projects_each_point_through_its_rows_pose() {
        // 8 m/s along x, a camera looking sideways (−y).
        let (trajectory, vehicle_from_camera) =
            crate::geometry::projection::sideways_camera_at_8_mps();
        let intrinsics = CameraIntrinsics::pinhole(640, 480, 500.0, 500.0, 320.0, 240.0);
        let readout = RowTimes::from_millis(-30.0, 10.0);
        let stamp = 500_000_000;
        let middle_from_world = trajectory
            .world_from_vehicle(stamp + readout.middle_nanos())
            .unwrap()
            .inverse();
        let pixels = [(20.0, 3.0), (320.0, 240.0), (600.0, 470.0)];
        let points: Vec<DVec3> = pixels
            .iter()
            .map(|&(x, y)| {
                let t = stamp + readout.offset_nanos(y, intrinsics.height);
                let world_from_camera =
                    trajectory.world_from_vehicle(t).unwrap() * vehicle_from_camera;
                let ray = intrinsics.unproject(DVec2::new(x, y)).unwrap();
                middle_from_world
                    .transform_point(world_from_camera.transform_point(ray * 10.0 / ray.z))
            })
            .collect();
        let image = image::RgbImage::new(640, 480);
        let global = EdgeFrame::new(&image, points.clone());
        let rolling = global.clone().rolling(&trajectory, stamp, readout).unwrap();
        assert_eq!(rolling.rows_from_middle.len(), SAMPLED_ROWS);
        let camera_from_vehicle = vehicle_from_camera.inverse();
        for (q, &(x, y)) in points.iter().zip(&pixels) {
            let px = rolling.pixel(&intrinsics, camera_from_vehicle, *q).unwrap();
            assert!(px.distance(DVec2::new(x, y)) < 0.5, "({x}, {y}) -> {px:?}");
            let at_middle = global.pixel(&intrinsics, camera_from_vehicle, *q).unwrap();
            if (y - 240.0f64).abs() > 100.0 {
                assert!(at_middle.distance(DVec2::new(x, y)) > 2.0, "{at_middle:?}");
            }
        }
        // A readout of no length keeps the frame global.
        let none = global
            .rolling(&trajectory, stamp, RowTimes::from_millis(5.0, 5.0))
            .unwrap();
        assert!(none.rows_from_middle.is_empty());
    }
}
