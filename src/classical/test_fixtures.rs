//! Test fixtures shared by the hand-eye, camera-motion and LiDAR-map tests: a side camera and
//! deterministic noise.

use crate::geometry::{Rigid, so3};
use glam::{DMat3, DVec3};

/// A deterministic value in [−1, 1) for index `(k, j)`, one sequence per `salt`.
pub fn noise(k: usize, j: usize, salt: u64) -> f64 {
    crate::sim::noise::hash3(k as i32, j as i32, 3, salt) as f64 * 2.0 - 1.0
}

/// A side camera (looking left, optical z along the vehicle's +y) 1.2 m forward, 0.8 m left
/// and 1.7 m up.
pub fn left_camera() -> Rigid {
    let vehicle_from_optical = DMat3::from_cols(DVec3::X, -DVec3::Z, DVec3::Y);
    Rigid::new(
        so3::quat_from_matrix_orthonormalized(vehicle_from_optical),
        DVec3::new(1.2, 0.8, 1.7),
    )
}

/// `truth` turned 10° about an axis and moved 1 m along a direction, both drawn from `seed`
/// (`noise` with `salt`).
pub fn ten_degrees_and_a_metre_off(truth: Rigid, seed: usize, salt: u64) -> Rigid {
    let draw = |j: usize| {
        DVec3::new(
            noise(seed, j, salt),
            noise(seed, j + 1, salt),
            noise(seed, j + 2, salt),
        )
        .normalize_or_zero()
    };
    Rigid::new(
        so3::exp(draw(10) * 10f64.to_radians()) * truth.rotation,
        truth.translation + draw(13),
    )
}
