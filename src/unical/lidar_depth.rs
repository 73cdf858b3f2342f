//! The LiDAR depth term (main Eq. 5, method.md §6 and §8) for a batch of rays, with gradients
//! for the scene and for the LiDAR's pose.
//!
//! A ray is a return `p` of sensor s fired at time t: `o = P(t)·t_s`, `d = R_P R_s p/|p|` (rolling
//! shutter: P is the trajectory at each return's own time, §5), target range `|p|`. The field is
//! sampled at `x_i = o + τ_i d` (τ from the occupancy grid), composited to a range D, and the loss
//! is the mean of `(D − |p|)²`. Backward: composite → SDF → field (sparse grid + MLP gradients,
//! and ∂L/∂x_i from the encoding's spatial gradient) → ∂L/∂o = Σ∂L/∂x_i, ∂L/∂d = Σ τ_i ∂L/∂x_i →
//! pose parameters.

use glam::DVec3;

use super::composite::{alpha_from_sdf, composite, composite_backward};
use super::field::SceneField;
use super::hash_grid::SparseGrad;
use super::mlp::MlpGrad;
use super::pose::{PoseGrad, PoseParams};
use crate::geometry::Rigid;

/// One LiDAR ray ready to render.
#[derive(Clone, Debug)]
pub struct DepthRay {
    /// `world_from_vehicle` at the return's firing time.
    pub world_from_vehicle: Rigid,
    /// Unit direction in the sensor frame.
    pub dir_in_sensor: DVec3,
    pub range_m: f32,
    /// Sample distances along the ray.
    pub taus_m: Vec<f32>,
}

/// Loss and gradients of one batch.
#[derive(Debug)]
pub struct DepthStep {
    pub loss: f64,
    pub mean_abs_error_m: f64,
    /// Unmerged: repeated entries are summed by the caller (see `GradAccumulator`).
    pub grid: SparseGrad,
    pub mlp: MlpGrad,
    pub beta_grad: f64,
    pub pose: PoseGrad,
}

/// Mean squared range error of `rays` seen from `pose` and its gradients.
pub fn depth_step(
    field: &SceneField,
    beta: f32,
    pose: &PoseParams,
    rays: &[DepthRay],
) -> DepthStep {
    let mut out = DepthStep {
        loss: 0.0,
        mean_abs_error_m: 0.0,
        grid: SparseGrad::default(),
        mlp: field.geo.zero_grad(),
        beta_grad: 0.0,
        pose: PoseGrad::default(),
    };
    let n = rays.len().max(1) as f64;
    for ray in rays {
        if ray.taus_m.is_empty() {
            continue;
        }
        let (o, d) = pose.ray(ray.world_from_vehicle, ray.dir_in_sensor);
        let samples: Vec<_> = ray
            .taus_m
            .iter()
            .map(|t| field.query(o + d * *t as f64))
            .collect();
        let alphas: Vec<f32> = samples
            .iter()
            .map(|s| alpha_from_sdf(s.sdf(), beta).0)
            .collect();
        let c = composite(&alphas, &ray.taus_m, &[], 0);
        let r = (c.depth_m - ray.range_m) as f64;
        out.loss += r * r / n;
        out.mean_abs_error_m += r.abs() / n;
        let upstream = composite_backward(
            &alphas,
            &ray.taus_m,
            &[],
            0,
            &c,
            (2.0 * r / n) as f32,
            0.0,
            &[],
        );
        let (d_o, d_d, d_beta) = field.ray_backward(
            &samples,
            &ray.taus_m,
            beta,
            &upstream,
            &mut out.grid,
            &mut out.mlp,
        );
        out.beta_grad += d_beta;
        out.pose
            .add(&pose.ray_backward(ray.world_from_vehicle, ray.dir_in_sensor, d_o, d_d));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::field::FieldConfig;
    use super::super::hash_grid::HashGridConfig;
    use super::*;
    use glam::DQuat;

    /// End-to-end check of the whole chain (field, compositing, rolling-shutter ray, 6D pose)
    /// against finite differences of the loss in the pose parameters.
    #[test]
    fn pose_gradient_matches_finite_differences() {
        let config = FieldConfig {
            grid: HashGridConfig {
                levels: 4,
                log2_table_size: 12,
                base_resolution: 4.0,
                max_resolution: 32.0,
            },
            hidden: 16,
            feature_dim: 2,
            initial_sdf_m: 0.2,
        };
        let mut field = SceneField::new(DVec3::splat(-20.0), DVec3::splat(20.0), &config, 5);
        // A non-trivial field: large table values so the SDF varies in space.
        for (i, p) in field.grid.params.iter_mut().enumerate() {
            *p = ((i as f32 * 0.7548).fract() - 0.5) * 4.0;
        }
        let pose = PoseParams::from_rigid(Rigid::new(
            DQuat::from_euler(glam::EulerRot::ZYX, 0.2, 0.05, -0.03),
            DVec3::new(0.9, 0.1, 1.8),
        ));
        let rays: Vec<DepthRay> = (0..6)
            .map(|i| DepthRay {
                world_from_vehicle: Rigid::new(
                    DQuat::from_rotation_z(0.1 * i as f64),
                    DVec3::new(2.0 + i as f64 * 0.3, 1.0, 0.0),
                ),
                dir_in_sensor: DVec3::new(1.0, 0.2 * i as f64 - 0.5, -0.3).normalize_or_zero(),
                range_m: 6.0,
                taus_m: (1..40).map(|k| k as f32 * 0.2).collect(),
            })
            .collect();
        let beta = 3.0;
        let step = depth_step(&field, beta, &pose, &rays);
        assert!(step.loss > 0.0);
        let loss = |p: &PoseParams| depth_step(&field, beta, p, &rays).loss;
        // f32 fields make the finite differences noisy at the 1e-3 level of the loss: compare
        // each component against 1 % of the whole gradient's size.
        let eps = 1e-3;
        let norm = step.pose.r6.iter().map(|g| g * g).sum::<f64>().sqrt()
            + step.pose.translation_m.length();
        let tol = 0.01 * norm;
        for k in 0..6 {
            let (mut up, mut down) = (pose, pose);
            up.r6[k] += eps;
            down.r6[k] -= eps;
            let fd = (loss(&up) - loss(&down)) / (2.0 * eps);
            let an = step.pose.r6[k];
            assert!(
                (fd - an).abs() < tol,
                "r6[{k}]: {fd} vs {an} (tolerance {tol})"
            );
        }
        for k in 0..3 {
            let (mut up, mut down) = (pose, pose);
            up.translation_m[k] += eps;
            down.translation_m[k] -= eps;
            let fd = (loss(&up) - loss(&down)) / (2.0 * eps);
            let an = step.pose.translation_m[k];
            assert!(
                (fd - an).abs() < tol,
                "t[{k}]: {fd} vs {an} (tolerance {tol})"
            );
        }
        assert!(norm > 1e-2, "gradient too small to test: {norm}");
        let fd = (depth_step(&field, beta + 1e-3, &pose, &rays).loss
            - depth_step(&field, beta - 1e-3, &pose, &rays).loss)
            / 2e-3;
        assert!((fd - step.beta_grad).abs() < 2e-2 * (fd.abs() + step.beta_grad.abs()) + 1e-3);
    }
}
