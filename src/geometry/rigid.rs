//! Rigid transforms `a_from_b` (rotation as a unit quaternion + translation in metres) and the
//! rig-error metric of method.md §13.
//!
//! `Rigid` maps points: `p_a = a_from_b.transform_point(p_b) = R p_b + t`. Composition reads
//! right to left like the names: `world_from_vehicle * vehicle_from_lidar = world_from_lidar`.

use glam::{DAffine3, DMat3, DMat4, DQuat, DVec3};
use serde::{Deserialize, Serialize};
use std::ops::Mul;

use super::so3;

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rigid {
    pub rotation: DQuat,
    pub translation: DVec3,
}

impl Default for Rigid {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Rigid {
    pub const IDENTITY: Self = Self {
        rotation: DQuat::IDENTITY,
        translation: DVec3::ZERO,
    };

    pub fn new(rotation: DQuat, translation: DVec3) -> Self {
        Self {
            rotation: rotation.normalize(),
            translation,
        }
    }

    pub fn from_translation(translation: DVec3) -> Self {
        Self {
            rotation: DQuat::IDENTITY,
            translation,
        }
    }

    /// From a (near-)rigid 4×4 matrix; the rotation block is projected onto SO(3).
    pub fn from_mat4(m: DMat4) -> Self {
        let r = DMat3::from_mat4(m);
        Self {
            rotation: so3::quat_from_matrix_orthonormalized(r),
            translation: m.w_axis.truncate(),
        }
    }

    /// From row-major rows, as in most calibration files.
    pub fn from_rows(rows: [[f64; 4]; 4]) -> Self {
        Self::from_mat4(DMat4::from_cols_array_2d(&rows).transpose())
    }

    pub fn to_mat4(self) -> DMat4 {
        DMat4::from_rotation_translation(self.rotation, self.translation)
    }

    pub fn to_rows(self) -> [[f64; 4]; 4] {
        self.to_mat4().transpose().to_cols_array_2d()
    }

    pub fn to_affine(self) -> DAffine3 {
        DAffine3::from_rotation_translation(self.rotation, self.translation)
    }

    pub fn rotation_matrix(self) -> DMat3 {
        DMat3::from_quat(self.rotation)
    }

    pub fn inverse(self) -> Self {
        let inv = self.rotation.conjugate();
        Self {
            rotation: inv,
            translation: -(inv * self.translation),
        }
    }

    pub fn transform_point(self, p: DVec3) -> DVec3 {
        self.rotation * p + self.translation
    }

    pub fn transform_vector(self, v: DVec3) -> DVec3 {
        self.rotation * v
    }

    /// `self ∘ exp(δ)` with δ = (ω, v) applied on the right (in the `b` frame): a small
    /// perturbation of the source side. ω in radians, v in metres.
    pub fn perturbed_right(self, omega_rad: DVec3, v_m: DVec3) -> Self {
        self * Self {
            rotation: so3::exp(omega_rad),
            translation: v_m,
        }
    }

    /// Rotation angle (rad) and translation length (m) of `self⁻¹ ∘ other`... expressed as
    /// separate rotation and translation differences between two transforms of the same name.
    pub fn difference(self, other: Self) -> (f64, f64) {
        let rot = so3::angle_rad(self.rotation.conjugate() * other.rotation);
        (rot, (self.translation - other.translation).length())
    }

    /// Roll, pitch, yaw (fixed-axis X-Y-Z, as URDF `rpy`): R = Rz(yaw) Ry(pitch) Rx(roll).
    pub fn roll_pitch_yaw_rad(self) -> [f64; 3] {
        let (z, y, x) = self.rotation.to_euler(glam::EulerRot::ZYX);
        [x, y, z]
    }

