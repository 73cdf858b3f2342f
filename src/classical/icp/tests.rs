//! Tests of [`super`] (icp).

use super::*;
use glam::DQuat;

/// A 3 m pole of radius 0.3 m standing at (cx, cy).
fn pole(pts: &mut Vec<DVec3>, cx: f64, cy: f64) {
    for h in 0..30 {
        for t in 0..12 {
            let ang = t as f64 * std::f64::consts::TAU / 12.0;
            pts.push(DVec3::new(
                cx + 0.3 * ang.cos(),
                cy + 0.3 * ang.sin(),
                h as f64 * 0.1,
            ));
        }
    }
}

/// A street-like scene: ground, two façades, a few poles and boxes, sampled densely.
fn scene() -> Vec<DVec3> {
    let mut pts = Vec::new();
    for i in 0..200 {
        for j in 0..40 {
            let (a, b) = (i as f64 * 0.1 - 10.0, j as f64 * 0.1);
            pts.push(DVec3::new(a, b * 3.0 - 6.0, 0.0)); // ground
            pts.push(DVec3::new(a, 6.0, b * 1.5)); // façade left
            pts.push(DVec3::new(a, -6.0, b * 1.5)); // façade right
        }
    }
    for k in 0..8 {
        let (cx, cy) = (-8.0 + k as f64 * 2.3, if k % 2 == 0 { 3.0 } else { -3.5 });
        pole(&mut pts, cx, cy);
        // A box face facing the road.
        for u in 0..10 {
            for w in 0..10 {
                pts.push(DVec3::new(
                    cx + 1.0 + u as f64 * 0.08,
                    cy * 0.6,
                    w as f64 * 0.08,
                ));
            }
        }
    }
    pts
}

/// The target sees the scene from the vehicle; the source LiDAR's points are the same
/// scene expressed in its own frame (true extrinsic `truth`), vehicle moving along x.
fn problem(truth: Rigid, start: Rigid) -> IcpProblem {
    problem_with(truth, start, 0.0, IcpConfig::default())
}

/// As [`problem`], with the source LiDAR's ground returns farther than 8 m (horizontally)
/// raised as a beam-elevation error of `elevation_error_deg` would raise them: by the
/// horizontal distance times its tangent.
fn problem_with(
    truth: Rigid,
    start: Rigid,
    elevation_error_deg: f64,
    config: IcpConfig,
) -> IcpProblem {
    let world = scene();
    let poses: Vec<Rigid> = (0..4)
        .map(|k| {
            Rigid::new(
                DQuat::from_rotation_z(0.02 * k as f64),
                DVec3::new(k as f64 * 0.5, 0.0, 0.0),
            )
        })
        .collect();
    let source: Vec<SourcePoint> = world
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let wv = poses[i % poses.len()];
            let lidar = (wv * truth).translation;
            let distance = (*p - lidar).truncate().length();
            let measured = if p.z == 0.0 && distance > 8.0 {
                *p + DVec3::Z * distance * elevation_error_deg.to_radians().tan()
            } else {
                *p
            };
            let in_sensor = truth
                .inverse()
                .transform_point(wv.inverse().transform_point(measured));
            SourcePoint {
                in_sensor,
                world_from_vehicle: wv,
            }
        })
        .collect();
    IcpProblem::new(&world, &source, start, config)
}

/// Far ground returns raised by a 0.5° beam-elevation error (7–11 cm at 8–12.7 m) meet the
/// ground at 77–82° from 1.8 m up: with every correspondence they tilt the answer by
/// 0.24° / 1.7 cm, with the default incidence limit they are left out and the walls, poles
/// and near ground hold it ten times closer (0.023° / 0.23 cm: what is left comes through
/// the few target normals at the feet of walls, which mix ground and wall).
#[test]
fn grazing_returns_do_not_tilt_the_answer() {
    let truth = Rigid::new(
        DQuat::from_euler(glam::EulerRot::ZYX, 0.4, 0.02, -0.01),
        DVec3::new(1.2, -0.3, 1.8),
    );
    let start = Rigid::new(
        so3::exp(DVec3::new(0.3, -0.5, 0.8).normalize_or_zero() * 1f64.to_radians()),
        DVec3::new(0.06, 0.07, -0.04),
    ) * truth;
    let error = |config: IcpConfig| {
        let mut p = problem_with(truth, start, 0.5, config);
        p.run();
        let (rot, trans) = truth.difference(p.vehicle_from_source);
        (rot.to_degrees(), trans * 100.0)
    };
    let every = error(IcpConfig {
        min_incidence_cos: 0.0,
        ..IcpConfig::default()
    });
    let steep = error(IcpConfig::default());
    assert!(every.0 > 0.05, "every correspondence: {every:?}");
    assert!(
        steep.0 < every.0 / 5.0 && steep.1 < every.1 / 5.0,
        "steep only: {steep:?}, every: {every:?}"
    );
}

