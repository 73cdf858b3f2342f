//! Photometric consistency of one camera's images over the LiDARs' geometry: a texture-free
//! check and refinement of a camera extrinsic.
//!
//! How it works. The LiDAR sweeps (every LiDAR of the rig, at their calibrated extrinsics) are
//! placed in the world through the trajectory at each return's firing time and thinned to one
//! point per voxel. A few images of the camera are loaded at a working width, turned grey,
//! blurred and normalised to zero mean and unit variance each (which absorbs a change of
//! exposure between frames). Which image sees which point is decided once, at the starting
//! extrinsic, by a coarse depth buffer per image: a point is seen when it is within a margin of
//! the nearest point projected into its cell. For a candidate `vehicle_from_camera` every
//! point seen by at least `min_views` images is projected into each of them, its grey values
//! read bilinearly, and the cost is the mean over the points of their (truncated) squared
//! deviations from the point's mean grey.
//!
//! Why it helps. A neural scene learns its colours together with the cameras, so a camera that
//! is off can paint its own texture and hold itself there. Here nothing is painted: the only
//! geometry is the LiDARs', and the images must agree with each other about the colour of each
//! LiDAR point. A wrong rotation samples each point at an offset that grows with its distance
//! from the camera, and that distance changes from frame to frame as the vehicle drives, so the
//! samples disagree. A translation parallel to a flat surface (along a street whose ground and
//! façades are parallel to the drive) shifts every frame's sample alike and is not observed;
//! [`search`] then keeps the translation where it started unless the cost improves.
//!
//! A rolling shutter ([`Drive::camera_readout`]): each image keeps the vehicle's pose at
//! [`SAMPLED_ROWS`] rows spread from the first to the last, and a point is projected at the
//! middle row's pose, then again at the pose of the row it fell on.

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use crate::calib::Rig;
use crate::classical::icp::voxel_thin;
use crate::classical::mutual_info::gaussian_blur;
use crate::features::grey::grey_unit as grey;
use crate::geometry::camera::CameraIntrinsics;
use crate::geometry::projection::{SweepView, world_points};
use crate::geometry::{Rigid, RowTimes, SAMPLED_ROWS};
use crate::log::Drive;
use crate::optim::edge_align::{AlignError, CompassSearch};

/// At most this many images per camera (a point's grey values are kept on the stack).
pub const MAX_IMAGES: usize = 64;

/// Settings of the problem and its search.
#[derive(Clone, Debug)]
pub struct PhotoConfig {
    /// Images of the camera, evenly spread over the drive (2 to [`MAX_IMAGES`]).
    pub images: usize,
    /// Sweeps per LiDAR, evenly spread over the drive.
    pub sweeps_per_lidar: usize,
    /// Width (px) the images are resized to.
    pub working_width_px: u32,
    /// Gaussian blur at the working width (px).
    pub blur_sigma_px: f64,
    /// One point per voxel of this size.
    pub voxel_m: f64,
    /// Points nearer or further than this from the camera are not used.
    pub min_range_m: f64,
    pub max_range_m: f64,
    /// Depth-buffer cell (px at the working width).
    pub cell_px: u32,
    /// A point is seen when its depth is within `nearest · (1 + margin) + 0.1 m` of its cell.
    pub depth_margin: f64,
    /// Points seen by fewer images are not used.
    pub min_views: usize,
    /// Squared deviations are truncated here (units of the normalised grey).
    pub truncation: f32,
    /// Radial fall-off to undo, `k` of a gain `1 − k·r²` (r: distance from the centre over the
    /// half-diagonal) applied before a 2.2 gamma; 0 leaves the images as they are.
    pub vignetting_k: f64,
}

impl Default for PhotoConfig {
    fn default() -> Self {
        Self {
            images: 16,
            sweeps_per_lidar: 16,
            working_width_px: 480,
            blur_sigma_px: 1.0,
            voxel_m: 0.1,
            min_range_m: 2.0,
            max_range_m: 60.0,
            cell_px: 4,
            depth_margin: 0.03,
            min_views: 3,
            truncation: 1.0,
            vignetting_k: 0.0,
        }
    }
}

/// One grey image and the vehicle pose it was taken at.
#[derive(Clone, Debug)]
pub struct PhotoImage {
    pub width: usize,
    pub height: usize,
    /// Blurred grey, zero mean and unit variance over the image.
    pub grey: Vec<f32>,
    pub vehicle_from_world: Rigid,
    pub stamp_nanos: i64,
    /// When each row was exposed relative to `stamp_nanos`.
    pub readout: RowTimes,
    /// With a rolling shutter, `vehicle_from_world` at [`SAMPLED_ROWS`] rows evenly from the
    /// first to the last (empty for a global shutter: `vehicle_from_world` for every row).
    pub row_poses: Vec<Rigid>,
}

