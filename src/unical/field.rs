//! The scene field (main Eq. 1): `[s, f] = MLP_geo(h(x))` — signed distance and appearance
//! feature at a world point, from the hash encoding of the point's position in the scene box.
//!
//! World points map to \[0,1\]³ by the scene's axis-aligned box (from the aggregated LiDAR plus a
//! margin, method.md §2), each axis by its own extent; with [`FieldConfig::cubic_box`] all by the
//! largest, so a street scene tens of metres high and hundreds long gets cells as tall as wide. The geometry MLP is the paper's two layers of 64 (`L·F → 64 → 1 + d_f`);
//! its SDF output starts at +`initial_sdf_m` (free space everywhere) so the first renders see
//! through the scene instead of stopping at the first sample.

use glam::DVec3;

use super::composite::Opacity;
use super::hash_grid::{GradSink, HashGrid, HashGridConfig};
use super::mlp::{Mlp, MlpGrad, Trace};

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FieldConfig {
    pub grid: HashGridConfig,
    pub hidden: usize,
    pub feature_dim: usize,
    pub initial_sdf_m: f32,
    /// Map the box to \[0,1\]³ by its largest extent on every axis (cubic cells) instead of each
    /// axis by its own (cells as many times finer vertically as the box is flatter).
    pub cubic_box: bool,
}

impl Default for FieldConfig {
    fn default() -> Self {
        Self {
            grid: HashGridConfig::default(),
            hidden: 64,
            feature_dim: 15,
            initial_sdf_m: 0.5,
            cubic_box: false,
        }
    }
}

#[derive(Clone, Debug)]
pub struct SceneField {
    pub box_min: DVec3,
    pub box_size: DVec3,
    pub grid: HashGrid,
    pub geo: Mlp,
}

/// What a backward pass through the field needs from its forward pass.
#[derive(Clone, Debug)]
pub struct FieldSample {
    pub unit: [f32; 3],
    pub trace: Trace,
}

impl FieldSample {
    pub fn sdf(&self) -> f32 {
        self.trace.output()[0]
    }

    pub fn feature(&self) -> &[f32] {
        &self.trace.output()[1..]
    }
}

impl SceneField {
    pub fn new(box_min: DVec3, box_max: DVec3, config: &FieldConfig, seed: u64) -> Self {
        let grid = HashGrid::new(config.grid.clone(), seed);
        let mut geo = Mlp::new(
            &[grid.output_dim(), config.hidden, 1 + config.feature_dim],
            seed ^ 0x51DF,
        );
        if let Some(last) = geo.layers.last_mut() {
            last.bias[0] = config.initial_sdf_m;
        }
        Self {
            box_min,
            box_size: {
                let size = (box_max - box_min).max(DVec3::splat(1e-6));
                if config.cubic_box {
                    DVec3::splat(size.max_element())
                } else {
                    size
                }
            },
            grid,
            geo,
        }
    }

    /// Position in the unit cube (clamped by the encoding).
    pub fn unit(&self, world: DVec3) -> [f32; 3] {
        let u = (world - self.box_min) / self.box_size;
        [u.x as f32, u.y as f32, u.z as f32]
    }

    /// Evaluate the field at a world point.
    pub fn query(&self, world: DVec3) -> FieldSample {
        let unit = self.unit(world);
        FieldSample {
            unit,
            trace: self
                .geo
                .forward_from(self.grid.output_dim(), |h| self.grid.encode(unit, h)),
        }
    }

    /// Evaluate the field at many world points at once (the MLP as one batch: [`Mlp::forward_many`]).
    pub fn query_many(&self, points: &[DVec3]) -> Vec<FieldSample> {
        let units = points.iter().map(|p| self.unit(*p)).collect();
        encode_and_decode(&self.grid, &self.geo, units)
    }

    /// The field at `o + τ d` for every `τ` of `taus_m` ([`SceneField::query_many`]).
    pub fn query_ray(&self, o: DVec3, d: DVec3, taus_m: &[f32]) -> Vec<FieldSample> {
        let points: Vec<DVec3> = taus_m.iter().map(|t| o + d * *t as f64).collect();
        self.query_many(&points)
    }