    /// Interpolate: SLERP on rotation, linear on translation; `s` in [0, 1] (extrapolates outside).
    pub fn interpolate(self, other: Self, s: f64) -> Self {
        let mut q1 = other.rotation;
        if self.rotation.dot(q1) < 0.0 {
            q1 = -q1;
        }
        // Extrapolation-safe SLERP through the log map.
        let delta = so3::log(self.rotation.conjugate() * q1);
        Self {
            rotation: (self.rotation * so3::exp(delta * s)).normalize(),
            translation: self.translation.lerp(other.translation, s),
        }
    }
}

impl Mul for Rigid {
    type Output = Rigid;
    fn mul(self, rhs: Rigid) -> Rigid {
        Rigid {
            rotation: (self.rotation * rhs.rotation).normalize(),
            translation: self.rotation * rhs.translation + self.translation,
        }
    }
}

/// Error of one sensor after root alignment (method.md §13).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RigError {
    pub sensor: String,
    pub rotation_deg: f64,
    pub translation_m: f64,
    /// The error's rotation vector (°) in the reference sensor's own frame: how far the
    /// estimate is turned about each of the sensor's axes.
    #[serde(default)]
    pub rotation_axes_deg: [f64; 3],
    /// The error's translation (m) in the reference sensor's own frame.
    #[serde(default)]
    pub translation_axes_m: [f64; 3],
    /// The error's translation (m) in the vehicle frame: t'_s − t_ref.
    #[serde(default)]
    pub translation_vehicle_m: [f64; 3],
}

