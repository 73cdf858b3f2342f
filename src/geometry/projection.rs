//! LiDAR points into camera images: `camera_from_lidar(t)` with the trajectory interpolated at
//! each point's own firing time and at the image's stamp, then the full camera model.
//!
//! p_cam = (world_from_vehicle(t_img) · vehicle_from_camera)⁻¹ · world_from_vehicle(t_pt) ·
//! vehicle_from_lidar · p_lidar  (method.md §1 and §5). Points of a deskewed sweep share the
//! sweep stamp. Poses are interpolated once per time bucket (1 ms), not once per point.
//!
//! A rolling-shutter camera ([`RowTimes`]) was at its own pose for every image row: the camera
//! side is then taken at [`SAMPLED_ROWS`] rows spread from the top edge to the bottom edge,
//! a point is projected from the middle row's pose first and then again from the pose of the
//! row it fell on (`t_img` above becomes that row's time).

use glam::DVec3;
use rayon::prelude::*;

use super::camera::CameraIntrinsics;
use super::{Rigid, RowTimes, SAMPLED_ROWS, Trajectory, TrajectoryError};

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

/// The 1 ms bucket nearest a firing time (s, relative to the stamp): a point is moved with the
/// pose at most 0.5 ms from its own time, early or late alike.
fn bucket_of(offset_secs: f32) -> i64 {
    (offset_secs as f64 * 1e9 / BUCKET_NANOS as f64).round() as i64
}

/// First and last 1 ms firing-time bucket of a sweep (relative to its stamp); `None` when the
/// sweep has no per-point time (one bucket).
fn bucket_range(sweep: &SweepView<'_>) -> Option<(i64, i64)> {
    let offsets = sweep.time_offset_secs?;
    let (lo, hi) = offsets
        .iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), &t| (lo.min(t), hi.max(t)));
    (lo <= hi).then_some((bucket_of(lo), bucket_of(hi)))
}

