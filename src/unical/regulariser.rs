//! The SDF regulariser `L_reg` (method.md §8), evaluated along LiDAR rays whose true range
//! `D_gt` is known:
//!
//! `L_reg = (1/N) Σ_r [ Σ_{i: |τ_i − D_gt| < ε} (‖∇s(x_i)‖ − 1)²  +  Σ_{i: |τ_i − D_gt| ≥ ε} w_i² ]`
//!
//! The Eikonal part keeps the field a distance function near the surface; the weight part
//! suppresses rendering weight away from it (free space and behind the hit). ε = 10 cm.
//!
//! `∇s` comes from the tetrahedral stencil: with `v_k ∈ {(1,−1,−1), (−1,−1,1), (−1,1,−1),
//! (1,1,1)}` (Σ v_k = 0, Σ v_k v_kᵀ = 4I), `g = Σ_k v_k s(x + δ v_k) / (4δ)` is exact for linear
//! fields and needs only four forward passes. Its gradient is the same four samples' backward
//! passes with `∂L/∂s_k = 2(‖g‖ − 1) (ĝ · v_k) / (4δ)`. The regulariser shapes the scene only:
//! no gradient reaches the poses (the data terms move the sensors).

use glam::DVec3;

use super::field::SceneField;
use super::hash_grid::GradSink;
use super::mlp::MlpGrad;

/// Half-width of the band around a LiDAR hit where the Eikonal term applies (method.md §8).
pub const NEAR_HIT_M: f32 = 0.1;
/// Finite-difference step of the stencil.
pub const STENCIL_M: f64 = 0.01;

const TETRAHEDRON: [DVec3; 4] = [
    DVec3::new(1.0, -1.0, -1.0),
    DVec3::new(-1.0, -1.0, 1.0),
    DVec3::new(-1.0, 1.0, -1.0),
    DVec3::new(1.0, 1.0, 1.0),
];

/// The gradient from the SDF at the four stencil points `x + δ v_k`.
fn stencil_gradient(sdf: [f64; 4]) -> DVec3 {
    gradient_at_step(sdf, STENCIL_M)
}

fn gradient_at_step(sdf: [f64; 4], step_m: f64) -> DVec3 {
    TETRAHEDRON
        .iter()
        .zip(sdf)
        .map(|(v, s)| *v * s)
        .sum::<DVec3>()
        / (4.0 * step_m)
}

/// The SDF's gradient at `x` by the tetrahedral stencil at a wide `step_m`: a surface normal
/// averaged over the stencil. The exact spatial gradient of a hash-grid field varies from one
/// finest cell to the next; on a simulated street scene its direction is a median 49° off the
/// true surface normal, against 9° for a 10 cm stencil and 6.5° for 20 cm (docs/experiments/unical-lidar-terms.md).
pub fn smoothed_gradient(field: &SceneField, x: DVec3, step_m: f64) -> DVec3 {
    let samples = field.query_many(&TETRAHEDRON.map(|v| x + v * step_m));
    gradient_at_step(std::array::from_fn(|k| samples[k].sdf() as f64), step_m)
}

/// The Eikonal penalty `(‖∇s(x)‖ − 1)²` at `x`; when `weight` is non-zero, accumulates
/// `weight ×` its gradient into the field's gradients.
pub fn eikonal(
    field: &SceneField,
    x: DVec3,
    weight: f32,
    grid_grad: &mut impl GradSink,
    mlp_grad: &mut MlpGrad,
) -> f64 {
    eikonal_many(field, &[x], weight, grid_grad, mlp_grad)
}

