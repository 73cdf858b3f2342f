//! How the step draws camera rays: heat maps, the LiDARs' highest beam, silhouettes and each
//! row's time under a rolling shutter.

use super::*;

#[test]
fn camera_pixels_follow_the_keypoint_heat_maps() {
    let (trajectory, mount, sweeps) = flat_drive();
    let mut camera = ground_camera(&trajectory);
    let keypoint = crate::features::orb::Keypoint {
        x: 20.0,
        y: 30.0,
        angle_rad: 0.0,
        response: 1.0,
        descriptor: [0; 4],
    };
    for f in &mut camera.frames {
        f.keypoints = vec![keypoint];
    }
    let config = DepthCalibConfig {
        iterations: 100,
        heatmap_start_fraction: 0.2,
        heatmap_uniform_share: 0.0,
        ..small_config()
    };
    let mut c = DepthCalibration::new(
        config,
        trajectory,
        vec![LidarData {
            name: "lidar".into(),
            initial: mount,
            sweeps,
        }],
    )
    .with_cameras(vec![camera]);
    assert_eq!(c.heatmap_sigma(1920.0), None, "uniform at first");
    c.iteration = 20;
    assert!((c.heatmap_sigma(1920.0).unwrap_or(0.0) - 40.0).abs() < 1e-9);
    assert!((c.heatmap_sigma(64.0).unwrap_or(0.0) - 40.0 * 64.0 / 1920.0).abs() < 1e-9);
    c.iteration = 100;
    assert!((c.heatmap_sigma(1920.0).unwrap_or(0.0) - 5.0).abs() < 1e-9);
    // σ = 5 px at 1920 wide is 0.17 px here: every draw is the keypoint's pixel.
    let intrinsics = c.camera_intrinsics("camera").cloned().unwrap();
    let rays = c.draw_camera_rays(0);
    assert!(!rays.is_empty());
    for r in &rays {
        let px = intrinsics.project(r.dir_in_sensor).unwrap();
        assert!(
            (px.x - 20.0).abs() < 0.51 && (px.y - 30.0).abs() < 0.51,
            "{px:?}"
        );
    }
}

/// With `camera_rays_below_lidar_top` no camera ray looks higher than the LiDAR's highest
/// return (the test LiDAR's returns lie 11.5° to 28.6° below its horizon; the camera, pitched
/// 25° down, sees from 56° below to 6° above), and without it some do.
#[test]
fn camera_rays_stay_below_the_lidars_highest_beam() {
    let (trajectory, mount, sweeps) = flat_drive();
    let lidars = vec![LidarData {
        name: "lidar".into(),
        initial: mount,
        sweeps,
    }];
    let top = crate::unical::coverage::lidar_top_elevation_rad(&lidars).unwrap();
    assert!(
        (top.to_degrees() + 11.46).abs() < 0.1,
        "{}",
        top.to_degrees()
    );
    let highest = |below: bool| {
        let config = DepthCalibConfig {
            camera_rays_below_lidar_top: below,
            ..small_config()
        };
        let mut c = DepthCalibration::new(config, trajectory.clone(), lidars.clone())
            .with_cameras(vec![ground_camera(&trajectory)]);
        let rays = c.draw_camera_rays(0);
        assert!(rays.len() > 50, "{}", rays.len());
        rays.iter()
            .map(|r| {
                let pose = c.camera.as_ref().unwrap().poses[0];
                let (_, d) = pose.ray(r.world_from_vehicle, r.dir_in_sensor);
                crate::unical::coverage::ray_elevation_rad(r.world_from_vehicle, d)
            })
            .fold(f64::MIN, f64::max)
    };
    assert!(highest(true) <= top, "{} > {}", highest(true), top);
    assert!(highest(false) > top + 0.1, "{}", highest(false));
}

/// Silhouette-guided sampling: a pole in front of the car is a depth discontinuity of the
/// sweeps; projected into the frames it is where the silhouette draws land.
#[test]
fn silhouette_draws_land_on_the_lidars_depth_edges() {
    let (trajectory, mount, mut sweeps) = flat_drive();
    // A ring 20° below the horizon: a pole 5 m ahead between far returns at 20 m.
    let el = -0.35f32;
    for s in &mut sweeps {
        for j in -30i32..=30 {
            let az = j as f32 * 0.01;
            let r = if j.abs() <= 2 { 5.0 } else { 20.0 };
            s.points_in_sensor.push([
                r * el.cos() * az.cos(),
                r * el.cos() * az.sin(),
                r * el.sin(),
            ]);
            s.intensity.push(40.0);
        }
    }
    let camera = ground_camera(&trajectory);
    let intrinsics = camera.intrinsics.clone();
    let vehicle_from_camera = camera.initial;
    let stamps: Vec<i64> = camera.frames.iter().map(|f| f.stamp_nanos).collect();
    let config = DepthCalibConfig {
        iterations: 100,
        heatmap_start_fraction: 0.2,
        heatmap_uniform_share: 0.0,
        silhouette_share: 1.0,
        ..small_config()
    };
    let mut c = one_lidar(config, &trajectory, mount, sweeps).with_cameras(vec![camera]);
    c.iteration = 100;
    c.refresh_silhouettes();
    // Each frame's silhouette pixels are the pole's two edge returns (its outermost, beside
    // the far ones) in the sweep at the frame's own stamp, seen by the camera.
    for f in 0..stamps.len() {
        let pixels = &c.silhouette_pixels.0[0][f];
        assert_eq!(pixels.len(), 2, "frame {f}: {pixels:?}");
        let camera_from_vehicle = vehicle_from_camera.inverse();
        for j in [-2, 2] {
            let az = j as f64 * 0.01;
            let p = DVec3::new(
                5.0 * (el as f64).cos() * az.cos(),
                5.0 * (el as f64).cos() * az.sin(),
                5.0 * (el as f64).sin(),
            );
            let in_camera = camera_from_vehicle.transform_point(mount.transform_point(p));
            let px = intrinsics.project(in_camera).unwrap();
            assert!(
                pixels
                    .iter()
                    .any(|q| (q.0 as f64 - px.x).abs() < 0.05 && (q.1 as f64 - px.y).abs() < 0.05),
                "frame {f}: {px:?} not in {pixels:?}"
            );
        }
    }
    // σ = 5 px at 1920 wide is 0.17 px here: every draw is at a silhouette pixel.
    let rays = c.draw_camera_rays(0);
    assert!(!rays.is_empty());
    let all: Vec<(f32, f32)> = c.silhouette_pixels.0[0].concat();
    for r in &rays {
        let px = intrinsics.project(r.dir_in_sensor).unwrap();
        assert!(
            all.iter()
                .any(|q| (px.x - q.0 as f64).abs() < 1.2 && (px.y - q.1 as f64).abs() < 1.2),
            "{px:?}"
        );
    }
}

