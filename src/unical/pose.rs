//! Sensor poses as optimisation variables (method.md §11): the extrinsic `vehicle_from_sensor`
//! as a continuous 6D rotation (the first two columns of R, Gram–Schmidt back to a rotation) and
//! a translation, with the backward pass from ray gradients to these parameters.
//!
//! A ray of sensor s fired at time t: `o = P(t)·t_s`, `d = R_P R_s u` with u the unit direction
//! in the sensor frame and P(t) = `world_from_vehicle(t)`. Samples `x_i = o + τ_i d`, so
//! `∂L/∂o = Σ ∂L/∂x_i` and `∂L/∂d = Σ τ_i ∂L/∂x_i`; then `∂L/∂t_s = R_Pᵀ ∂L/∂o` and
//! `∂L/∂R_s = (R_Pᵀ ∂L/∂d) uᵀ`, pulled back through Gram–Schmidt to the 6D vector.

use glam::{DMat3, DVec3};

use crate::geometry::{Rigid, rot6d};

/// One sensor's extrinsic as free parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseParams {
    pub r6: [f64; 6],
    pub translation_m: DVec3,
}

/// Gradient with respect to [`PoseParams`].
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct PoseGrad {
    pub r6: [f64; 6],
    pub translation_m: DVec3,
}

impl PoseGrad {
    pub fn add(&mut self, o: &PoseGrad) {
        for k in 0..6 {
            self.r6[k] += o.r6[k];
        }
        self.translation_m += o.translation_m;
    }
}

impl PoseParams {
    pub fn from_rigid(vehicle_from_sensor: Rigid) -> Self {
        Self {
            r6: rot6d::from_matrix(vehicle_from_sensor.rotation_matrix()),
            translation_m: vehicle_from_sensor.translation,
        }
    }

    pub fn rotation(&self) -> DMat3 {
        rot6d::to_matrix(self.r6).unwrap_or(DMat3::IDENTITY)
    }

    pub fn to_rigid(&self) -> Rigid {
        Rigid::new(
            glam::DQuat::from_mat3(&self.rotation()).normalize(),
            self.translation_m,
        )
    }

    /// World ray of a sensor-frame unit direction `u` when the vehicle is at `world_from_vehicle`.
    pub fn ray(&self, world_from_vehicle: Rigid, u: DVec3) -> (DVec3, DVec3) {
        let rp = world_from_vehicle.rotation_matrix();
        (
            world_from_vehicle.transform_point(self.translation_m),
            rp * (self.rotation() * u),
        )
    }

    /// Pull ∂L/∂o and ∂L/∂d of a ray back to the pose parameters.
    pub fn ray_backward(
        &self,
        world_from_vehicle: Rigid,
        u: DVec3,
        d_origin: DVec3,
        d_direction: DVec3,
    ) -> PoseGrad {
        let rpt = world_from_vehicle.rotation_matrix().transpose();
        let g_dir_vehicle = rpt * d_direction;
        // ∂L/∂R = g uᵀ: column j is g·u_j.
        let d_rotation = DMat3::from_cols(
            g_dir_vehicle * u.x,
            g_dir_vehicle * u.y,
            g_dir_vehicle * u.z,
        );
        PoseGrad {
            r6: rot6d_backward(self.r6, d_rotation),
            translation_m: rpt * d_origin,
        }
    }
}