impl PhotoImage {
    /// Set `vehicle_from_world` (the middle row's) and the row poses for an image taken at
    /// `stamp_nanos + delay_nanos` with `readout`; fails outside the trajectory.
    fn place(
        &mut self,
        trajectory: &crate::geometry::Trajectory,
        delay_nanos: i64,
    ) -> Result<(), crate::geometry::TrajectoryError> {
        let stamp = self.stamp_nanos + delay_nanos;
        self.vehicle_from_world = trajectory
            .world_from_vehicle(stamp + self.readout.middle_nanos())?
            .inverse();
        self.row_poses.clear();
        if self.readout.first_row_nanos != self.readout.last_row_nanos {
            for offset in self.readout.sampled_offsets_nanos(SAMPLED_ROWS) {
                self.row_poses
                    .push(trajectory.world_from_vehicle(stamp + offset)?.inverse());
            }
        }
        Ok(())
    }

    /// Where world point `p` appears, through `intrinsics` at `vehicle_from_camera` (the
    /// point in the camera frame and the pixel); with a rolling shutter, at the pose of the
    /// row it falls on.
    fn project(
        &self,
        intrinsics: &CameraIntrinsics,
        camera_from_vehicle: Rigid,
        p: DVec3,
    ) -> Option<(DVec3, DVec2)> {
        let q = (camera_from_vehicle * self.vehicle_from_world).transform_point(p);
        let px = intrinsics.project(q)?;
        if self.row_poses.is_empty() {
            return Some((q, px));
        }
        let k = RowTimes::nearest_sample(px.y, self.height as u32, SAMPLED_ROWS);
        let q = (camera_from_vehicle * self.row_poses[k]).transform_point(p);
        Some((q, intrinsics.project(q)?))
    }

    /// Bilinear grey at `pixel`; `None` outside the image.
    fn sample(&self, pixel: DVec2) -> Option<f32> {
        let (x, y) = (pixel.x, pixel.y);
        if !(x >= 0.0 && y >= 0.0 && x < (self.width - 1) as f64 && y < (self.height - 1) as f64) {
            return None;
        }
        let (x0, y0) = (x as usize, y as usize);
        let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
        let i = y0 * self.width + x0;
        let g = &self.grey;
        let top = g[i] + (g[i + 1] - g[i]) * fx;
        let bottom = g[i + self.width] + (g[i + self.width + 1] - g[i + self.width]) * fx;
        Some(top + (bottom - top) * fy)
    }
}

/// How far [`PhotoProblem::best_focal_scale`] looks from 1 (±2 %).
pub const FOCAL_SCALE_RANGE: f64 = 0.02;
/// Its scan's step (0.5 %).
pub const FOCAL_SCALE_STEP: f64 = 0.005;

/// The photo-consistency problem of one camera.
#[derive(Clone, Debug)]
pub struct PhotoProblem {
    pub camera: String,
    /// Intrinsics at the working width.
    pub intrinsics: CameraIntrinsics,
    pub images: Vec<PhotoImage>,
    pub points_in_world: Vec<DVec3>,
    /// Views of point `p`: `view_images[view_offsets[p]..view_offsets[p + 1]]`.
    pub view_offsets: Vec<u32>,
    pub view_images: Vec<u16>,
    pub truncation: f32,
}

/// Grey of an RGB image resized to `width` (Rec. 601 luma, 0–1).
fn grey_at_width(image: &image::RgbImage, width: u32) -> (usize, usize, Vec<f32>) {
    let height =
        ((image.height() as f64 * width as f64 / image.width() as f64).round() as u32).max(2);
    let resized = if image.width() == width {
        image.clone()
    } else {
        image::imageops::resize(image, width, height, image::imageops::FilterType::Triangle)
    };
    (
        resized.width() as usize,
        resized.height() as usize,
        grey(&resized),
    )
}

/// Divide out a gain `1 − k·r²` applied before a 2.2 gamma.
fn devignette(grey: &mut [f32], width: usize, height: usize, k: f64) {
    let (cx, cy) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
    let inv_r2 = 1.0 / (cx * cx + cy * cy).max(1e-9);
    for (i, g) in grey.iter_mut().enumerate() {
        let (x, y) = ((i % width) as f64 - cx, (i / width) as f64 - cy);
        let gain = (1.0 - k * (x * x + y * y) * inv_r2).max(0.05);
        *g /= gain.powf(1.0 / 2.2) as f32;
    }
}

