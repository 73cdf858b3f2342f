//! The background model for distant regions (method.md §2 and §15.3): what camera rays see
//! beyond the scene box (far façades, trees, hills) lives in a second, smaller field on
//! inverted-sphere coordinates, sampled 16 times per ray.
//!
//! Around the box's centre `c` with the sphere of radius `R` that encloses the box, a point `x`
//! at `p = x − c`, `r = |p|` maps to `(atan2(p_y, p_x)/2π + ½, asin(p_z/r)/π + ½, R/r)` ∈ \[0,1\]³
//! (the neurad-unisim form of NeRF++'s inverted sphere): direction and disparity, so the
//! infinite outside becomes a bounded cube. A hash grid and an MLP on it give `[s, f]` like the
//! scene field, turned into opacity by the same `α = sigmoid(−β s)`. Samples are uniform in
//! disparity between the sphere and `far_m` (3 km), stratified by a jitter, placed where the
//! ray crosses each radius. Backward: the field's gradient with respect to the unit coordinates
//! is pulled back to `x` by central differences of the (cheap, f64) coordinate map.

use glam::DVec3;

use super::composite::Opacity;
use super::field::{FieldSample, decode_backward, encode_and_decode, samples_backward};
use super::hash_grid::{GradSink, HashGrid, HashGridConfig};
use super::mlp::{Mlp, MlpGrad};

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BackgroundConfig {
    pub grid: HashGridConfig,
    pub hidden: usize,
    /// Samples per ray (method.md §7: 16).
    pub samples: usize,
    pub far_m: f64,
}

impl Default for BackgroundConfig {
    fn default() -> Self {
        Self {
            grid: HashGridConfig {
                levels: 8,
                log2_table_size: 17,
                base_resolution: 8.0,
                max_resolution: 512.0,
            },
            hidden: 32,
            samples: 16,
            far_m: 3000.0,
        }
    }
}

#[derive(Clone, Debug)]
pub struct Background {
    pub centre: DVec3,
    pub radius_m: f64,
    pub grid: HashGrid,
    pub geo: Mlp,
    pub samples: usize,
    pub far_m: f64,
}

impl Background {
    /// The background of a scene box; the SDF output starts at +0.5 m (transparent).
    pub fn new(
        box_min: DVec3,
        box_max: DVec3,
        feature_dim: usize,
        config: &BackgroundConfig,
        seed: u64,
    ) -> Self {
        let grid = HashGrid::new(config.grid.clone(), seed ^ 0xB6);
        let mut geo = Mlp::new(
            &[grid.output_dim(), config.hidden, 1 + feature_dim],
            seed ^ 0xB6B6,
        );
        if let Some(last) = geo.layers.last_mut() {
            last.bias[0] = 0.5;
        }
        Self {
            centre: (box_min + box_max) * 0.5,
            radius_m: ((box_max - box_min).length() * 0.5).max(1.0),
            grid,
            geo,
            samples: config.samples,
            far_m: config.far_m,
        }
    }

    /// Inverted-sphere coordinates of a world point.
    pub fn unit(&self, x: DVec3) -> DVec3 {
        let p = x - self.centre;
        let r = p.length().max(1e-9);
        DVec3::new(
            p.y.atan2(p.x) / std::f64::consts::TAU + 0.5,
            (p.z / r).clamp(-1.0, 1.0).asin() / std::f64::consts::PI + 0.5,
            (self.radius_m / r).min(1.0),
        )
    }

    /// Sample distances along `o + τ d` (d unit): `samples` radii uniform in disparity from the
    /// sphere to `far_m`, each at `(k + jitter)/samples`, where the ray leaves that radius.
    pub fn taus(&self, origin: DVec3, dir: DVec3, jitter: f64) -> Vec<f32> {
        let p = origin - self.centre;
        let (b, c) = (p.dot(dir), p.length_squared());
        let (near, far) = (1.0 / self.radius_m, 1.0 / self.far_m.max(self.radius_m));
        (0..self.samples)
            .filter_map(|k| {
                let u = (k as f64 + jitter) / self.samples as f64;
                let r = 1.0 / (near * (1.0 - u) + far * u);
                let disc = b * b - (c - r * r);
                let tau = -b + disc.max(0.0).sqrt();
                (disc >= 0.0 && tau > 0.0).then_some(tau as f32)
            })
            .collect()
    }

    pub fn query(&self, x: DVec3) -> FieldSample {
        let u = self.unit(x);
        let unit = [u.x as f32, u.y as f32, u.z as f32];
        let mut h = vec![0.0; self.grid.output_dim()];
        self.grid.encode(unit, &mut h);
        FieldSample {
            unit,
            trace: self.geo.forward(&h),
        }
    }

    /// [`Background::query`] at many points, the decoder as one batch.
    pub fn query_many(&self, points: &[DVec3]) -> Vec<FieldSample> {
        let units = points
            .iter()
            .map(|p| {
                let u = self.unit(*p);
                [u.x as f32, u.y as f32, u.z as f32]
            })
            .collect();
        encode_and_decode(&self.grid, &self.geo, units)
    }