/// Backward of the Gram–Schmidt map `[a1, a2] → R = [b1 b2 b3]` (columns).
pub fn rot6d_backward(r6: [f64; 6], d_rotation: DMat3) -> [f64; 6] {
    let a1 = DVec3::new(r6[0], r6[1], r6[2]);
    let a2 = DVec3::new(r6[3], r6[4], r6[5]);
    let n1 = a1.length().max(1e-12);
    let b1 = a1 / n1;
    let u2 = a2 - b1.dot(a2) * b1;
    let n2 = u2.length().max(1e-12);
    let b2 = u2 / n2;
    let (mut gb1, mut gb2, gb3) = (d_rotation.x_axis, d_rotation.y_axis, d_rotation.z_axis);
    // b3 = b1 × b2
    gb1 += b2.cross(gb3);
    gb2 += gb3.cross(b1);
    // b2 = u2 / |u2|
    let gu2 = (gb2 - b2 * b2.dot(gb2)) / n2;
    // u2 = a2 − (b1·a2) b1
    let ga2 = gu2 - b1 * b1.dot(gu2);
    gb1 -= gu2 * b1.dot(a2) + a2 * b1.dot(gu2);
    // b1 = a1 / |a1|
    let ga1 = (gb1 - b1 * b1.dot(gb1)) / n1;
    [ga1.x, ga1.y, ga1.z, ga2.x, ga2.y, ga2.z]
}

/// Test support: `analytic` against central differences of `loss` in each of the nine pose
/// parameters (6D rotation, then translation), within `tol`.
#[cfg(test)]
pub(crate) fn assert_pose_gradient(
    pose: PoseParams,
    analytic: &PoseGrad,
    eps: f64,
    tol: f64,
    loss: impl Fn(&PoseParams) -> f64,
) {
    for k in 0..9 {
        let (mut up, mut down) = (pose, pose);
        if k < 6 {
            up.r6[k] += eps;
            down.r6[k] -= eps;
        } else {
            up.translation_m[k - 6] += eps;
            down.translation_m[k - 6] -= eps;
        }
        let fd = (loss(&up) - loss(&down)) / (2.0 * eps);
        let an = if k < 6 {
            analytic.r6[k]
        } else {
            analytic.translation_m[k - 6]
        };
        assert!((fd - an).abs() < tol, "pose[{k}]: {fd} vs {an} (tol {tol})");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    #[test]
    fn round_trips_a_rigid_transform() {
        let t = Rigid::new(
            DQuat::from_euler(glam::EulerRot::ZYX, 0.3, -0.2, 1.1),
            DVec3::new(1.0, -0.5, 1.8),
        );
        let back = PoseParams::from_rigid(t).to_rigid();
        let (r, d) = t.difference(back);
        assert!(r < 1e-12 && d < 1e-12);
    }

    #[test]
    fn ray_backward_matches_finite_differences() {
        let world_from_vehicle = Rigid::new(
            DQuat::from_euler(glam::EulerRot::ZYX, 0.7, 0.05, -0.02),
            DVec3::new(100.0, -40.0, 2.0),
        );
        let mut pose = PoseParams::from_rigid(Rigid::new(
            DQuat::from_euler(glam::EulerRot::ZYX, -1.2, 0.1, 0.3),
            DVec3::new(0.8, 0.1, 1.7),
        ));
        // Perturb the 6D vector off the exact-rotation manifold, as optimisation does.
        pose.r6[0] *= 1.3;
        pose.r6[4] += 0.2;
        let u = DVec3::new(0.3, -0.8, 0.2).normalize_or_zero();
        let (co, cd) = (DVec3::new(0.4, -1.1, 0.7), DVec3::new(-2.0, 0.5, 1.3));
        let loss = |p: &PoseParams| {
            let (o, d) = p.ray(world_from_vehicle, u);
            co.dot(o) + cd.dot(d)
        };
        let g = pose.ray_backward(world_from_vehicle, u, co, cd);
        let eps = 1e-6;
        for k in 0..6 {
            let mut up = pose;
            up.r6[k] += eps;
            let mut down = pose;
            down.r6[k] -= eps;
            let fd = (loss(&up) - loss(&down)) / (2.0 * eps);
            assert!((fd - g.r6[k]).abs() < 1e-6, "r6[{k}]: {fd} vs {}", g.r6[k]);
        }
        for k in 0..3 {
            let mut up = pose;
            up.translation_m[k] += eps;
            let mut down = pose;
            down.translation_m[k] -= eps;
            let fd = (loss(&up) - loss(&down)) / (2.0 * eps);
            assert!((fd - g.translation_m[k]).abs() < 1e-6, "t[{k}]");
        }
    }
}