/// Zero mean, unit variance (a flat image stays flat).
fn normalise(values: &mut [f32]) {
    let n = values.len().max(1) as f64;
    let mean = values.iter().map(|&v| v as f64).sum::<f64>() / n;
    let var = values
        .iter()
        .map(|&v| (v as f64 - mean).powi(2))
        .sum::<f64>()
        / n;
    let inv_std = if var > 1e-12 { 1.0 / var.sqrt() } else { 0.0 };
    for v in values {
        *v = ((*v as f64 - mean) * inv_std) as f32;
    }
}

/// Which points each image sees (indices into `points`), by a depth buffer of `cell_px` cells.
fn visible_per_image(
    points: &[DVec3],
    images: &[PhotoImage],
    intrinsics: &CameraIntrinsics,
    vehicle_from_camera: Rigid,
    config: &PhotoConfig,
) -> Vec<Vec<u32>> {
    let cell = config.cell_px.max(1) as usize;
    images
        .par_iter()
        .map(|image| {
            let camera_from_vehicle = vehicle_from_camera.inverse();
            let (cw, ch) = (image.width.div_ceil(cell), image.height.div_ceil(cell));
            let mut nearest = vec![f64::INFINITY; cw * ch];
            let mut projected = Vec::new();
            for (i, &p) in points.iter().enumerate() {
                let Some((q, px)) = image.project(intrinsics, camera_from_vehicle, p) else {
                    continue;
                };
                let range = q.length();
                if range < config.min_range_m || range > config.max_range_m {
                    continue;
                }
                if !(px.x >= 0.0
                    && px.y >= 0.0
                    && px.x < (image.width - 1) as f64
                    && px.y < (image.height - 1) as f64)
                {
                    continue;
                }
                let c = (px.y as usize / cell) * cw + px.x as usize / cell;
                nearest[c] = nearest[c].min(q.z);
                projected.push((i as u32, c, q.z));
            }
            projected
                .into_iter()
                .filter(|&(_, c, z)| z <= nearest[c] * (1.0 + config.depth_margin) + 0.1)
                .map(|(i, _, _)| i)
                .collect()
        })
        .collect()
}

/// Every LiDAR's sweeps (`config.sweeps_per_lidar` each, spread over the drive) placed in the
/// world at `rig`'s extrinsics and thinned to one point per `config.voxel_m` voxel: the
/// geometry every camera of that rig is checked against.
pub fn lidar_map(drive: &Drive, rig: &Rig, config: &PhotoConfig) -> Result<Vec<DVec3>, AlignError> {
    let mut world = Vec::new();
    for lidar in rig.lidars() {
        let usable = drive.frames_within(&lidar.name, &[]);
        for index in crate::log::spread_evenly(&usable, config.sweeps_per_lidar) {
            let Some(sweep) = drive.sweep_or_skip(&lidar.name, index) else {
                continue;
            };
            let view = SweepView {
                points_in_lidar: &sweep.points_in_sensor,
                intensity: &sweep.intensity,
                time_offset_secs: sweep.time_offset_secs.as_deref(),
                stamp_nanos: sweep.stamp_nanos,
            };
            world.extend(world_points(
                &view,
                &drive.trajectory,
                lidar.vehicle_from_sensor,
                1,
            )?);
        }
    }
    if world.is_empty() {
        return Err(AlignError::Setup(
            "no LiDAR sweep inside the trajectory".into(),
        ));
    }
    Ok(voxel_thin(&world, config.voxel_m, |p| *p))
}