    /// Accumulate gradients for one sample at `x` given ∂L/∂s and ∂L/∂f; returns ∂L/∂x,
    /// through the grid's `spatial_levels` coarsest levels (`None`: all).
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        x: DVec3,
        sample: &FieldSample,
        d_sdf: f32,
        d_feature: &[f32],
        grid_grad: &mut impl GradSink,
        mlp_grad: &mut MlpGrad,
        spatial_levels: Option<f32>,
    ) -> DVec3 {
        let mut d_out = Vec::with_capacity(1 + d_feature.len());
        d_out.push(d_sdf);
        d_out.extend_from_slice(d_feature);
        let d_h = self.geo.backward(&sample.trace, &d_out, mlp_grad);
        self.grid_backward(x, sample, &d_h, grid_grad, spatial_levels)
    }

    /// The grid's part of [`Background::backward`], given ∂L/∂(encoding) `d_h`: the table's
    /// gradients, and ∂L/∂x through the inverted-sphere map.
    fn grid_backward(
        &self,
        x: DVec3,
        sample: &FieldSample,
        d_h: &[f32],
        grid_grad: &mut impl GradSink,
        spatial_levels: Option<f32>,
    ) -> DVec3 {
        let g = self
            .grid
            .backward_and_grad_x(sample.unit, d_h, Some(grid_grad), spatial_levels);
        let d_unit = DVec3::new(g[0] as f64, g[1] as f64, g[2] as f64);
        // Jᵀ·d_unit = ∇_x (d_unit · unit(x)), by central differences.
        let h = 1e-6 * (x - self.centre).length().max(1.0);
        let mut d_x = DVec3::ZERO;
        for axis in 0..3 {
            let mut e = DVec3::ZERO;
            e[axis] = h;
            d_x[axis] = d_unit.dot(self.unit(x + e) - self.unit(x - e)) / (2.0 * h);
        }
        d_x
    }

    /// Backward through a ray's background samples given the compositing's `∂L/∂α_i` and
    /// `∂L/∂f_i` (row per sample): returns `(∂L/∂o, ∂L/∂d, ∂L/∂β)`, the first two through the
    /// grid's `spatial_levels` coarsest levels (`None`: all).
    #[allow(clippy::too_many_arguments)]
    pub fn ray_backward(
        &self,
        (origin, dir): (DVec3, DVec3),
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
            |d_out| {
                let d_h = decode_backward(&self.geo, samples, d_out, mlp_grad);
                let width = self.grid.output_dim().max(1);
                samples
                    .iter()
                    .zip(d_h.chunks_exact(width))
                    .zip(taus_m)
                    .map(|((s, d_h), tau)| {
                        let x = origin + dir * *tau as f64;
                        self.grid_backward(x, s, d_h, grid_grad, spatial_levels)
                    })
                    .collect()
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::unical::hash_grid::SparseGrad;

    fn background() -> Background {
        Background::new(
            DVec3::new(-50.0, -40.0, -5.0),
            DVec3::new(70.0, 40.0, 25.0),
            3,
            &BackgroundConfig::default(),
            2,
        )
    }

    #[test]
    fn samples_lie_on_radii_uniform_in_disparity_outside_the_sphere() {
        let bg = background();
        let o = DVec3::new(5.0, 3.0, 1.5);
        let d = DVec3::new(0.8, 0.5, 0.1).normalize_or_zero();
        let taus = bg.taus(o, d, 0.5);
        assert_eq!(taus.len(), 16);
        let mut last_r = bg.radius_m;
        for (k, t) in taus.iter().enumerate() {
            let r = (o + d * *t as f64 - bg.centre).length();
            assert!(r > last_r, "radius {r} after {last_r}");
            let want = 1.0 / bg.radius_m * (1.0 - (k as f64 + 0.5) / 16.0)
                + (k as f64 + 0.5) / 16.0 / 3000.0;
            assert!((1.0 / r - want).abs() < 1e-6 * want.max(1e-6) + 1e-9, "{r}");
            last_r = r;
            let u = bg.unit(o + d * *t as f64);
            assert!((0.0..=1.0).contains(&u.x) && (0.0..=1.0).contains(&u.y));
            assert!((0.0..=1.0).contains(&u.z));
        }
    }

    /// ∂(sdf, feature)/∂x through the inverted-sphere map and the grid, against finite
    /// differences of the field in world coordinates.
    #[test]
    fn spatial_gradient_matches_finite_differences() {
        let mut bg = background();
        for (i, p) in bg.grid.params.iter_mut().enumerate() {
            *p = ((i as f32 * 0.618_034).fract() - 0.5) * 2.0;
        }
        let d_feature = [0.3f32, -0.7, 0.2];
        let value = |x: DVec3| {
            let s = bg.query(x);
            let f = s.feature();
            (1.5 * s.sdf() + f.iter().zip(&d_feature).map(|(a, b)| a * b).sum::<f32>()) as f64
        };
        for x in [
            DVec3::new(150.0, 40.0, 12.0),
            DVec3::new(-300.0, 120.0, 30.0),
            DVec3::new(20.0, -900.0, 80.0),
        ] {
            let s = bg.query(x);
            let (mut g, mut m) = (SparseGrad::default(), bg.geo.zero_grad());
            let an = bg.backward(x, &s, 1.5, &d_feature, &mut g, &mut m, None);
            // A step well inside one grid cell of the finest level at this distance.
            let h = 5e-3 * (x - bg.centre).length() / 100.0;
            for axis in 0..3 {
                let mut e = DVec3::ZERO;
                e[axis] = h;
                let fd = (value(x + e) - value(x - e)) / (2.0 * h);
                assert!(
                    (fd - an[axis]).abs() < 0.02 * an.length() + 1e-5,
                    "{x} axis {axis}: {fd} vs {}",
                    an[axis]
                );
            }
            assert!(an.length() > 1e-6);
        }
    }
}
