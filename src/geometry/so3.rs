//! SO(3) exponential and logarithm maps (axis-angle vectors ↔ rotation matrices / quaternions).
//!
//! `exp(ω)` is Rodrigues' formula, with a Taylor expansion near zero; `log(R)` goes through the
//! unit quaternion, which is well conditioned everywhere including near π (unlike the trace form).

use glam::{DMat3, DQuat, DVec3};

/// Rotation by the axis-angle vector `omega_rad` (axis · angle in radians).
pub fn exp(omega_rad: DVec3) -> DQuat {
    let theta = omega_rad.length();
    if theta < 1e-12 {
        // q ≈ (ω/2, 1), normalised: exact to second order.
        return DQuat::from_xyzw(omega_rad.x * 0.5, omega_rad.y * 0.5, omega_rad.z * 0.5, 1.0)
            .normalize();
    }
    DQuat::from_axis_angle(omega_rad / theta, theta)
}

/// Axis-angle vector of a rotation, with angle in [0, π].
pub fn log(rotation: DQuat) -> DVec3 {
    // Take the hemisphere with w ≥ 0 so the angle is in [0, π].
    let q = if rotation.w < 0.0 {
        -rotation
    } else {
        rotation
    };
    let v = DVec3::new(q.x, q.y, q.z);
    let sin_half = v.length();
    if sin_half < 1e-12 {
        return v * 2.0;
    }
    let theta = 2.0 * sin_half.atan2(q.w);
    v * (theta / sin_half)
}

/// Matrix form of [`exp`].
pub fn exp_mat(omega_rad: DVec3) -> DMat3 {
    DMat3::from_quat(exp(omega_rad))
}

/// Skew-symmetric (cross-product) matrix: `hat(a) * b == a × b`.
pub fn hat(a: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, a.z, -a.y),
        DVec3::new(-a.z, 0.0, a.x),
        DVec3::new(a.y, -a.x, 0.0),
    )
}

/// Outer product `a bᵀ` (`outer(a, b) * c == a (b · c)`).
pub fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// Angle of a rotation in radians, in [0, π].
pub fn angle_rad(rotation: DQuat) -> f64 {
    log(rotation).length()
}

/// Quaternion from a rotation matrix that may be slightly non-orthonormal (e.g. parsed from a
/// file with 9-12 digits): projects to the nearest rotation first.
pub fn quat_from_matrix_orthonormalized(m: DMat3) -> DQuat {
    // Polar decomposition by a few Newton iterations R ← (R + R^-T)/2; converges quadratically
    // for near-orthonormal input.
    let mut r = m;
    for _ in 0..5 {
        let det = r.determinant();
        if det.abs() < 1e-12 {
            break;
        }
        r = (r + r.inverse().transpose()) * 0.5;
    }
    DQuat::from_mat3(&r).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_log_round_trip() {
        for omega in [
            DVec3::new(0.1, -0.2, 0.3),
            DVec3::new(1e-9, 0.0, 2e-9),
            DVec3::new(0.0, 0.0, std::f64::consts::PI - 1e-6),
            DVec3::new(-2.0, 0.5, 0.7),
        ] {
            let back = log(exp(omega));
            assert!((back - omega).length() < 1e-9, "{omega} -> {back}");
        }
    }

    #[test]
    fn exp_matches_rodrigues() {
        let omega = DVec3::new(0.3, -0.4, 1.2);
        let theta = omega.length();
        let k = hat(omega / theta);
        let rodrigues = DMat3::IDENTITY + k * theta.sin() + k * k * (1.0 - theta.cos());
        let ours = exp_mat(omega);
        for (a, b) in ours.to_cols_array().iter().zip(rodrigues.to_cols_array()) {
            assert!((a - b).abs() < 1e-12);
        }
    }

    #[test]
    fn hat_is_cross_product() {
        let a = DVec3::new(1.0, 2.0, 3.0);
        let b = DVec3::new(-0.5, 0.25, 4.0);
        assert!((hat(a) * b - a.cross(b)).length() < 1e-12);
    }
}