impl PhotoProblem {
    /// Build the problem of `camera` from a drive over `map` ([`lidar_map`] of the same rig),
    /// with the visibility decided at the camera's extrinsic in `rig`.
    pub fn from_drive(
        drive: &Drive,
        rig: &Rig,
        camera: &str,
        map: &[DVec3],
        config: &PhotoConfig,
    ) -> Result<Self, AlignError> {
        let setup = |what: String| AlignError::Setup(what);
        let sensor = rig
            .sensor(camera)
            .ok_or_else(|| setup(format!("no sensor '{camera}' in the rig")))?;
        let full = sensor
            .camera
            .clone()
            .ok_or_else(|| setup(format!("'{camera}' is not a camera with intrinsics")))?;
        let stream = drive
            .stream(camera)
            .ok_or_else(|| setup(format!("no images for '{camera}' in the log")))?;
        let usable = drive.frames_within(camera, &[]);
        if usable.len() < 2 {
            return Err(setup(format!(
                "'{camera}' has fewer than two images inside the trajectory"
            )));
        }
        let mut images = Vec::new();
        for index in crate::log::spread_evenly(&usable, config.images.clamp(2, MAX_IMAGES)) {
            let stamp_nanos = stream.frames[index].stamp_nanos;
            let Some(image) = drive.image_or_skip(camera, index) else {
                continue;
            };
            let (width, height, mut grey) = grey_at_width(&image, config.working_width_px.max(2));
            if config.vignetting_k != 0.0 {
                devignette(&mut grey, width, height, config.vignetting_k);
            }
            let mut grey = gaussian_blur(&grey, width, height, config.blur_sigma_px);
            normalise(&mut grey);
            let mut image = PhotoImage {
                width,
                height,
                grey,
                vehicle_from_world: Rigid::IDENTITY,
                stamp_nanos,
                readout: drive.camera_readout,
                row_poses: Vec::new(),
            };
            image.place(&drive.trajectory, 0)?;
            images.push(image);
        }
        let factor = images[0].width as f64 / full.width as f64;
        let intrinsics = full.scaled(factor);

        Ok(Self::new(
            camera,
            intrinsics,
            images,
            map.to_vec(),
            sensor.vehicle_from_sensor,
            config,
        ))
    }

    /// A problem from prepared images (at most [`MAX_IMAGES`] count for a point) and points;
    /// visibility at `vehicle_from_camera`.
    pub fn new(
        camera: &str,
        intrinsics: CameraIntrinsics,
        images: Vec<PhotoImage>,
        points_in_world: Vec<DVec3>,
        vehicle_from_camera: Rigid,
        config: &PhotoConfig,
    ) -> Self {
        let visible = visible_per_image(
            &points_in_world,
            &images,
            &intrinsics,
            vehicle_from_camera,
            config,
        );
        let mut views: Vec<Vec<u16>> = vec![Vec::new(); points_in_world.len()];
        for (image, seen) in visible.iter().enumerate() {
            for &p in seen {
                views[p as usize].push(image as u16);
            }
        }
        let mut kept_points = Vec::new();
        let mut view_offsets = vec![0u32];
        let mut view_images = Vec::new();
        for (p, v) in views.into_iter().enumerate() {
            if v.len() >= config.min_views.max(2) {
                kept_points.push(points_in_world[p]);
                view_images.extend(v);
                view_offsets.push(view_images.len() as u32);
            }
        }
        Self {
            camera: camera.to_string(),
            intrinsics,
            images,
            points_in_world: kept_points,
            view_offsets,
            view_images,
            truncation: config.truncation,
        }
    }

    /// The same problem with every image taken `delay_nanos` after its stamp (the vehicle pose
    /// read from `trajectory` there); `None` if a delayed stamp leaves the trajectory.
    pub fn delayed(
        &self,
        trajectory: &crate::geometry::Trajectory,
        delay_nanos: i64,
    ) -> Option<Self> {
        let mut out = self.clone();
        for image in out.images.iter_mut() {
            image.place(trajectory, delay_nanos).ok()?;
        }
        Some(out)
    }

    /// The same problem with both focal lengths scaled by `scale` (principal point kept).
    pub fn with_focal_scale(&self, scale: f64) -> Self {
        Self {
            intrinsics: focal_scaled(&self.intrinsics, scale),
            ..self.clone()
        }
    }