/// `world_from_lidar` at every 1 ms bucket the sweep's points fall in.
fn world_from_lidar_buckets(
    sweep: &SweepView<'_>,
    trajectory: &Trajectory,
    vehicle_from_lidar: Rigid,
) -> Result<(i64, Vec<Rigid>), TrajectoryError> {
    let Some((first, last)) = bucket_range(sweep) else {
        return Ok((
            0,
            vec![trajectory.world_from_vehicle(sweep.stamp_nanos)? * vehicle_from_lidar],
        ));
    };
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

/// Every `stride`-th point of a sweep in the world frame, each moved with the trajectory at
/// its own firing time (for maps and aggregation).
pub fn world_points(
    sweep: &SweepView<'_>,
    trajectory: &Trajectory,
    vehicle_from_lidar: Rigid,
    stride: usize,
) -> Result<Vec<DVec3>, TrajectoryError> {
    let (first, poses) = world_from_lidar_buckets(sweep, trajectory, vehicle_from_lidar)?;
    let stride = stride.max(1);
    Ok((0..sweep.points_in_lidar.len())
        .step_by(stride)
        .map(|i| {
            let b = match sweep.time_offset_secs {
                Some(t) => (bucket_of(t[i]) - first).clamp(0, poses.len() as i64 - 1) as usize,
                None => 0,
            };
            let p = sweep.points_in_lidar[i];
            poses[b].transform_point(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        })
        .collect())
}

/// Index of each point's firing-time bucket into [`camera_from_lidar_buckets`]. It depends only
/// on the sweep, so a GPU can keep it while extrinsics change.
pub fn point_buckets(sweep: &SweepView<'_>) -> Vec<u32> {
    let n = sweep.points_in_lidar.len();
    match (bucket_range(sweep), sweep.time_offset_secs) {
        (Some((first, last)), Some(t)) => t
            .iter()
            .map(|&s| (bucket_of(s) - first).clamp(0, last - first) as u32)
            .collect(),
        _ => vec![0; n],
    }
}

/// How many camera poses an image has: one for a shutter that exposes every row at once (at
/// the stamp plus its one offset), else [`SAMPLED_ROWS`].
pub fn shutter_rows(readout: RowTimes) -> usize {
    if readout.first_row_nanos == readout.last_row_nanos {
        1
    } else {
        SAMPLED_ROWS
    }
}

/// `camera_from_lidar` at each firing-time bucket of a sweep, for an image taken at
/// `image_stamp_nanos`: `(world_from_vehicle(t_img) · vehicle_from_camera)⁻¹ ·
/// world_from_vehicle(t_bucket) · vehicle_from_lidar`. Small numbers even far from the world
/// origin, so they survive conversion to f32 for shaders.
pub fn camera_from_lidar_buckets(
    sweep: &SweepView<'_>,
    trajectory: &Trajectory,
    vehicle_from_lidar: Rigid,
    vehicle_from_camera: Rigid,
    image_stamp_nanos: i64,
) -> Result<Vec<Rigid>, TrajectoryError> {
    camera_from_lidar_rows(
        sweep,
        trajectory,
        vehicle_from_lidar,
        vehicle_from_camera,
        (image_stamp_nanos, RowTimes::GLOBAL),
        1,
    )
}

/// The firing-time buckets of a sweep: one per millisecond its points span (one for a
/// deskewed sweep); [`camera_from_lidar_buckets`] gives a transform for each.
pub fn bucket_count(sweep: &SweepView<'_>) -> usize {
    bucket_range(sweep).map_or(1, |(first, last)| (last - first + 1) as usize)
}

/// As [`camera_from_lidar_buckets`] for an image exposed row by row: `image` is its stamp and
/// its readout. `rows` transforms per bucket ([`shutter_rows`], or fewer to bound the table;
/// odd keeps one at the middle row), bucket-major (`[bucket * rows + row]`), at the readout's
/// samples ([`RowTimes::sampled_offsets_nanos`]; a single row is the middle row's).
pub fn camera_from_lidar_rows(
    sweep: &SweepView<'_>,
    trajectory: &Trajectory,
    vehicle_from_lidar: Rigid,
    vehicle_from_camera: Rigid,
    (image_stamp_nanos, readout): (i64, RowTimes),
    rows: usize,
) -> Result<Vec<Rigid>, TrajectoryError> {
    let cameras_from_world = readout
        .sampled_offsets_nanos(rows)
        .into_iter()
        .map(|offset| {
            Ok(
                (trajectory.world_from_vehicle(image_stamp_nanos + offset)? * vehicle_from_camera)
                    .inverse(),
            )
        })
        .collect::<Result<Vec<_>, TrajectoryError>>()?;
    let (_, buckets) = world_from_lidar_buckets(sweep, trajectory, vehicle_from_lidar)?;
    Ok(buckets
        .iter()
        .flat_map(|w| cameras_from_world.iter().map(move |c| *c * *w))
        .collect())
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
    project_sweep_rolling(
        sweep,
        trajectory,
        vehicle_from_lidar,
        vehicle_from_camera,
        intrinsics,
        (image_stamp_nanos, RowTimes::GLOBAL),
        stride,
    )
}

/// [`project_sweep`] into an image exposed row by row (`image`: its stamp and readout): each
/// point from the middle row's pose, then from the pose of the row it fell on.
pub fn project_sweep_rolling(
    sweep: &SweepView<'_>,
    trajectory: &Trajectory,
    vehicle_from_lidar: Rigid,
    vehicle_from_camera: Rigid,
    intrinsics: &CameraIntrinsics,
    (image_stamp_nanos, readout): (i64, RowTimes),
    stride: usize,
) -> Result<Vec<ProjectedPoint>, TrajectoryError> {
    let (first_bucket, _) = bucket_range(sweep).unwrap_or((0, 0));
    let rows = shutter_rows(readout);
    let camera_from_lidar = camera_from_lidar_rows(
        sweep,
        trajectory,
        vehicle_from_lidar,
        vehicle_from_camera,
        (image_stamp_nanos, readout),
        rows,
    )?;
    let buckets = camera_from_lidar.len() / rows;
    let stride = stride.max(1);
    let n = sweep.points_in_lidar.len();
    Ok((0..n.div_ceil(stride))
        .into_par_iter()
        .with_min_len(4096)
        .filter_map(|k| {
            let i = k * stride;
            let b = match sweep.time_offset_secs {
                Some(t) => (bucket_of(t[i]) - first_bucket).clamp(0, buckets as i64 - 1) as usize,
                None => 0,
            };
            let p = sweep.points_in_lidar[i];
            let p = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let mut p_cam = camera_from_lidar[b * rows + rows / 2].transform_point(p);
            let mut pixel = intrinsics.project(p_cam)?;
            if rows > 1 {
                let row = RowTimes::nearest_sample(pixel.y, intrinsics.height, rows);
                p_cam = camera_from_lidar[b * rows + row].transform_point(p);
                pixel = intrinsics.project(p_cam)?;
            }
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

/// Occlusion by depth-tested splats: which projected points are not hidden behind a nearer
/// surface. Every point writes its depth into a `(2r+1)²` square of a `width × height` min-depth
/// buffer; a point stays visible when its depth, pulled forward by `tolerance` (a fraction of
/// its depth), is not behind the buffer at its own pixel. The GPU overlay does the same with
/// round splats (`shaders/lidar_overlay.wgsl`).
pub fn visible_points(
    points: &[ProjectedPoint],
    width: u32,
    height: u32,
    radius_px: u32,
    tolerance: f32,
) -> Vec<bool> {
    let (w, h) = (width as usize, height as usize);
    if w == 0 || h == 0 {
        return vec![false; points.len()];
    }
    let pixel = |p: &ProjectedPoint| {
        let x = (p.pixel[0].round().max(0.0) as usize).min(w - 1);
        let y = (p.pixel[1].round().max(0.0) as usize).min(h - 1);
        (x, y)
    };
    let mut min_depth = vec![f32::INFINITY; w * h];
    let r = radius_px as usize;
    for p in points {
        let (x, y) = pixel(p);
        for yy in y.saturating_sub(r)..=(y + r).min(h - 1) {
            let row = &mut min_depth[yy * w..(yy + 1) * w];
            for d in &mut row[x.saturating_sub(r)..=(x + r).min(w - 1)] {
                *d = d.min(p.depth_m);
            }
        }
    }
    points
        .iter()
        .map(|p| {
            let (x, y) = pixel(p);
            p.depth_m * (1.0 - tolerance) <= min_depth[y * w + x]
        })
        .collect()
}

/// For tests of rolling-shutter projections: a drive at 8 m/s along x for a second, and a
/// camera on it 0.5 m right of the origin, 1.5 m up, looking right (−y), x along the drive.
#[cfg(test)]
pub(crate) fn sideways_camera_at_8_mps() -> (Trajectory, Rigid) {
    let trajectory = Trajectory::new(vec![
        (0, Rigid::IDENTITY),
        (
            1_000_000_000,
            Rigid::from_translation(DVec3::new(8.0, 0.0, 0.0)),
        ),
    ]);
    let vehicle_from_camera = Rigid::new(
        glam::DQuat::from_mat3(&glam::DMat3::from_cols(DVec3::X, DVec3::Z, -DVec3::Y)),
        DVec3::new(0.0, -0.5, 1.5),
    );
    (trajectory, vehicle_from_camera)
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

    /// A rolling shutter: a point placed along pixel (x, y)'s ray from where the camera was
    /// when row y was exposed projects back onto (x, y), within the rows' pose spacing; the
    /// global projection misses it. The bucket-major table reproduces the projection.
    #[test]
    fn a_rolling_shutter_projects_each_point_from_its_rows_pose() {
        // 8 m/s along x, a camera looking sideways (−y), a deskewed sweep.
        let (traj, vehicle_from_camera) = sideways_camera_at_8_mps();
        let vehicle_from_lidar = Rigid::new(DQuat::IDENTITY, DVec3::new(0.0, 0.0, 1.8));
        let k = CameraIntrinsics::pinhole(640, 480, 500.0, 500.0, 320.0, 240.0);
        let readout = RowTimes::from_millis(-30.0, 10.0);
        let (image_stamp, sweep_stamp) = (500_000_000, 480_000_000);
        let lidar_from_world =
            (traj.world_from_vehicle(sweep_stamp).unwrap() * vehicle_from_lidar).inverse();
        let pixels = [(20.0, 3.0), (320.0, 240.0), (600.0, 470.0), (100.0, 400.0)];
        let pts: Vec<[f32; 3]> = pixels
            .iter()
            .map(|&(x, y)| {
                let t = image_stamp + readout.offset_nanos(y, k.height);
                let world_from_camera = traj.world_from_vehicle(t).unwrap() * vehicle_from_camera;
                let ray = k.unproject(glam::DVec2::new(x, y)).unwrap();
                let p = lidar_from_world
                    .transform_point(world_from_camera.transform_point(ray * 10.0 / ray.z));
                [p.x as f32, p.y as f32, p.z as f32]
            })
            .collect();
        let sweep = SweepView {
            points_in_lidar: &pts,
            intensity: &[0.0; 4],
            time_offset_secs: None,
            stamp_nanos: sweep_stamp,
        };
        let project = |readout| {
            project_sweep_rolling(
                &sweep,
                &traj,
                vehicle_from_lidar,
                vehicle_from_camera,
                &k,
                (image_stamp, readout),
                1,
            )
            .unwrap()
        };
        let rolling = project(readout);
        let global = project(RowTimes::GLOBAL);
        assert_eq!(rolling.len(), 4);
        for (r, &(x, y)) in rolling.iter().zip(&pixels) {
            let miss = ((r.pixel[0] - x as f32).powi(2) + (r.pixel[1] - y as f32).powi(2)).sqrt();
            assert!(miss < 0.5, "({x}, {y}) -> {:?}", r.pixel);
        }
        // At the stamp the camera is 8–24 cm further along: the image's points shift by px.
        let g = global.iter().find(|g| g.index == 0).unwrap();
        assert!((g.pixel[0] - 20.0).abs() > 2.0, "{:?}", g.pixel);
        assert_eq!(shutter_rows(RowTimes::GLOBAL), 1);
        assert_eq!(shutter_rows(RowTimes::from_millis(5.0, 5.0)), 1);
        // The table the overlay uploads, for a sweep fired over 3 ms: bucket-major, entry
        // `b * rows + r` the camera at row r's time (r / 32 of the way from −30 to +10 ms; the
        // middle row, 16, at −10 ms) and the LiDAR at bucket b's.
        let times = [0.0f32, 0.001, 0.002, 0.003];
        let timed = SweepView {
            time_offset_secs: Some(&times),
            ..sweep
        };
        let table = camera_from_lidar_rows(
            &timed,
            &traj,
            vehicle_from_lidar,
            vehicle_from_camera,
            (image_stamp, readout),
            SAMPLED_ROWS,
        )
        .unwrap();
        assert_eq!(table.len(), 4 * SAMPLED_ROWS);
        assert_eq!(bucket_count(&timed), 4);
        assert_eq!(bucket_count(&sweep), 1);
        for (b, r) in [(0, 0), (1, 5), (2, 32), (3, 16)] {
            let row_nanos = -30_000_000 + 40_000_000 * r as i64 / 32;
            let expected = (traj.world_from_vehicle(image_stamp + row_nanos).unwrap()
                * vehicle_from_camera)
                .inverse()
                * traj
                    .world_from_vehicle(sweep_stamp + b as i64 * 1_000_000)
                    .unwrap()
                * vehicle_from_lidar;
            let (dr, dt) = table[b * SAMPLED_ROWS + r].difference(expected);
            assert!(dr < 1e-12 && dt < 1e-9, "bucket {b} row {r}: {dr} {dt}");
        }
    }

    #[test]
    fn bucket_transforms_reproduce_project_sweep() {
        let traj = Trajectory::new(vec![
            (0, Rigid::IDENTITY),
            (
                1_000_000_000,
                Rigid::new(DQuat::from_rotation_z(0.3), DVec3::new(10.0, 2.0, 0.0)),
            ),
        ]);
        let vehicle_from_camera = Rigid::new(DQuat::from_xyzw(-0.5, 0.5, -0.5, 0.5), DVec3::ZERO);
        let vehicle_from_lidar = Rigid::new(DQuat::from_rotation_z(0.1), DVec3::new(0.5, 0.0, 1.8));
        let mut k = CameraIntrinsics::pinhole(640, 480, 500.0, 500.0, 320.0, 240.0);
        k.model = crate::geometry::camera::CameraModel::PlumbBob;
        k.distortion = vec![-0.2, 0.05, 0.001, -0.001, 0.0];
        let pts: Vec<[f32; 3]> = (0..50)
            .map(|i| {
                [
                    15.0 + i as f32 * 0.3,
                    -4.0 + i as f32 * 0.17,
                    -1.0 + i as f32 * 0.05,
                ]
            })
            .collect();
        let times: Vec<f32> = (0..50).map(|i| -0.05 + i as f32 * 0.002).collect();
        let sweep = SweepView {
            points_in_lidar: &pts,
            intensity: &[0.0; 50],
            time_offset_secs: Some(&times),
            stamp_nanos: 400_000_000,
        };
        let reference = project_sweep(
            &sweep,
            &traj,
            vehicle_from_lidar,
            vehicle_from_camera,
            &k,
            420_000_000,
            1,
        )
        .unwrap();
        let buckets = point_buckets(&sweep);
        let transforms = camera_from_lidar_buckets(
            &sweep,
            &traj,
            vehicle_from_lidar,
            vehicle_from_camera,
            420_000_000,
        )
        .unwrap();
        assert!(transforms.len() > 50 && buckets.iter().all(|&b| (b as usize) < transforms.len()));
        assert!(!reference.is_empty());
        for r in &reference {
            let i = r.index as usize;
            let p = pts[i];
            let p_cam = transforms[buckets[i] as usize].transform_point(DVec3::new(
                p[0] as f64,
                p[1] as f64,
                p[2] as f64,
            ));
            let px = k.project(p_cam).unwrap();
            assert!(
                (px.x as f32 - r.pixel[0]).abs() < 1e-3 && (px.y as f32 - r.pixel[1]).abs() < 1e-3
            );
        }
    }

    #[test]
    fn points_behind_a_nearer_surface_are_hidden() {
        let point = |x: f32, y: f32, depth_m: f32| ProjectedPoint {
            pixel: [x, y],
            depth_m,
            intensity: 0.0,
            index: 0,
        };
        // A sparse near wall (every 4 px, 10 m) over x in [20, 40], a dense far wall (30 m)
        // everywhere, and a point on the near wall's own surface 2 % further.
        let mut points = Vec::new();
        for y in (0..60).step_by(4) {
            for x in (20..=40).step_by(4) {
                points.push(point(x as f32, y as f32, 10.0));
            }
        }
        let n_near = points.len();
        points.push(point(30.0, 30.0, 10.2));
        for y in 0..60 {
            for x in 0..60 {
                points.push(point(x as f32, y as f32, 30.0));
            }
        }
        let visible = visible_points(&points, 64, 64, 2, 0.05);
        assert!(
            visible[..=n_near].iter().all(|&v| v),
            "the near wall is visible"
        );
        for (p, v) in points[n_near + 1..].iter().zip(&visible[n_near + 1..]) {
            let inside = (20.0..=40.0).contains(&p.pixel[0]) && p.pixel[1] < 58.0;
            let outside = p.pixel[0] < 18.0 || p.pixel[0] > 42.0;
            if inside {
                assert!(!v, "far point at {:?} shows through the near wall", p.pixel);
            }
            if outside {
                assert!(
                    v,
                    "far point at {:?} was hidden with nothing in front",
                    p.pixel
                );
            }
        }
        // Without splat radius the gaps of the sparse near wall let the far wall through.
        let leaky = visible_points(&points, 64, 64, 0, 0.05);
        assert!(leaky[n_near + 1..].iter().filter(|&&v| v).count() > 3000);
    }
}
