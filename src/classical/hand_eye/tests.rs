//! Tests of [`super`] (hand_eye).

use super::*;

use crate::classical::test_fixtures::left_camera;

/// A deterministic value in [−1, 1).
fn noise(k: usize, j: usize) -> f64 {
    crate::classical::test_fixtures::noise(k, j, 0x4E)
}

/// World poses of a vehicle on an S-shaped drive at 5 m/s, every 0.5 s.
fn s_drive() -> Vec<Rigid> {
    let (mut position, mut heading) = (DVec3::ZERO, 0.0f64);
    (0..24)
        .map(|k| {
            let yaw_rate = 0.35 * (k as f64 * 0.3).sin();
            heading += yaw_rate * 0.5;
            position += DVec3::new(heading.cos(), heading.sin(), 0.0) * 2.5;
            Rigid::new(DQuat::from_rotation_z(heading), position)
        })
        .collect()
}

/// Exact motion pairs of `camera` on `poses` (baselines within the candidate range), the
/// camera's rotation and direction disturbed by `noise_deg`.
fn pairs_of(camera: Rigid, poses: &[Rigid], noise_deg: f64) -> Vec<MotionPair> {
    let mut out = Vec::new();
    for i in 0..poses.len() {
        for j in i + 1..poses.len() {
            let motion = poses[i].inverse() * poses[j];
            if !(MIN_BASELINE_M..=MAX_BASELINE_M).contains(&motion.translation.length()) {
                continue;
            }
            let c = camera.inverse() * motion * camera;
            let k = out.len();
            let wobble = |s: usize| {
                DVec3::new(noise(k, s), noise(k, s + 1), noise(k, s + 2)) * noise_deg.to_radians()
            };
            let j_from_i = c.inverse();
            let rays: Vec<(DVec3, DVec3)> = (0..60)
                .filter_map(|m| {
                    let p = DVec3::new(
                        noise(k, 100 + 3 * m) * 8.0,
                        noise(k, 101 + 3 * m) * 4.0,
                        12.0 + 8.0 * noise(k, 102 + 3 * m),
                    );
                    let q = j_from_i.transform_point(p);
                    (q.z > 1.0).then(|| {
                        let shake = |v: DVec3, s: usize| {
                            (v.normalize_or_zero() + wobble(400 + s) * 0.35).normalize_or_zero()
                        };
                        (shake(p, m), shake(q, m + 200))
                    })
                })
                .collect();
            out.push(MotionPair {
                camera_rotation: so3::exp(wobble(0)) * c.rotation,
                camera_direction: (so3::exp(wobble(3)) * c.translation).normalize_or_zero(),
                vehicle_motion: motion,
                rays,
                first_image: 0,
            });
        }
    }
    out
}

#[test]
fn relative_motion_recovers_a_known_motion_in_both_directions() {
    let a_from_b = Rigid::new(
        so3::exp(DVec3::new(0.02, -0.08, 0.05)),
        DVec3::new(0.4, -0.1, 2.0),
    );
    let points_a: Vec<DVec3> = (0..200)
        .map(|k| {
            DVec3::new(
                noise(k, 0) * 6.0,
                noise(k, 1) * 3.0,
                8.0 + 6.0 * noise(k, 2),
            )
        })
        .collect();
    let b_from_a = a_from_b.inverse();
    let rays_a: Vec<DVec3> = points_a.iter().map(|p| p.normalize_or_zero()).collect();
    let rays_b: Vec<DVec3> = points_a
        .iter()
        .map(|p| b_from_a.transform_point(*p).normalize_or_zero())
        .collect();
    for (from, to, expected) in [(&rays_a, &rays_b, a_from_b), (&rays_b, &rays_a, b_from_a)] {
        let (rotation, direction, inliers) = relative_motion(from, to, 1).unwrap();
        assert!(inliers.len() >= 190, "{}", inliers.len());
        assert!(so3::angle_rad(rotation.inverse() * expected.rotation) < 1e-6);
        let truth = expected.translation.normalize_or_zero();
        assert!(direction.dot(truth) > 1.0 - 1e-9, "{direction} {truth}");
    }
}