/// Rotation (deg) and translation (m) error of every sensor of `estimate` against `reference`,
/// after aligning the `root` sensor: G = T_ref,root · T_est,root⁻¹; T'_s = G · T_est,s;
/// e_R = angle(R_refᵀ R'_s), e_t = ‖t_ref − t'_s‖ (method.md §13), and per axis of the reference
/// sensor's frame: log(R_refᵀ R'_s) and R_refᵀ (t'_s − t_ref). Sensors missing from either side
/// are skipped; returns `None` when the root is missing.
pub fn rig_errors(
    reference: &[(String, Rigid)],
    estimate: &[(String, Rigid)],
    root: &str,
) -> Option<Vec<RigError>> {
    let find =
        |set: &[(String, Rigid)], name: &str| set.iter().find(|(n, _)| n == name).map(|(_, t)| *t);
    let alignment = find(reference, root)? * find(estimate, root)?.inverse();
    Some(
        reference
            .iter()
            .filter_map(|(name, vehicle_from_sensor_ref)| {
                let aligned = alignment * find(estimate, name)?;
                let (rot, trans) = vehicle_from_sensor_ref.difference(aligned);
                let reference_from_estimate = vehicle_from_sensor_ref.inverse() * aligned;
                Some(RigError {
                    sensor: name.clone(),
                    rotation_deg: rot.to_degrees(),
                    translation_m: trans,
                    rotation_axes_deg: (so3::log(reference_from_estimate.rotation) * 180.0
                        / std::f64::consts::PI)
                        .to_array(),
                    translation_axes_m: reference_from_estimate.translation.to_array(),
                    translation_vehicle_m: (aligned.translation
                        - vehicle_from_sensor_ref.translation)
                        .to_array(),
                })
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Rigid {
        Rigid::new(
            so3::exp(DVec3::new(0.2, -0.5, 1.0)),
            DVec3::new(1.0, -2.0, 0.5),
        )
    }

    #[test]
    fn inverse_composes_to_identity() {
        let t = sample();
        let i = t * t.inverse();
        assert!(i.translation.length() < 1e-12);
        assert!(so3::angle_rad(i.rotation) < 1e-12);
    }

    #[test]
    fn rig_errors_name_the_axis_in_the_sensor_frame() {
        let root = Rigid::IDENTITY;
        let truth = sample();
        // 1° about the sensor's own x axis and 2 cm along its own y axis.
        let off = truth
            * Rigid::new(
                so3::exp(DVec3::new(1f64.to_radians(), 0.0, 0.0)),
                DVec3::new(0.0, 0.02, 0.0),
            );
        let reference = vec![("root".to_string(), root), ("s".to_string(), truth)];
        let estimate = vec![("root".to_string(), root), ("s".to_string(), off)];
        let errors = rig_errors(&reference, &estimate, "root").unwrap();
        let e = &errors[1];
        assert!((e.rotation_deg - 1.0).abs() < 1e-9);
        assert!((e.translation_m - 0.02).abs() < 1e-9);
        let expect = [1.0, 0.0, 0.0, 0.0, 0.02, 0.0];
        let got = [
            e.rotation_axes_deg[0],
            e.rotation_axes_deg[1],
            e.rotation_axes_deg[2],
            e.translation_axes_m[0],
            e.translation_axes_m[1],
            e.translation_axes_m[2],
        ];
        for (g, x) in got.iter().zip(expect) {
            assert!((g - x).abs() < 1e-9, "{got:?}");
        }
        let in_vehicle = truth.rotation * DVec3::new(0.0, 0.02, 0.0);
        assert!((DVec3::from_array(e.translation_vehicle_m) - in_vehicle).length() < 1e-12);
    }

    #[test]
    fn matrix_round_trip() {
        let t = sample();
        let back = Rigid::from_rows(t.to_rows());
        let (r, d) = t.difference(back);
        assert!(r < 1e-12 && d < 1e-12);
        let p = DVec3::new(0.3, 0.7, -1.1);
        assert!((t.to_affine().transform_point3(p) - t.transform_point(p)).length() < 1e-12);
    }

    #[test]
    fn rpy_is_fixed_axis_xyz() {
        let (roll, pitch, yaw) = (0.1, -0.2, 0.3);
        let q = DQuat::from_rotation_z(yaw)
            * DQuat::from_rotation_y(pitch)
            * DQuat::from_rotation_x(roll);
        let rpy = Rigid::new(q, DVec3::ZERO).roll_pitch_yaw_rad();
        assert!(
            (rpy[0] - roll).abs() < 1e-12
                && (rpy[1] - pitch).abs() < 1e-12
                && (rpy[2] - yaw).abs() < 1e-12
        );
    }

    #[test]
    fn interpolation_endpoints_and_midpoint() {
        let a = Rigid::IDENTITY;
        let b = Rigid::new(DQuat::from_rotation_z(1.0), DVec3::new(2.0, 0.0, 0.0));
        let mid = a.interpolate(b, 0.5);
        assert!((so3::angle_rad(mid.rotation) - 0.5).abs() < 1e-12);
        assert!((mid.translation.x - 1.0).abs() < 1e-12);
        let (r, d) = a.interpolate(b, 1.0).difference(b);
        assert!(r < 1e-12 && d < 1e-12);
    }

    #[test]
    fn rig_errors_are_invariant_to_a_common_offset() {
        let reference = vec![
            ("root".to_string(), Rigid::IDENTITY),
            ("cam".to_string(), sample()),
        ];
        // The estimate differs by a global transform G plus a known error on `cam`.
        let g = Rigid::new(
            so3::exp(DVec3::new(0.0, 0.3, 0.0)),
            DVec3::new(5.0, 0.0, 0.0),
        );
        let err = Rigid::new(
            so3::exp(DVec3::new(1f64.to_radians(), 0.0, 0.0)),
            DVec3::new(0.0, 0.1, 0.0),
        );
        let estimate = vec![
            ("root".to_string(), g * Rigid::IDENTITY),
            ("cam".to_string(), g * sample() * err),
        ];
        let errors = rig_errors(&reference, &estimate, "root").unwrap();
        assert!(errors[0].rotation_deg < 1e-9 && errors[0].translation_m < 1e-12);
        assert!((errors[1].rotation_deg - 1.0).abs() < 1e-9);
        // Translation error of sample()*err vs sample(): R_sample * (0, 0.1, 0), length 0.1.
        assert!((errors[1].translation_m - 0.1).abs() < 1e-12);
        assert!(rig_errors(&reference, &estimate, "missing").is_none());
    }
}