/// [`eikonal`] summed over the points `xs`, their stencils' samples evaluated as one batch.
pub fn eikonal_many(
    field: &SceneField,
    xs: &[DVec3],
    weight: f32,
    grid_grad: &mut impl GradSink,
    mlp_grad: &mut MlpGrad,
) -> f64 {
    if xs.is_empty() {
        return 0.0;
    }
    let points: Vec<DVec3> = xs
        .iter()
        .flat_map(|x| TETRAHEDRON.map(|v| *x + v * STENCIL_M))
        .collect();
    let samples = field.query_many(&points);
    let width = field.geo.output_dim().max(1);
    let mut d_out = vec![0.0; samples.len() * width];
    let mut loss = 0.0;
    for (stencil, d_rows) in samples
        .chunks_exact(4)
        .zip(d_out.chunks_exact_mut(4 * width))
    {
        let g = stencil_gradient(std::array::from_fn(|k| stencil[k].sdf() as f64));
        let norm = g.length();
        loss += (norm - 1.0) * (norm - 1.0);
        if weight != 0.0 && norm > 1e-9 {
            let d_g = g * (2.0 * (norm - 1.0) / norm);
            for (v, row) in TETRAHEDRON.iter().zip(d_rows.chunks_exact_mut(width)) {
                row[0] = (weight as f64 * d_g.dot(*v) / (4.0 * STENCIL_M)) as f32;
            }
        }
    }
    if weight != 0.0 {
        field.backward_many(&samples, &d_out, grid_grad, mlp_grad, None);
    }
    loss
}

/// Per-sample `∂(Σ_{far} w_i²)/∂w_i` (times `weight`) for a ray with true range `range_m`, and
/// the penalty itself. Samples within [`NEAR_HIT_M`] of the hit are the Eikonal term's.
pub fn weight_suppression(
    weights: &[f32],
    taus_m: &[f32],
    range_m: f32,
    weight: f32,
) -> (f64, Vec<f32>) {
    let mut loss = 0.0;
    let d_w = weights
        .iter()
        .zip(taus_m)
        .map(|(w, t)| {
            if (t - range_m).abs() < NEAR_HIT_M {
                0.0
            } else {
                loss += (w * w) as f64;
                2.0 * w * weight
            }
        })
        .collect();
    (loss, d_w)
}

/// How far in front of a return free space is claimed by a LiDAR whose pose may still be off
/// (registration phase): 1 m plus 5 % of the range, more than a 2° / 20 cm error moves a
/// surface along the ray at street ranges.
pub fn free_space_margin_m(range_m: f32) -> f32 {
    1.0 + 0.05 * range_m
}

/// Per-sample `∂(Σ w_i²)/∂w_i` (times `weight`) over the samples clearly in front of the return
/// (τ < range − [`free_space_margin_m`]), and the penalty: free space without any surface
/// placement, robust to a small error in the ray's pose.
pub fn free_space_suppression(
    weights: &[f32],
    taus_m: &[f32],
    range_m: f32,
    weight: f32,
) -> (f64, Vec<f32>) {
    let until = range_m - free_space_margin_m(range_m);
    let mut loss = 0.0;
    let d_w = weights
        .iter()
        .zip(taus_m)
        .map(|(w, t)| {
            if *t < until {
                loss += (w * w) as f64;
                2.0 * w * weight
            } else {
                0.0
            }
        })
        .collect();
    (loss, d_w)
}

#[cfg(test)]
mod tests {
    use super::super::field::tiny_config;
    use super::*;
    use crate::unical::hash_grid::SparseGrad;

    /// A tiny field with its own table pattern: the Eikonal check differentiates a 1 cm
    /// stencil, so it needs a field without ReLU or cell kinks near its points.
    fn field() -> SceneField {
        let (lo, hi) = (DVec3::splat(-10.0), DVec3::splat(10.0));
        let mut field = SceneField::new(lo, hi, &tiny_config(2), 3);
        for (i, p) in field.grid.params.iter_mut().enumerate() {
            *p = ((i as f32 * 0.618_034).fract() - 0.5) * 2.0;
        }
        field
    }

    #[test]
    fn the_stencil_recovers_a_distance_functions_unit_gradient() {
        // A sphere of radius 3 m: ∇s = x/|x|, so the Eikonal penalty vanishes.
        let sdf = |p: DVec3| p.length() - 3.0;
        for x in [DVec3::new(1.0, 2.0, 3.0), DVec3::new(-4.0, 0.5, 0.2)] {
            let g = stencil_gradient(TETRAHEDRON.map(|v| sdf(x + v * STENCIL_M)));
            // First-order accurate: the error is δ times the SDF's curvature (1/r).
            assert!(
                (g - x / x.length()).length() < 2.0 * STENCIL_M / x.length(),
                "{g}"
            );
        }
        // A plane with slope 2: the penalty is (2 − 1)².
        let g = stencil_gradient(TETRAHEDRON.map(|v| 2.0 * (v.z * STENCIL_M)));
        assert!((g.length() - 2.0).abs() < 1e-9);
    }