/// A rolling shutter: every colour ray and every matched pixel's ray leaves from where the
/// vehicle was when its row was exposed (the test drive moves 8 m/s along x, so a ray's
/// origin tells its time), and a world point seen on a row projects back to that pixel.
#[test]
fn rolling_shutter_rays_leave_from_their_rows_time() {
    let (trajectory, mount, sweeps) = flat_drive();
    let readout = RowTimes::from_millis(-30.0, 10.0);
    let camera = CameraData {
        readout,
        ..ground_camera(&trajectory)
    };
    let (h, frame_stamps) = (
        camera.intrinsics.height,
        camera
            .frames
            .iter()
            .map(|f| f.stamp_nanos)
            .collect::<Vec<_>>(),
    );
    let mut c =
        one_lidar(small_config(), &trajectory, mount, sweeps).with_cameras(vec![camera.clone()]);
    // The ray's time from the vehicle's position, and the frame stamp it implies.
    let check = |wv: Rigid, y: f64| {
        let t_nanos = (wv.translation.x / 8.0 * 1e9).round() as i64;
        let stamp = t_nanos - readout.offset_nanos(y, h);
        assert!(
            frame_stamps.iter().any(|s| (s - stamp).abs() < 1_000),
            "row {y}: ray at {t_nanos} ns, stamp {stamp} not a frame's"
        );
    };
    let rays = c.draw_camera_rays(0);
    assert!(rays.len() > 50, "{}", rays.len());
    let mut rows = std::collections::BTreeSet::new();
    for r in &rays {
        let y = camera.intrinsics.project(r.dir_in_sensor).unwrap().y;
        check(r.world_from_vehicle, y);
        rows.insert(y.round() as i64);
    }
    // Rays from rows far apart leave from places far apart: 40 ms is 32 cm here.
    assert!(rows.len() > 20, "{rows:?}");
    for (frame, y) in [(0, 0.0), (3, 23.5), (6, 47.0)] {
        let ray = c.align_ray((0, frame), DVec2::new(30.0, y)).unwrap();
        check(ray.world_from_vehicle, y);
        assert!(
            ray.world_from_vehicle.translation.distance(
                trajectory
                    .world_from_vehicle(frame_stamps[frame] + readout.offset_nanos(y, h))
                    .unwrap()
                    .translation
            ) < 1e-9
        );
    }
    // A point 6 m out along pixel (x, y)'s ray at its row's time projects back onto it.
    for (x, y) in [(5.0, 2.0), (31.5, 23.5), (60.0, 45.0)] {
        let stamp = frame_stamps[2];
        let wv = trajectory
            .world_from_vehicle(camera.row_stamp_nanos(stamp, y))
            .unwrap();
        let u = camera.intrinsics.unproject(DVec2::new(x, y)).unwrap();
        let world_from_camera = wv * camera.initial;
        let p = world_from_camera.transform_point(u * 6.0 / u.z);
        let px = camera
            .project_world(&trajectory, camera.initial, stamp, p)
            .unwrap();
        assert!(px.distance(DVec2::new(x, y)) < 0.01, "({x}, {y}) -> {px:?}");
        // Projected as if the whole image were exposed at the stamp, it lands elsewhere.
        let global = CameraData {
            readout: RowTimes::GLOBAL,
            ..camera.clone()
        };
        let px_global = global
            .project_world(&trajectory, camera.initial, stamp, p)
            .unwrap();
        assert!(px_global.distance(DVec2::new(x, y)) > 0.05, "{px_global:?}");
    }
    // Matches found with one readout are not read back from the cache for another: the
    // overlap check places each frame at its middle row's pose.
    let global = CameraData {
        readout: RowTimes::GLOBAL,
        ..camera.clone()
    };
    let key = |c: &CameraData| {
        crate::unical::correspondences::cache_key(
            std::slice::from_ref(c),
            &[c.initial],
            &trajectory,
        )
    };
    assert_ne!(key(&camera), key(&global));
    assert_eq!(
        camera.middle_stamp_nanos(frame_stamps[0]),
        frame_stamps[0] - 10_000_000
    );
}