    /// [`SceneField::backward_spatial`] of many samples at once: `d_out` holds each sample's
    /// `(∂L/∂s, ∂L/∂f)` as a row; returns each sample's ∂L/∂x (world).
    pub fn backward_many(
        &self,
        samples: &[FieldSample],
        d_out: &[f32],
        grid_grad: &mut impl GradSink,
        mlp_grad: &mut MlpGrad,
        spatial_levels: Option<f32>,
    ) -> Vec<DVec3> {
        let d_h = decode_backward(&self.geo, samples, d_out, mlp_grad);
        let dim = self.grid.output_dim().max(1);
        samples
            .iter()
            .zip(d_h.chunks_exact(dim))
            .map(|(s, d)| {
                let g =
                    self.grid
                        .backward_and_grad_x(s.unit, d, Some(&mut *grid_grad), spatial_levels);
                DVec3::new(g[0] as f64, g[1] as f64, g[2] as f64) / self.box_size
            })
            .collect()
    }

    /// Accumulate gradients for one sample given ∂L/∂s and ∂L/∂f; returns ∂L/∂x (world).
    pub fn backward(
        &self,
        sample: &FieldSample,
        d_sdf: f32,
        d_feature: &[f32],
        grid_grad: &mut impl GradSink,
        mlp_grad: &mut MlpGrad,
    ) -> DVec3 {
        self.backward_spatial(sample, (d_sdf, d_feature), grid_grad, mlp_grad, None)
    }

    /// [`SceneField::backward`] with ∂L/∂x through the grid's `spatial_levels` coarsest levels
    /// only ([`HashGrid::backward_and_grad_x`]; `None`: all of them).
    pub fn backward_spatial(
        &self,
        sample: &FieldSample,
        (d_sdf, d_feature): (f32, &[f32]),
        grid_grad: &mut impl GradSink,
        mlp_grad: &mut MlpGrad,
        spatial_levels: Option<f32>,
    ) -> DVec3 {
        let mut d_out = Vec::with_capacity(1 + d_feature.len());
        d_out.push(d_sdf);
        d_out.extend_from_slice(d_feature);
        let d_h = self.geo.backward(&sample.trace, &d_out, mlp_grad);
        let g = self
            .grid
            .backward_and_grad_x(sample.unit, &d_h, Some(grid_grad), spatial_levels);
        DVec3::new(g[0] as f64, g[1] as f64, g[2] as f64) / self.box_size
    }

    /// Backward through the samples `x_i = o + τ_i d` of one ray, given the compositing's
    /// `(∂L/∂α_i, ∂L/∂f_i)` (features row per sample; empty for depth-only terms): accumulates
    /// the field's gradients and returns `(∂L/∂o, ∂L/∂d, ∂L/∂β)`, the first two through the
    /// grid's `spatial_levels` coarsest levels ([`SceneField::backward_spatial`]; `None`: all).
    #[allow(clippy::too_many_arguments)]
    pub fn ray_backward(
        &self,
        samples: &[FieldSample],
        taus_m: &[f32],
        opacity: Opacity,
        (d_alpha, d_features): (&[f32], &[f32]),
        grid_grad: &mut impl GradSink,
        mlp_grad: &mut MlpGrad,
        spatial_levels: Option<f32>,
    ) -> (DVec3, DVec3, f64) {
        let dim = self.geo.output_dim().saturating_sub(1);
        samples_backward(
            samples,
            taus_m,
            opacity,
            (d_alpha, d_features),
            dim,
            |d_out| self.backward_many(samples, d_out, grid_grad, mlp_grad, spatial_levels),
        )
    }
}

/// Encode points already in the unit cube and run the decoder on all of them as one batch.
pub(crate) fn encode_and_decode(
    grid: &HashGrid,
    geo: &Mlp,
    units: Vec<[f32; 3]>,
) -> Vec<FieldSample> {
    let dim = grid.output_dim();
    let mut inputs = vec![0.0; units.len() * dim];
    for (u, h) in units.iter().zip(inputs.chunks_exact_mut(dim.max(1))) {
        grid.encode(*u, h);
    }
    let traces = geo.forward_many(units.len(), &inputs);
    units
        .into_iter()
        .zip(traces)
        .map(|(unit, trace)| FieldSample { unit, trace })
        .collect()
}

/// The decoder's part of a batch's backward pass ([`encode_and_decode`]'s second half, reversed):
/// `d_out` holds each sample's ∂L/∂(decoder output) as a row; accumulates the decoder's gradients
/// and returns each sample's ∂L/∂(encoding), row by row.
pub(crate) fn decode_backward(
    geo: &Mlp,
    samples: &[FieldSample],
    d_out: &[f32],
    mlp_grad: &mut MlpGrad,
) -> Vec<f32> {
    let traces: Vec<&Trace> = samples.iter().map(|s| &s.trace).collect();
    geo.backward_many(&traces, d_out, mlp_grad)
}