    /// The focal-length scale, within ±[`FOCAL_SCALE_RANGE`], at which the images agree best
    /// at `vehicle_from_camera`: scanned in [`FOCAL_SCALE_STEP`] steps, then the vertex of the
    /// parabola through the best scale and its two neighbours. `None` when no scale has a
    /// finite cost.
    ///
    /// One camera's images tell a scale apart from a move along the optical axis only through
    /// the spread of depths they see: a scene at depth `d` looks the same with the camera
    /// `δ` further back or the focal length scaled by about `1 − δ / d`. So a scale away from
    /// 1 says the intrinsics are off, or the camera sits off along its axis.
    pub fn best_focal_scale(&self, vehicle_from_camera: Rigid) -> Option<f64> {
        let n = (FOCAL_SCALE_RANGE / FOCAL_SCALE_STEP).round() as i32;
        let costs: Vec<(f64, f64)> = (-n..=n)
            .map(|k| {
                let scale = 1.0 + k as f64 * FOCAL_SCALE_STEP;
                let intrinsics = focal_scaled(&self.intrinsics, scale);
                (scale, self.cost_with(&intrinsics, vehicle_from_camera))
            })
            .collect();
        let (i, &(scale, cost)) = costs
            .iter()
            .enumerate()
            .filter(|(_, c)| c.1.is_finite())
            .min_by(|a, b| a.1.1.total_cmp(&b.1.1))?;
        let (Some(left), Some(right)) = (i.checked_sub(1).map(|j| costs[j]), costs.get(i + 1))
        else {
            return Some(scale);
        };
        // Vertex of the parabola through three equally spaced costs.
        let curvature = left.1 - 2.0 * cost + right.1;
        if !(curvature.is_finite() && curvature > 0.0) {
            return Some(scale);
        }
        let offset = 0.5 * (left.1 - right.1) / curvature;
        Some(scale + offset.clamp(-0.5, 0.5) * FOCAL_SCALE_STEP)
    }

    /// Points used (seen by enough images).
    pub fn point_count(&self) -> usize {
        self.points_in_world.len()
    }

    /// Views used, over all points.
    pub fn view_count(&self) -> usize {
        self.view_images.len()
    }

    /// Mean truncated squared deviation of each point's grey values from their mean, over the
    /// points still seen twice at `vehicle_from_camera`.
    pub fn cost(&self, vehicle_from_camera: Rigid) -> f64 {
        self.cost_with(&self.intrinsics, vehicle_from_camera)
    }

    /// [`Self::cost`] with the images projected through `intrinsics` instead of the problem's.
    fn cost_with(&self, intrinsics: &CameraIntrinsics, vehicle_from_camera: Rigid) -> f64 {
        let camera_from_vehicle = vehicle_from_camera.inverse();
        let point = |p: usize| {
            let range = self.view_offsets[p] as usize..self.view_offsets[p + 1] as usize;
            let mut values = [0f32; MAX_IMAGES];
            let mut n = 0;
            for &image in &self.view_images[range] {
                let image = image as usize;
                let Some((_, px)) = self.images[image].project(
                    intrinsics,
                    camera_from_vehicle,
                    self.points_in_world[p],
                ) else {
                    continue;
                };
                if let Some(v) = self.images[image].sample(px)
                    && n < values.len()
                {
                    values[n] = v;
                    n += 1;
                }
            }
            if n < 2 {
                return (0.0, 0usize);
            }
            let values = &values[..n];
            let mean = values.iter().sum::<f32>() / n as f32;
            let dev: f32 = values
                .iter()
                .map(|v| ((v - mean) * (v - mean)).min(self.truncation))
                .sum();
            ((dev / n as f32) as f64, 1usize)
        };
        let add = |a: (f64, usize), b: (f64, usize)| (a.0 + b.0, a.1 + b.1);
        // Fixed chunks added in order: rayon's `reduce` groups by how work was stolen, so its
        // sum would differ in the last bits from run to run.
        let parts: Vec<_> = (0..self.points_in_world.len())
            .into_par_iter()
            .fold_chunks(4096, || (0.0, 0), |acc, p| add(acc, point(p)))
            .collect();
        let (sum, count) = parts.into_iter().fold((0.0, 0), add);
        if count == 0 {
            f64::INFINITY
        } else {
            sum / count as f64
        }
    }
}

/// `intrinsics` with both focal lengths scaled by `scale`.
fn focal_scaled(intrinsics: &CameraIntrinsics, scale: f64) -> CameraIntrinsics {
    CameraIntrinsics {
        fx: intrinsics.fx * scale,
        fy: intrinsics.fy * scale,
        ..intrinsics.clone()
    }
}

/// A compass search ([`CompassSearch`]) over one camera's extrinsic for this cost: rotation
/// and translation, from 0.1° / 2 cm steps down to 0.005° / 1 mm, within 1° / 20 cm of `start`.
pub fn search(problem: &PhotoProblem, start: Rigid) -> CompassSearch {
    let mut search = CompassSearch::from_cost(start, problem.cost(start));
    search.step_rad = 0.1f64.to_radians();
    search.step_m = 0.02;
    search.min_step_m = 0.001;
    search.translate = true;
    search.max_rotation_rad = 1f64.to_radians();
    search.max_translation_m = 0.2;
    search
}

#[cfg(test)]
mod tests;
