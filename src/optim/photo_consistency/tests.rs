//! Tests of [`super`] (photo_consistency).

use super::*;
use crate::geometry::so3;
use glam::{DMat3, DQuat};

/// A street side: a textured wall at y = 8 m and textured ground 1.5 m below the vehicle.
fn albedo(p: DVec3) -> f32 {
    let v = if p.y > 7.99 {
        (1.3 * p.x).sin() * (1.7 * p.z).sin() + 0.5 * (5.1 * p.x + 2.3 * p.z).sin()
    } else {
        (2.1 * p.x + 0.7 * p.y).sin() * (1.1 * p.y).cos() + 0.4 * (4.3 * p.y - 3.7 * p.x).sin()
    };
    v as f32
}

fn hit(origin: DVec3, dir: DVec3) -> Option<DVec3> {
    let mut best: Option<f64> = None;
    if dir.y > 1e-9 {
        best = Some((8.0 - origin.y) / dir.y);
    }
    if dir.z < -1e-9 {
        let t = (-1.5 - origin.z) / dir.z;
        if best.is_none_or(|b| t < b) {
            best = Some(t);
        }
    }
    best.filter(|t| *t > 0.0).map(|t| origin + dir * t)
}

/// A camera looking left (+y) from the vehicle's origin: x right = +x, y down = −z.
fn vehicle_from_camera() -> Rigid {
    let m = DMat3::from_cols(DVec3::X, DVec3::NEG_Z, DVec3::Y);
    Rigid::new(DQuat::from_mat3(&m), DVec3::ZERO)
}

fn scene() -> (CameraIntrinsics, Vec<PhotoImage>, Vec<DVec3>) {
    scene_read_out(RowTimes::GLOBAL, |t| 10.0 * t)
}

/// A drive along x speeding up from standing, 20 m/s²: 14 m/s at the last frame.
fn speeding_up(t_secs: f64) -> f64 {
    10.0 * t_secs * t_secs
}

/// [`speeding_up`] as a trajectory, a pose every 10 ms.
fn speeding_up_trajectory() -> crate::geometry::Trajectory {
    crate::geometry::Trajectory::new(
        (-20..100)
            .map(|i| {
                let t = i as f64 * 0.01;
                (
                    i * 10_000_000,
                    Rigid::from_translation(DVec3::new(speeding_up(t.max(0.0)), 0.0, 0.0)),
                )
            })
            .collect(),
    )
}

/// The street side seen every 100 ms by a camera whose rows are exposed at `readout`'s
/// times, while the vehicle is at x = `x_m(t)`.
fn scene_read_out(
    readout: RowTimes,
    x_m: fn(f64) -> f64,
) -> (CameraIntrinsics, Vec<PhotoImage>, Vec<DVec3>) {
    let intrinsics = CameraIntrinsics::pinhole(160, 120, 100.0, 100.0, 79.5, 59.5);
    let truth = vehicle_from_camera();
    let images = (0..8)
        .map(|i| {
            let stamp_secs = i as f64 * 0.1;
            let world_from_vehicle = Rigid::from_translation(DVec3::new(x_m(stamp_secs), 0.0, 0.0));
            let mut grey = Vec::with_capacity(160 * 120);
            for y in 0..120 {
                let t = stamp_secs + readout.offset_nanos(y as f64, 120) as f64 * 1e-9;
                let world_from_camera =
                    Rigid::from_translation(DVec3::new(x_m(t.max(0.0)), 0.0, 0.0)) * truth;
                for x in 0..160 {
                    let ray = intrinsics
                        .unproject(DVec2::new(x as f64, y as f64))
                        .unwrap_or(DVec3::Z);
                    let dir = world_from_camera.transform_vector(ray);
                    grey.push(hit(world_from_camera.translation, dir).map_or(0.0, albedo));
                }
            }
            PhotoImage {
                width: 160,
                height: 120,
                grey,
                vehicle_from_world: world_from_vehicle.inverse(),
                stamp_nanos: i * 100_000_000,
                readout: RowTimes::GLOBAL,
                row_poses: Vec::new(),
            }
        })
        .collect();
    let mut points = Vec::new();
    for i in 0..120 {
        let x = -5.0 + i as f64 * 0.15;
        for k in 0..35 {
            points.push(DVec3::new(x, 8.0, -1.5 + k as f64 * 0.15));
        }
        for k in 0..45 {
            points.push(DVec3::new(x, 1.5 + k as f64 * 0.15, -1.5));
        }
    }
    (intrinsics, images, points)
}

fn problem() -> PhotoProblem {
    let (intrinsics, images, points) = scene();
    let config = PhotoConfig {
        min_range_m: 1.0,
        ..PhotoConfig::default()
    };
    PhotoProblem::new(
        "left",
        intrinsics,
        images,
        points,
        vehicle_from_camera(),
        &config,
    )
}

