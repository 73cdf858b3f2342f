//! The LiDAR intensity decoder (main Eq. 5, method.md §6) and the per-LiDAR intensity mapping
//! (§4: the analogue of a camera's exposure).
//!
//! `Î = a_s · sigmoid(D_lidar(F, SH(d))) + b_s`: the decoder is the paper's 3-layer, 64-wide MLP
//! on the rendered feature `F = Σ w_i f_i` and the degree-3 spherical-harmonics encoding of the
//! ray direction, shared by every LiDAR; `(a_s, b_s)` (init 1, 0) absorb each sensor's own
//! intensity scale. Targets are the sensor's intensities normalised to [0, 1] (see
//! [`normaliser`]).

use super::camera_rgb::{SH_DIM, sigmoid};
use super::mlp::{Mlp, MlpGrad, Trace};

/// The shared intensity decoder.
#[derive(Clone, Debug)]
pub struct IntensityDecoder {
    pub mlp: Mlp,
}

impl IntensityDecoder {
    pub fn new(feature_dim: usize, seed: u64) -> Self {
        Self {
            mlp: Mlp::new(&[feature_dim + SH_DIM, 64, 64, 1], seed ^ 0x1A7),
        }
    }

    /// `sigmoid(D_lidar(F, SH))` and the trace its backward pass needs.
    pub fn forward(&self, feature: &[f32], sh: &[f32]) -> (f32, Trace) {
        let mut input = Vec::with_capacity(feature.len() + sh.len());
        input.extend_from_slice(feature);
        input.extend_from_slice(sh);
        let trace = self.mlp.forward(&input);
        (sigmoid(trace.output()[0]), trace)
    }

    /// Given `∂L/∂(sigmoid output)`: accumulates the decoder's gradient and returns
    /// `(∂L/∂F, ∂L/∂SH)`.
    pub fn backward(
        &self,
        trace: &Trace,
        value: f32,
        d_value: f32,
        grad: &mut MlpGrad,
    ) -> (Vec<f32>, Vec<f32>) {
        let d_logit = d_value * value * (1.0 - value);
        let mut d_input = self.mlp.backward(trace, &[d_logit], grad);
        let d_sh = d_input.split_off(d_input.len().saturating_sub(SH_DIM));
        (d_input, d_sh)
    }
}

/// Per-LiDAR affine intensity mapping `Î = scale · I + offset`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntensityMap {
    pub scale: f32,
    pub offset: f32,
}

impl Default for IntensityMap {
    fn default() -> Self {
        Self {
            scale: 1.0,
            offset: 0.0,
        }
    }
}

/// The factor that maps a sensor's raw intensities to [0, 1]: one over their 99th percentile
/// (a few specular returns should not squash the rest), or `None` when the sensor reports no
/// usable intensity (absent or all zero).
pub fn normaliser<'a>(intensities: impl Iterator<Item = &'a f32>) -> Option<f32> {
    let mut v: Vec<f32> = intensities
        .copied()
        .filter(|x| x.is_finite() && *x > 0.0)
        .collect();
    if v.is_empty() {
        return None;
    }
    let k = ((v.len() - 1) as f64 * 0.99) as usize;
    let (_, p99, _) = v.select_nth_unstable_by(k, f32::total_cmp);
    (*p99 > 0.0).then(|| 1.0 / *p99)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normaliser_maps_the_99th_percentile_to_one() {
        let raw: Vec<f32> = (1..=1000).map(|v| v as f32 * 0.255).collect();
        let k = normaliser(raw.iter()).unwrap();
        assert!((raw[989] * k - 1.0).abs() < 2e-3, "{}", raw[989] * k);
        assert_eq!(normaliser([0.0f32, 0.0].iter()), None);
        assert_eq!(normaliser([].iter()), None);
        assert_eq!(normaliser([f32::NAN].iter()), None);
    }

    #[test]
    fn decoder_backward_matches_finite_differences() {
        let dec = IntensityDecoder::new(3, 4);
        let feature = [0.3f32, -0.8, 0.5];
        let sh: Vec<f32> = (0..SH_DIM).map(|k| (k as f32 * 0.7).sin() * 0.4).collect();
        let (v, trace) = dec.forward(&feature, &sh);
        let mut grad = dec.mlp.zero_grad();
        let (d_f, d_sh) = dec.backward(&trace, v, 1.0, &mut grad);
        assert_eq!((d_f.len(), d_sh.len()), (3, SH_DIM));
        let eps = 1e-3;
        for k in 0..3 {
            let (mut up, mut down) = (feature, feature);
            up[k] += eps;
            down[k] -= eps;
            let fd = (dec.forward(&up, &sh).0 - dec.forward(&down, &sh).0) / (2.0 * eps);
            assert!(
                (fd - d_f[k]).abs() < 1e-3 + 0.02 * fd.abs(),
                "{fd} vs {}",
                d_f[k]
            );
        }
        for k in [0, 5, 15] {
            let (mut up, mut down) = (sh.clone(), sh.clone());
            up[k] += eps;
            down[k] -= eps;
            let fd = (dec.forward(&feature, &up).0 - dec.forward(&feature, &down).0) / (2.0 * eps);
            assert!(
                (fd - d_sh[k]).abs() < 1e-3 + 0.02 * fd.abs(),
                "{fd} vs {}",
                d_sh[k]
            );
        }
    }
}
