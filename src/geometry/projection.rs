//! LiDAR points into camera images: `camera_from_lidar(t)` with the trajectory interpolated at
//! each point's own firing time and at the image's stamp, then the full camera model.
//!
//! p_cam = (world_from_vehicle(t_img) · vehicle_from_camera)⁻¹ · world_from_vehicle(t_pt) ·
//! vehicle_from_lidar · p_lidar  (method.md §1 and §5). Points of a deskewed sweep share the
//! sweep stamp. Poses are interpolated once per time bucket (1 ms), not once per point.

use glam::DVec3;
use rayon::prelude::*;

use super::camera::CameraIntrinsics;
use super::{Rigid, Trajectory, TrajectoryError};

/// One LiDAR point seen in an image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProjectedPoint {
    pub pixel: [f32; 2],
    pub depth_m: f32,
    pub intensity: f32,
    /// Index of the point in its sweep.
    pub index: u32,
}

/// What a projection needs about one LiDAR sweep.
#[derive(Clone, Copy, Debug)]
pub struct SweepView<'a> {
    pub points_in_lidar: &'a [[f32; 3]],
    pub intensity: &'a [f32],
    /// Per-point firing time relative to `stamp_nanos`; `None` for a deskewed sweep.
    pub time_offset_secs: Option<&'a [f32]>,
    pub stamp_nanos: i64,
}

const BUCKET_NANOS: i64 = 1_000_000;

/// `world_from_lidar` at every 1 ms bucket the sweep's points fall in.
fn world_from_lidar_buckets(
    sweep: &SweepView<'_>,
    trajectory: &Trajectory,
    vehicle_from_lidar: Rigid,
) -> Result<(i64, Vec<Rigid>), TrajectoryError> {
    let Some(offsets) = sweep.time_offset_secs else {
        return Ok((
            0,
            vec![trajectory.world_from_vehicle(sweep.stamp_nanos)? * vehicle_from_lidar],
        ));
    };
    let (lo, hi) = offsets
        .iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), &t| (lo.min(t), hi.max(t)));
    if lo > hi {
        return Ok((
            0,
            vec![trajectory.world_from_vehicle(sweep.stamp_nanos)? * vehicle_from_lidar],
        ));
    }
    let first = (lo as f64 * 1e9) as i64 / BUCKET_NANOS;
    let last = (hi as f64 * 1e9) as i64 / BUCKET_NANOS;
    let poses = (first..=last)
        .map(|b| {
            Ok(
                trajectory.world_from_vehicle(sweep.stamp_nanos + b * BUCKET_NANOS)?
                    * vehicle_from_lidar,
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((first, poses))
}

/// Project a sweep into an image taken at `image_stamp_nanos`. Points behind the camera or
/// outside the image are dropped; `stride` keeps every n-th point.
pub fn project_sweep(
    sweep: &SweepView<'_>,
    trajectory: &Trajectory,
    vehicle_from_lidar: Rigid,
    vehicle_from_camera: Rigid,
    intrinsics: &CameraIntrinsics,
    image_stamp_nanos: i64,
    stride: usize,
) -> Result<Vec<ProjectedPoint>, TrajectoryError> {
    let camera_from_world =
        (trajectory.world_from_vehicle(image_stamp_nanos)? * vehicle_from_camera).inverse();
    let (first_bucket, buckets) = world_from_lidar_buckets(sweep, trajectory, vehicle_from_lidar)?;
    let camera_from_lidar: Vec<Rigid> = buckets.iter().map(|w| camera_from_world * *w).collect();
    let stride = stride.max(1);
    let n = sweep.points_in_lidar.len();
    Ok((0..n.div_ceil(stride))
        .into_par_iter()
        .with_min_len(4096)
        .filter_map(|k| {
            let i = k * stride;
            let b = match sweep.time_offset_secs {
                Some(t) => ((t[i] as f64 * 1e9) as i64 / BUCKET_NANOS - first_bucket)
                    .clamp(0, camera_from_lidar.len() as i64 - 1)
                    as usize,
                None => 0,
            };
            let p = sweep.points_in_lidar[i];
            let p_cam = camera_from_lidar[b].transform_point(DVec3::new(
                p[0] as f64,
                p[1] as f64,
                p[2] as f64,
            ));
            let pixel = intrinsics.project(p_cam)?;
            if !intrinsics.in_image(pixel) {
                return None;
            }
            Some(ProjectedPoint {
                pixel: [pixel.x as f32, pixel.y as f32],
                depth_m: p_cam.length() as f32,
                intensity: sweep.intensity.get(i).copied().unwrap_or(0.0),
                index: i as u32,
            })
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    #[test]
    fn a_point_straight_ahead_lands_on_the_principal_point() {
        let traj = Trajectory::new(vec![
            (0, Rigid::IDENTITY),
            (
                1_000_000_000,
                Rigid::from_translation(DVec3::new(10.0, 0.0, 0.0)),
            ),
        ]);
        // Camera looking along vehicle +x (optical z = vehicle x).
        let vehicle_from_camera = Rigid::new(DQuat::from_xyzw(-0.5, 0.5, -0.5, 0.5), DVec3::ZERO);
        let k = CameraIntrinsics::pinhole(640, 480, 500.0, 500.0, 320.0, 240.0);
        // A LiDAR at the vehicle origin sees a point 20 m ahead at t = 0.5 s; the image is taken
        // at t = 0.5 s too, so the vehicle motion cancels.
        let pts = [[20.0f32, 0.0, 0.0]];
        let sweep = SweepView {
            points_in_lidar: &pts,
            intensity: &[7.0],
            time_offset_secs: Some(&[0.0]),
            stamp_nanos: 500_000_000,
        };
        let out = project_sweep(
            &sweep,
            &traj,
            Rigid::IDENTITY,
            vehicle_from_camera,
            &k,
            500_000_000,
            1,
        )
        .unwrap();
        assert_eq!(out.len(), 1);
        assert!((out[0].pixel[0] - 320.0).abs() < 1e-3 && (out[0].pixel[1] - 240.0).abs() < 1e-3);
        assert!((out[0].depth_m - 20.0).abs() < 1e-4);
        // The same point fired 0.1 s before the image: the vehicle was 1 m further back, so the
        // point is 1 m further from the camera... in world terms it sits at x = 4 + 20 = 24 → 19 m
        // ahead of the camera at t = 0.5 s.
        let sweep = SweepView {
            time_offset_secs: Some(&[-0.1]),
            ..sweep
        };
        let out = project_sweep(
            &sweep,
            &traj,
            Rigid::IDENTITY,
            vehicle_from_camera,
            &k,
            500_000_000,
            1,
        )
        .unwrap();
        assert!((out[0].depth_m - 19.0).abs() < 1e-3, "{}", out[0].depth_m);
    }
}