/// A street leaves the grazing returns out (walls, poles and near ground observe every
/// direction); a wide flat lot with a few poles keeps them: there the far ground holds most
/// of what is known about the LiDAR's pitch.
#[test]
fn grazing_returns_are_kept_only_where_the_rest_leaves_a_direction_open() {
    let truth = Rigid::new(
        DQuat::from_euler(glam::EulerRot::ZYX, 0.4, 0.02, -0.01),
        DVec3::new(1.2, -0.3, 1.8),
    );
    assert!(!problem(truth, truth).grazing_kept);
    let mut lot = Vec::new();
    for i in 0..400 {
        for j in 0..200 {
            lot.push(DVec3::new(
                i as f64 * 0.1 - 20.0,
                j as f64 * 0.1 - 10.0,
                0.0,
            ));
        }
    }
    for (cx, cy) in [(-6.0, 3.0), (5.0, -4.0), (9.0, 5.0)] {
        pole(&mut lot, cx, cy);
    }
    let source: Vec<SourcePoint> = lot
        .iter()
        .map(|p| SourcePoint {
            in_sensor: truth.inverse().transform_point(*p),
            world_from_vehicle: Rigid::IDENTITY,
        })
        .collect();
    let p = IcpProblem::new(&lot, &source, truth, IcpConfig::default());
    assert!(p.grazing_kept);
}

#[test]
fn recovers_a_known_extrinsic_from_perturbed_starts_in_both_directions() {
    let truth = Rigid::new(
        DQuat::from_euler(glam::EulerRot::ZYX, 0.4, 0.02, -0.01),
        DVec3::new(1.2, -0.3, 1.8),
    );
    for (deg, cm, sign) in [
        (1.0, 10.0, 1.0),
        (1.0, 10.0, -1.0),
        (2.0, 20.0, 1.0),
        (2.0, 20.0, -1.0),
    ] {
        let axis = DVec3::new(0.3, -0.5, 0.8).normalize_or_zero() * sign;
        let delta = Rigid::new(
            so3::exp(axis * f64::to_radians(deg)),
            DVec3::new(0.6, 0.7, -0.4).normalize_or_zero() * (sign * cm / 100.0),
        );
        let mut p = problem(truth, delta * truth);
        let stats = p.run();
        let (rot, trans) = truth.difference(p.vehicle_from_source);
        assert!(
            rot.to_degrees() < 0.01 && trans < 0.002,
            "{deg}° {cm} cm ({sign}): {:.4}° {:.2} mm, {stats:?}",
            rot.to_degrees(),
            trans * 1000.0
        );
        // At the exact answer the residual left is the planes' approximation of the 0.3 m
        // poles (gently curved neighbourhoods take part: `max_flatness`).
        assert!(
            stats.fitness > 0.5 && stats.inlier_rmse_m < 0.006,
            "{stats:?}"
        );
    }
}

#[test]
fn the_kd_tree_finds_the_nearest_point_like_brute_force() {
    let pts: Vec<DVec3> = (0..2000)
        .map(|i| {
            let f = i as f64;
            DVec3::new(
                (f * 0.618).fract() * 10.0,
                (f * 0.377).fract() * 5.0,
                (f * 0.123).fract(),
            )
        })
        .collect();
    let tree = KdTree::new(&pts);
    for k in 0..300 {
        let f = k as f64 * 0.731;
        let q = DVec3::new(
            f.fract() * 12.0 - 1.0,
            (f * 1.7).fract() * 6.0,
            (f * 2.3).fract() * 2.0,
        );
        let brute = (0..pts.len())
            .filter(|&i| pts[i].distance(q) <= 0.5)
            .min_by(|&a, &b| {
                pts[a]
                    .distance_squared(q)
                    .total_cmp(&pts[b].distance_squared(q))
            });
        let got = tree.nearest(q, 0.5).map(|i| i as usize);
        match (brute, got) {
            (Some(b), Some(g)) => {
                assert!((pts[b].distance(q) - pts[g].distance(q)).abs() < 1e-12)
            }
            (b, g) => assert_eq!(b, g),
        }
    }
}

/// The normal equations are the same to the bit on one thread and on four: their sums are
/// grouped by fixed chunks, not by how the threads shared the work (rayon's `fold` grouped
/// them by work stealing, so a whole pipeline run differed from run to run).
#[test]
fn the_normal_equations_do_not_depend_on_the_threads() {
    let truth = Rigid::new(
        DQuat::from_euler(glam::EulerRot::ZYX, 0.4, 0.02, -0.01),
        DVec3::new(1.2, -0.3, 1.8),
    );
    let start = Rigid::new(
        so3::exp(DVec3::new(0.01, -0.02, 0.015)),
        DVec3::new(0.1, 0.05, -0.08),
    );
    let p = problem(truth, start);
    let finest = p.config.levels.len() - 1;
    let on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| p.normal_equations(finest))
    };
    // Several chunks, so that the grouping matters.
    assert!(
        p.sources[finest].len() > 2 * SUM_CHUNK,
        "{}",
        p.sources[finest].len()
    );
    let one = on(1);
    for _ in 0..3 {
        assert_eq!(on(4), one);
    }
}