#[test]
fn thinning_keeps_one_point_per_voxel() {
    let points = [
        DVec3::new(0.01, 0.02, 0.03),
        DVec3::new(0.05, 0.06, 0.07),
        DVec3::new(0.15, 0.02, 0.03),
        DVec3::new(-0.01, 0.02, 0.03),
    ];
    let kept = voxel_thin(&points, 0.1, |p| *p);
    assert_eq!(kept, vec![points[0], points[2], points[3]]);
}

#[test]
fn the_images_agree_best_at_the_true_extrinsic() {
    let problem = problem();
    assert!(problem.point_count() > 1000, "{}", problem.point_count());
    let truth = vehicle_from_camera();
    let at_truth = problem.cost(truth);
    for axis in 0..3 {
        for sign in [-1.0, 1.0] {
            let mut omega = DVec3::ZERO;
            omega[axis] = sign * 0.3f64.to_radians();
            let turned = Rigid::new(so3::exp(omega) * truth.rotation, truth.translation);
            assert!(
                problem.cost(turned) > at_truth * 1.05,
                "axis {axis} sign {sign}: {} vs {at_truth}",
                problem.cost(turned)
            );
        }
    }
}

/// A rolling shutter (rows exposed from 30 ms before the stamp to 10 ms after) on a drive
/// that speeds up, so the rows' spread along the drive grows from frame to frame (at
/// one speed every frame would shear alike and agree): the images agree at the true
/// extrinsic when each row is placed at its time, not when the image is placed at one
/// time, and then best near the middle row's time, 10 ms before the stamp.
#[test]
fn a_rolling_shutters_rows_are_placed_at_their_own_times() {
    let readout = RowTimes::from_millis(-30.0, 10.0);
    let (intrinsics, mut images, points) = scene_read_out(readout, speeding_up);
    let trajectory = speeding_up_trajectory();
    let config = PhotoConfig {
        min_range_m: 1.0,
        ..PhotoConfig::default()
    };
    let truth = vehicle_from_camera();
    let problem_with = |readout: RowTimes, images: &mut Vec<PhotoImage>| {
        for image in images.iter_mut() {
            image.readout = readout;
            image.place(&trajectory, 0).unwrap();
        }
        PhotoProblem::new(
            "left",
            intrinsics.clone(),
            images.clone(),
            points.clone(),
            truth,
            &config,
        )
    };
    let rolling = problem_with(readout, &mut images);
    assert_eq!(rolling.images[0].row_poses.len(), SAMPLED_ROWS);
    let global = problem_with(RowTimes::GLOBAL, &mut images);
    assert!(global.images[0].row_poses.is_empty());
    let (at_rows, at_stamp) = (rolling.cost(truth), global.cost(truth));
    assert!(at_rows < 0.25 * at_stamp, "{at_rows} vs {at_stamp}");
    // The best single time for the whole image is the middle row's.
    let best_delay_ms = (-40..=20)
        .step_by(5)
        .map(|ms| {
            (
                ms,
                global
                    .delayed(&trajectory, ms * 1_000_000)
                    .unwrap()
                    .cost(truth),
            )
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap()
        .0;
    assert!((-15..=-5).contains(&best_delay_ms), "{best_delay_ms}");
    // Delayed by nothing, the rolling problem is itself.
    assert_eq!(
        rolling.delayed(&trajectory, 0).unwrap().cost(truth),
        at_rows
    );
}

/// Intrinsics 1 % too long or too short are found as the scale that undoes them, and the
/// true ones as 1.
#[test]
fn the_best_focal_scale_undoes_a_wrong_focal_length() {
    let problem = problem();
    let truth = vehicle_from_camera();
    let found = problem.best_focal_scale(truth).unwrap();
    assert!((found - 1.0).abs() < 1e-3, "{found}");
    for wrong in [1.01, 0.99] {
        let found = problem
            .with_focal_scale(wrong)
            .best_focal_scale(truth)
            .unwrap();
        assert!((found * wrong - 1.0).abs() < 1.5e-3, "{wrong}: {found}");
    }
}

#[test]
fn the_search_returns_to_the_true_rotation_from_either_side() {
    let problem = problem();
    let truth = vehicle_from_camera();
    for omega_deg in [
        DVec3::new(0.6, 0.0, 0.0),
        DVec3::new(-0.6, 0.0, 0.0),
        DVec3::new(0.3, -0.4, 0.3),
        DVec3::new(-0.2, 0.4, -0.5),
    ] {
        let start = Rigid::new(
            so3::exp(omega_deg * std::f64::consts::PI / 180.0) * truth.rotation,
            truth.translation,
        );
        let mut search = search(&problem, start);
        search.translate = false;
        search.step_rad = 0.2f64.to_radians();
        for _ in 0..300 {
            if search.converged() {
                break;
            }
            search.step_with(|pose| problem.cost(pose));
        }
        let (rot, _) = truth.difference(search.best);
        assert!(
            rot.to_degrees() < 0.05,
            "from {omega_deg:?}°: {:.3}° left",
            rot.to_degrees()
        );
    }
}