#[test]
fn a_camera_ten_degrees_and_a_metre_off_comes_back_except_its_height_from_noisy_matches() {
    let truth = left_camera();
    let poses = s_drive();
    let mut pairs = pairs_of(truth, &poses, 0.05);
    // Two pairs whose images were matched on something moving.
    for (k, p) in pairs.iter_mut().take(2).enumerate() {
        p.camera_rotation =
            so3::exp(DVec3::new(0.2, -0.1, 0.3 * (k as f64 + 1.0))) * p.camera_rotation;
    }
    for seed in 0..4 {
        let start = crate::classical::test_fixtures::ten_degrees_and_a_metre_off(truth, seed, 0x4E);
        let fit = solve(&pairs, start).unwrap();
        let found = fit.vehicle_from_camera;
        let rotation_deg = so3::angle_rad(found.rotation.inverse() * truth.rotation).to_degrees();
        assert!(rotation_deg < 0.05, "seed {seed}: {rotation_deg}°");
        assert_eq!(
            fit.pairs_used,
            pairs.len() - 2,
            "the two bad pairs are dropped"
        );
        let error = found.translation - truth.translation;
        assert!(error.x.abs() < 0.01, "seed {seed}: {error}");
        // The sideways offset is along this camera's optical axis, which the scale-free
        // motion directions see least (module docs).
        assert!(error.y.abs() < 0.02, "seed {seed}: {error}");
        // A drive that only turns about the vertical cannot see the height.
        assert_eq!(fit.unobserved, vec!["z"]);
        assert!((found.translation.z - start.translation.z).abs() < 1e-6);
    }
}

#[test]
fn a_straight_drive_or_too_few_pairs_is_refused() {
    let truth = left_camera();
    let straight: Vec<Rigid> = (0..20)
        .map(|k| Rigid::from_translation(DVec3::X * k as f64 * 2.0))
        .collect();
    let pairs = pairs_of(truth, &straight, 0.0);
    assert!(matches!(
        solve(&pairs, truth),
        Err(HandEyeError::TooStraight { .. })
    ));
    assert!(matches!(
        solve(&pairs[..2], truth),
        Err(HandEyeError::TooFewPairs { found: 2, .. })
    ));
    // The same verdicts from the trajectory alone, before any image is read.
    let candidates: Vec<(usize, usize, Rigid)> = pairs
        .iter()
        .enumerate()
        .map(|(k, p)| (k, k + 1, p.vehicle_motion))
        .collect();
    assert!(matches!(
        check_turns(&candidates),
        Err(HandEyeError::TooStraight { .. })
    ));
    assert!(matches!(
        check_turns(&candidates[..2]),
        Err(HandEyeError::TooFewPairs { found: 2, .. })
    ));
    let turning: Vec<(usize, usize, Rigid)> = (0..6)
        .map(|k| {
            let turn = so3::exp(DVec3::Z * (k as f64 * 2.0).to_radians());
            (k, k + 1, Rigid::new(turn, DVec3::X * 3.0))
        })
        .collect();
    assert_eq!(check_turns(&turning), Ok(()));
}

/// [`s_drive`] with its turns scaled by `turning`.
fn s_drive_turning(turning: f64) -> Vec<Rigid> {
    let (mut position, mut heading) = (DVec3::ZERO, 0.0f64);
    (0..24)
        .map(|k| {
            heading += turning * 0.35 * (k as f64 * 0.3).sin() * 0.5;
            position += DVec3::new(heading.cos(), heading.sin(), 0.0) * 2.5;
            Rigid::new(DQuat::from_rotation_z(heading), position)
        })
        .collect()
}

#[test]
fn the_rotations_sigma_grows_as_the_turns_that_observe_it_shrink() {
    // The camera's tilt (about its own x, the vehicle's forward) is seen only through the
    // turns' axes: a drive that turns a quarter as much leaves it less certain, and each
    // axis's error stays within a few of its σ.
    let truth = left_camera();
    let mut sigmas = Vec::new();
    for turning in [1.0, 0.25] {
        let pairs = pairs_of(truth, &s_drive_turning(turning), 0.05);
        let fit = solve(&pairs, truth).unwrap();
        let error = so3::log(truth.rotation.inverse() * fit.vehicle_from_camera.rotation);
        let sigma = fit.rotation_sigma_deg;
        assert!(sigma.is_finite() && sigma.min_element() > 0.0, "{sigma}");
        for k in 0..3 {
            assert!(
                error[k].abs().to_degrees() <= 4.0 * sigma[k] + 0.005,
                "turning {turning}: axis {k} off {:.4}° with σ {:.4}°",
                error[k].to_degrees(),
                sigma[k]
            );
        }
        sigmas.push(sigma);
    }
    assert!(sigmas[1].x > 2.0 * sigmas[0].x, "{sigmas:?}");
}
