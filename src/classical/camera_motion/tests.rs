//! Tests of [`super`] (camera_motion): the rounds of hand-eye and map fit.

use super::*;
use crate::classical::hand_eye::{MAX_BASELINE_M, MIN_BASELINE_M};
use crate::classical::test_fixtures::left_camera;
use crate::geometry::so3;
use glam::DQuat;

/// A deterministic value in [−1, 1).
fn noise(k: usize, j: usize) -> f64 {
    crate::classical::test_fixtures::noise(k, j, 0x3C)
}

/// Flat ground sampled every 0.15 m and 1 m-square, 6 m-high pillars every 8 m over the area
/// the drive crosses: structure at every distance, in every direction.
fn town() -> Vec<DVec3> {
    let mut out = Vec::new();
    for i in -80..480 {
        for j in -200..200 {
            out.push(DVec3::new(i as f64 * 0.15, j as f64 * 0.15, 0.0));
        }
    }
    for px in -1..9 {
        for py in -3..4 {
            let (x0, y0) = (px as f64 * 8.0 + 3.0, py as f64 * 8.0 + 4.0);
            for k in 0..30 {
                let z = k as f64 * 0.2;
                for d in 0..5 {
                    let d = d as f64 * 0.2;
                    out.push(DVec3::new(x0 + d, y0, z));
                    out.push(DVec3::new(x0 + d, y0 + 1.0, z));
                    out.push(DVec3::new(x0, y0 + d, z));
                    out.push(DVec3::new(x0 + 1.0, y0 + d, z));
                }
            }
        }
    }
    out
}

/// A weaving drive at 5 m/s, every 0.5 s, turning up to 20° either way.
fn weave() -> Vec<Rigid> {
    let mut position = DVec3::ZERO;
    (0..22)
        .map(|k| {
            let heading = 0.35 * (k as f64 * 0.35).sin();
            position += DVec3::new(heading.cos(), heading.sin(), 0.0) * 2.5;
            Rigid::new(DQuat::from_rotation_z(heading), position)
        })
        .collect()
}

/// The motion pairs `camera` would give on `poses` in `map`: exact matches of the map
/// points both images see (the camera's motion read from them as the hand-eye reads it).
fn found(camera: Rigid, start: Rigid, poses: &[Rigid], map: &[DVec3]) -> CameraPairs {
    let mut pairs = Vec::new();
    for i in 0..poses.len() {
        for j in i + 1..poses.len() {
            let motion = poses[i].inverse() * poses[j];
            let baseline = motion.translation.length();
            if !(MIN_BASELINE_M..=MAX_BASELINE_M).contains(&baseline) {
                continue;
            }
            let (ci, cj) = ((poses[i] * camera).inverse(), (poses[j] * camera).inverse());
            let seen: Vec<(DVec3, DVec3)> = map
                .iter()
                .filter_map(|&p| {
                    let (a, b) = (ci.transform_point(p), cj.transform_point(p));
                    let inside = |v: DVec3| {
                        v.z > 1.0 && v.z < 30.0 && v.x.abs() < v.z && v.y.abs() < 0.6 * v.z
                    };
                    (inside(a) && inside(b)).then(|| (a.normalize_or_zero(), b.normalize_or_zero()))
                })
                .collect();
            let c = camera.inverse() * motion * camera;
            let k = pairs.len();
            let wobble = DVec3::new(noise(k, 0), noise(k, 1), noise(k, 2)) * 0.02f64.to_radians();
            pairs.push(MotionPair {
                camera_rotation: so3::exp(wobble) * c.rotation,
                camera_direction: c.translation.normalize_or_zero(),
                vehicle_motion: motion,
                rays: crate::log::spread_evenly(&seen, 150),
                first_image: i,
            });
        }
    }
    CameraPairs {
        start,
        pairs,
        world_from_vehicle: poses.iter().copied().map(Some).collect(),
    }
}

#[test]
fn every_start_ends_at_the_truth_after_rounds_of_hand_eye_and_map_where_one_fit_alone_is_biased() {
    let (points, poses, truth) = (town(), weave(), left_camera());
    let map = LidarMap::new(points.clone());
    let (mut ends, mut first_fits) = (Vec::new(), Vec::new());
    for seed in 0..3 {
        let start = crate::classical::test_fixtures::ten_degrees_and_a_metre_off(truth, seed, 0x3C);
        let pairs = found(truth, start, &poses, &points);
        // One hand-eye fit holds the height at the start's, a metre off, and pulls the rest of
        // the translation toward it (its prior): the lever arm's error biases the rotation
        // (up to 0.04° here, on exact matches).
        let once = solve(&pairs.pairs, start).unwrap();
        assert_eq!(once.unobserved, vec!["z"]);
        first_fits.push(truth.difference(once.vehicle_from_camera).0.to_degrees());
        let (fit, measured, rounds) = fit_with_map(&pairs, Some(&map));
        assert!(fit.is_ok(), "seed {seed}: {fit:?}");
        let end = match measured {
            Some(Ok(m)) => m.vehicle_from_camera,
            other => panic!("seed {seed}: no map fit: {other:?}"),
        };
        // A start a metre off moves in the first map fit: a second round follows.
        assert!(
            (2..=MAX_ROUNDS).contains(&rounds),
            "seed {seed}: {rounds} rounds"
        );
        let (turned, shifted) = truth.difference(end);
        assert!(
            turned.to_degrees() < 0.005,
            "seed {seed}: {}°",
            turned.to_degrees()
        );
        assert!(shifted < 0.005, "seed {seed}: {shifted} m");
        ends.push(end);
    }
    let worst_first = first_fits.iter().copied().fold(0.0, f64::max);
    assert!(worst_first > 0.02, "the first fit alone: {first_fits:?}°");
    for end in &ends[1..] {
        let (turned, shifted) = ends[0].difference(*end);
        assert!(
            turned.to_degrees() < 0.01 && shifted < 0.005,
            "{}° {} m",
            turned.to_degrees(),
            shifted
        );
    }
    // Without a map there is one round, the hand-eye fit alone.
    let (fit, measured, rounds) = fit_with_map(&found(truth, truth, &poses, &points), None);
    assert!(fit.is_ok() && measured.is_none() && rounds == 1);
}