    /// ∂L_eik/∂θ against finite differences in the geometry MLP's parameters.
    #[test]
    fn eikonal_gradient_matches_finite_differences() {
        let f = field();
        let points: Vec<DVec3> = (0..5)
            .map(|i| DVec3::new(0.7 * i as f64 - 1.0, 0.3 * i as f64, 1.1 - 0.2 * i as f64))
            .collect();
        let total = |f: &SceneField| -> f64 {
            let (mut g, mut m) = (SparseGrad::default(), f.geo.zero_grad());
            points
                .iter()
                .map(|x| eikonal(f, *x, 0.0, &mut g, &mut m))
                .sum()
        };
        let (mut grid_grad, mut mlp_grad) = (SparseGrad::default(), f.geo.zero_grad());
        let loss: f64 = points
            .iter()
            .map(|x| eikonal(&f, *x, 1.0, &mut grid_grad, &mut mlp_grad))
            .sum();
        assert!(loss > 0.0);
        let eps = 1e-3;
        let mut checked = 0;
        for layer in 0..f.geo.layers.len() {
            // The largest gradients of the layer (many hidden units are dead here) and one
            // that should be zero.
            let mut order: Vec<usize> = (0..mlp_grad.weights[layer].len()).collect();
            order.sort_by(|a, b| {
                let g = &mlp_grad.weights[layer];
                g[*b].abs().total_cmp(&g[*a].abs())
            });
            for &k in order.iter().take(4).chain(order.last()) {
                let an = mlp_grad.weights[layer][k] as f64;
                let (mut up, mut down) = (f.clone(), f.clone());
                up.geo.layers[layer].weights_mut()[k] += eps;
                down.geo.layers[layer].weights_mut()[k] -= eps;
                let fd = (total(&up) - total(&down)) / (2.0 * eps as f64);
                assert!(
                    (fd - an).abs() < 0.02 * (fd.abs() + an.abs()) + 1e-3,
                    "layer {layer} weight {k}: {fd} vs {an}"
                );
                checked += usize::from(an.abs() > 1e-2);
            }
        }
        assert!(checked >= 2, "too few non-zero gradients to test");
        // And the hash table: every touched entry's gradient against finite differences.
        grid_grad.merge();
        let mut touched = 0;
        for (entry, an) in grid_grad.entries.iter().take(20) {
            for (c, an) in an.iter().enumerate() {
                let index = *entry as usize * super::super::hash_grid::F + c;
                let (mut up, mut down) = (f.clone(), f.clone());
                up.grid.params[index] += eps;
                down.grid.params[index] -= eps;
                let fd = (total(&up) - total(&down)) / (2.0 * eps as f64);
                let an = *an as f64;
                // f32 SDF differences over a 1 cm stencil: ~1e-3 of finite-difference noise.
                assert!(
                    (fd - an).abs() < 0.02 * (fd.abs() + an.abs()) + 2e-3,
                    "entry {entry}.{c}: {fd} vs {an}"
                );
                touched += 1;
            }
        }
        assert!(touched > 0);
    }

    #[test]
    fn free_space_suppression_claims_only_what_lies_well_in_front() {
        let taus: Vec<f32> = (0..100).map(|k| k as f32 * 0.2).collect();
        let weights = vec![0.1f32; taus.len()];
        let (loss, d_w) = free_space_suppression(&weights, &taus, 18.0, 0.5);
        // In front of 18 − 1.9 m: 81 samples (0 … 16.0 m).
        let claimed = d_w.iter().filter(|g| **g != 0.0).count();
        assert_eq!(claimed, 81);
        assert!(
            d_w.iter()
                .zip(&taus)
                .all(|(g, t)| (*g != 0.0) == (*t < 16.1))
        );
        assert!((loss - 81.0 * 0.01).abs() < 1e-6 && (d_w[0] - 0.1).abs() < 1e-7);
    }

    #[test]
    fn weight_suppression_spares_the_band_around_the_hit() {
        let taus = [4.8, 4.95, 5.05, 5.2];
        let weights = [0.1, 0.4, 0.4, 0.1];
        let (loss, d_w) = weight_suppression(&weights, &taus, 5.0, 0.5);
        assert!((loss - 0.02).abs() < 1e-6);
        assert_eq!(d_w, vec![0.1, 0.0, 0.0, 0.1]);
    }
}