/// The part of a ray's backward pass every field shares: `∂L/∂s_i` from `∂L/∂α` through the
/// opacity model, each sample's `(∂L/∂s_i, ∂L/∂f_i)` as a row of one matrix, then
/// `points_backward(rows)`, which returns every `∂L/∂x_i`; sums `(∂L/∂o, ∂L/∂d, ∂L/∂β)` over
/// `x_i = o + τ_i d`.
pub fn samples_backward(
    samples: &[FieldSample],
    taus_m: &[f32],
    opacity: Opacity,
    (d_alpha, d_features): (&[f32], &[f32]),
    feature_dim: usize,
    points_backward: impl FnOnce(&[f32]) -> Vec<DVec3>,
) -> (DVec3, DVec3, f64) {
    let sdfs: Vec<f32> = samples.iter().map(|s| s.sdf()).collect();
    let (d_sdf, d_beta) = opacity.backward(&sdfs, d_alpha);
    let width = 1 + feature_dim;
    let mut d_out = vec![0.0; samples.len() * width];
    for (i, row) in d_out.chunks_exact_mut(width).enumerate() {
        row[0] = d_sdf[i];
        if let Some(d_f) = d_features.get(i * feature_dim..(i + 1) * feature_dim) {
            row[1..].copy_from_slice(d_f);
        }
    }
    let d_x = points_backward(&d_out);
    let (mut d_o, mut d_d) = (DVec3::ZERO, DVec3::ZERO);
    for (d_x, tau) in d_x.iter().zip(taus_m) {
        d_o += *d_x;
        d_d += *d_x * *tau as f64;
    }
    (d_o, d_d, d_beta)
}

/// The field configuration of gradient tests: 4 levels of 2^12 up to 32 cells, 16 hidden.
#[cfg(test)]
pub(crate) fn tiny_config(feature_dim: usize) -> FieldConfig {
    FieldConfig {
        grid: HashGridConfig {
            levels: 4,
            log2_table_size: 12,
            base_resolution: 4.0,
            max_resolution: 32.0,
        },
        hidden: 16,
        feature_dim,
        initial_sdf_m: 0.2,
        cubic_box: false,
    }
}

/// A [`tiny_config`] field in the box ±`half_size_m` with large pseudo-random table values (so
/// the SDF varies in space).
#[cfg(test)]
pub(crate) fn tiny_field(feature_dim: usize, amplitude: f32, half_size_m: f64) -> SceneField {
    let config = tiny_config(feature_dim);
    let (lo, hi) = (DVec3::splat(-half_size_m), DVec3::splat(half_size_m));
    let mut field = SceneField::new(lo, hi, &config, 5);
    for (i, p) in field.grid.params.iter_mut().enumerate() {
        *p = ((i as f32 * 0.7548).fract() - 0.5) * amplitude;
    }
    field
}

#[cfg(test)]
mod tests {
    use super::super::adam::{AdamConfig, DenseAdam, SparseAdam};
    use super::super::composite::{Upstream, alpha_from_sdf, composite, composite_backward};
    use super::*;
    use crate::unical::hash_grid::SparseGrad;

    fn flat(g: &MlpGrad) -> Vec<f32> {
        g.weights
            .iter()
            .zip(&g.bias)
            .flat_map(|(w, b)| w.iter().chain(b.iter()).copied())
            .collect()
    }

    fn set_flat(m: &mut Mlp, p: &[f32]) {
        let mut k = 0;
        for l in &mut m.layers {
            let (weights, bias) = l.params_mut();
            for v in weights.iter_mut().chain(bias.iter_mut()) {
                *v = p[k];
                k += 1;
            }
        }
    }

    fn get_flat(m: &Mlp) -> Vec<f32> {
        m.layers
            .iter()
            .flat_map(|l| l.weights().iter().chain(l.bias.iter()).copied())
            .collect()
    }

    #[test]
    fn a_cubic_box_maps_every_axis_by_the_largest_extent() {
        let (lo, hi) = (DVec3::new(-50.0, 0.0, -2.0), DVec3::new(50.0, 40.0, 8.0));
        let corner = DVec3::new(50.0, 40.0, 8.0);
        let per_axis = SceneField::new(lo, hi, &tiny_config(3), 1);
        assert_eq!(per_axis.unit(corner), [1.0, 1.0, 1.0]);
        let mut cubic = SceneField::new(
            lo,
            hi,
            &FieldConfig {
                cubic_box: true,
                ..tiny_config(3)
            },
            1,
        );
        for (i, p) in cubic.grid.params.iter_mut().enumerate() {
            *p = ((i as f32 * 0.7548).fract() - 0.5) * 2.0;
        }
        assert_eq!(cubic.box_size, DVec3::splat(100.0));
        assert_eq!(cubic.unit(corner), [1.0, 0.4, 0.1]);
        assert_eq!(cubic.unit(lo), [0.0, 0.0, 0.0]);
        // The spatial gradient is in world units either way: the same scale on every axis.
        let sample = cubic.query(DVec3::new(3.0, 7.0, 1.0));
        let mut grad = cubic.geo.zero_grad();
        let g = cubic.backward(
            &sample,
            1.0,
            &[0.0; 3],
            &mut SparseGrad::default(),
            &mut grad,
        );
        let h = 1e-2;
        let sdf = |p: DVec3| cubic.query(p).sdf() as f64;
        let p = DVec3::new(3.0, 7.0, 1.0);
        let fd = DVec3::new(
            sdf(p + DVec3::X * h) - sdf(p - DVec3::X * h),
            sdf(p + DVec3::Y * h) - sdf(p - DVec3::Y * h),
            sdf(p + DVec3::Z * h) - sdf(p - DVec3::Z * h),
        ) / (2.0 * h);
        assert!(fd.length() > 1e-3, "{fd}");
        assert!((g - fd).length() <= 0.05 * fd.length(), "{g} {fd}");
    }

    /// Depth-only fit of a ground plane (z = 0) seen by a LiDAR 2 m above it: the rendered
    /// range error must drop by an order of magnitude. Exercises encoding, MLP, compositing and
    /// both Adams together.
    #[test]
    fn learns_a_ground_plane_from_lidar_depth() {
        let config = FieldConfig {
            grid: HashGridConfig {
                levels: 8,
                log2_table_size: 14,
                base_resolution: 8.0,
                max_resolution: 128.0,
            },
            hidden: 32,
            feature_dim: 3,
            initial_sdf_m: 0.5,
            cubic_box: false,
        };
        let mut field = SceneField::new(
            DVec3::new(-10.0, -10.0, -1.0),
            DVec3::new(10.0, 10.0, 3.0),
            &config,
            1,
        );
        let origin = DVec3::new(0.0, 0.0, 2.0);
        let beta = 20.0;
        let mut grid_opt = SparseAdam::new(field.grid.params.len(), AdamConfig::NGP);
        let mut mlp_params = get_flat(&field.geo);
        let mut mlp_opt = DenseAdam::new(mlp_params.len(), AdamConfig::NGP);
        let rays: Vec<(DVec3, f32)> = (0..48)
            .map(|i| {
                let az = i as f64 * 0.37;
                let el = -0.35 - 0.4 * ((i * 7 % 13) as f64 / 13.0);
                let d = DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
                (d, (2.0 / -el.sin()) as f32)
            })
            .collect();
        let taus: Vec<f32> = (1..=50).map(|k| k as f32 * 0.15).collect();
        let mut errors = Vec::new();
        for _ in 0..80 {
            let mut grid_grad = SparseGrad::default();
            let mut mlp_grad = field.geo.zero_grad();
            let mut err = 0.0;
            for (d, target) in &rays {
                let samples: Vec<FieldSample> = taus
                    .iter()
                    .map(|t| field.query(origin + *d * *t as f64))
                    .collect();
                let alphas: Vec<f32> = samples
                    .iter()
                    .map(|s| alpha_from_sdf(s.sdf(), beta).0)
                    .collect();
                let c = composite(&alphas, &taus, &[], 0);
                let r = c.depth_m - target;
                err += r.abs();
                let up = Upstream {
                    depth: 2.0 * r / rays.len() as f32,
                    ..Upstream::default()
                };
                let (d_alpha, _) = composite_backward(&alphas, &taus, &[], 0, &c, &up);
                for (s, da) in samples.iter().zip(&d_alpha) {
                    let (_, da_ds, _) = alpha_from_sdf(s.sdf(), beta);
                    let zeros = vec![0.0; 3];
                    field.backward(s, da * da_ds, &zeros, &mut grid_grad, &mut mlp_grad);
                }
            }
            errors.push(err / rays.len() as f32);
            grid_grad.merge();
            grid_opt.step(&mut field.grid.params, &grid_grad, 0.01);
            mlp_opt.step(&mut mlp_params, &flat(&mlp_grad), 0.01);
            set_flat(&mut field.geo, &mlp_params);
        }
        let (first, last) = (errors[0], errors[errors.len() - 1]);
        assert!(
            last < 0.1 * first && last < 0.3,
            "mean range error {first} m -> {last} m"
        );
    }
}
