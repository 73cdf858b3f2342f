//! Volume rendering along one ray (method.md §3, main Eq. 2) and its backward pass.
//!
//! Per sample i: opacity `α_i = sigmoid(−β·s_i)` from the signed distance s_i (β > 0 learnable,
//! 1/m), transmittance `T_i = Π_{j<i}(1 − α_j)`, weight `w_i = T_i·α_i`. A ray renders its
//! expected range `D = Σ w_i τ_i` (Eq. 5), accumulated opacity `A = Σ w_i` and feature
//! `F = Σ w_i f_i` (feature rendering: decoders then run once per ray, §4(a)). [`Opacity`]
//! also offers NeuS's per-section opacity, whose weights sit at the sections' midpoints τ_i
//! (unbiased on a plane; the default stays the paper's per-sample form, see [`OpacityModel`]).
//!
//! Backward without dividing by (1 − α): with per-sample scalar `g_i = ∂L/∂w_i + ∂L/∂D·τ_i +
//! ∂L/∂A + ∂L/∂F·f_i`, `∂L/∂α_k = T_k (g_k − R_k)` where `R_k = Σ_{i>k} Π_{k<j<i}(1 − α_j) α_i g_i`
//! is accumulated from the back: `R_k = α_{k+1} g_{k+1} + (1 − α_{k+1}) R_{k+1}`.

/// What one ray renders.
#[derive(Clone, Debug, PartialEq)]
pub struct Composite {
    pub depth_m: f32,
    pub accumulation: f32,
    pub feature: Vec<f32>,
    /// Per-sample weights w_i (for losses on weights and for the backward pass).
    pub weights: Vec<f32>,
    /// Per-sample transmittance T_i.
    pub transmittance: Vec<f32>,
}

/// `α = sigmoid(−β s)` and its derivatives `∂α/∂s`, `∂α/∂β`.
#[inline]
pub fn alpha_from_sdf(sdf: f32, beta: f32) -> (f32, f32, f32) {
    let a = 1.0 / (1.0 + (beta * sdf).exp());
    let da = a * (1.0 - a);
    (a, -beta * da, -sdf * da)
}

/// How a ray's signed distances become opacities.
///
/// `PerSample` is UniSim's `α_i = sigmoid(−β s_i)` (method.md §3). On a plane with an exact SDF
/// it renders depth with a view-dependent bias: about +½ step when β·cos θ·step is large (the
/// first sample past the surface takes the whole weight), and up to tens of centimetres short
/// at grazing incidence (each sample in front of the surface already holds a little opacity,
/// and many of them lie within 1/(β cos θ) of it). Registration against such a scene moves
/// poses to absorb the bias.
///
/// `Interval` is NeuS's discrete opacity of the section between samples i and i+1,
/// `α_i = max(0, 1 − Φ(s_{i+1})/Φ(s_i))` with `Φ(s) = sigmoid(β s)`, placed at the section's
/// midpoint: unbiased on a plane at every incidence and β. The last sample closes the last
/// section and holds no opacity of its own.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum OpacityModel {
    #[default]
    PerSample,
    Interval,
}

/// An opacity model with its sharpness β (1/m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Opacity {
    pub model: OpacityModel,
    pub beta: f32,
}

/// `ln sigmoid(x)`, stable for large |x|.
#[inline]
fn ln_sigmoid(x: f32) -> f32 {
    x.min(0.0) - (-x.abs()).exp().ln_1p()
}

/// A section's `(α, ∂α/∂s_i, ∂α/∂s_{i+1}, ∂α/∂β)` under [`OpacityModel::Interval`].
#[inline]
fn section_alpha(s0: f32, s1: f32, beta: f32) -> (f32, f32, f32, f32) {
    let delta = ln_sigmoid(beta * s1) - ln_sigmoid(beta * s0);
    if delta >= 0.0 {
        return (0.0, 0.0, 0.0, 0.0);
    }
    let ratio = delta.exp();
    // ∂ ln sigmoid(x)/∂x = sigmoid(−x).
    let (g0, g1) = (
        1.0 / (1.0 + (beta * s0).exp()),
        1.0 / (1.0 + (beta * s1).exp()),
    );
    (
        1.0 - ratio,
        ratio * beta * g0,
        -ratio * beta * g1,
        -ratio * (s1 * g1 - s0 * g0),
    )
}

impl Opacity {
    /// Opacities of samples with signed distances `sdfs` at `taus_m`, and where each one's
    /// weight sits along the ray (the samples themselves, or the sections' midpoints).
    pub fn alphas(&self, sdfs: &[f32], taus_m: &[f32]) -> (Vec<f32>, Vec<f32>) {
        match self.model {
            OpacityModel::PerSample => (
                sdfs.iter()
                    .map(|s| alpha_from_sdf(*s, self.beta).0)
                    .collect(),
                taus_m[..sdfs.len()].to_vec(),
            ),
            OpacityModel::Interval => {
                let n = sdfs.len();
                let (mut alphas, mut at) = (Vec::with_capacity(n), Vec::with_capacity(n));
                for i in 0..n {
                    if i + 1 < n {
                        alphas.push(section_alpha(sdfs[i], sdfs[i + 1], self.beta).0);
                        at.push(0.5 * (taus_m[i] + taus_m[i + 1]));
                    } else {
                        alphas.push(0.0);
                        at.push(taus_m[i]);
                    }
                }
                (alphas, at)
            }
        }
    }

    /// The opacity that the newest of `sdfs` settles (for marching until opaque): the last
    /// sample's own, or the section it closes (`None` for a lone first section start).
    pub fn settled(&self, sdfs: &[f32]) -> Option<f32> {
        match (self.model, sdfs) {
            (OpacityModel::PerSample, [.., s]) => Some(alpha_from_sdf(*s, self.beta).0),
            (OpacityModel::Interval, [.., s0, s1]) => Some(section_alpha(*s0, *s1, self.beta).0),
            _ => None,
        }
    }

    /// `(∂L/∂s_i, ∂L/∂β)` from `∂L/∂α_i`.
    pub fn backward(&self, sdfs: &[f32], d_alpha: &[f32]) -> (Vec<f32>, f64) {
        let n = sdfs.len();
        let mut d_sdf = vec![0.0f32; n];
        let mut d_beta = 0.0f64;
        match self.model {
            OpacityModel::PerSample => {
                for i in 0..n {
                    let (_, da_ds, da_db) = alpha_from_sdf(sdfs[i], self.beta);
                    d_sdf[i] = d_alpha[i] * da_ds;
                    d_beta += (d_alpha[i] * da_db) as f64;
                }
            }
            OpacityModel::Interval => {
                for i in 0..n.saturating_sub(1) {
                    let (_, d0, d1, db) = section_alpha(sdfs[i], sdfs[i + 1], self.beta);
                    d_sdf[i] += d_alpha[i] * d0;
                    d_sdf[i + 1] += d_alpha[i] * d1;
                    d_beta += (d_alpha[i] * db) as f64;
                }
            }
        }
        (d_sdf, d_beta)
    }
}

/// Composite samples front to back. `features` is `n × dim`, row per sample.
pub fn composite(alphas: &[f32], taus_m: &[f32], features: &[f32], dim: usize) -> Composite {
    let n = alphas.len();
    let mut out = Composite {
        depth_m: 0.0,
        accumulation: 0.0,
        feature: vec![0.0; dim],
        weights: Vec::with_capacity(n),
        transmittance: Vec::with_capacity(n),
    };
    let mut t = 1.0f32;
    for i in 0..n {
        let w = t * alphas[i];
        out.transmittance.push(t);
        out.weights.push(w);
        out.depth_m += w * taus_m[i];
        out.accumulation += w;
        for c in 0..dim {
            out.feature[c] += w * features[i * dim + c];
        }
        t *= 1.0 - alphas[i];
    }
    out
}

/// What the loss says about one ray's composite: `∂L/∂D`, `∂L/∂A`, `∂L/∂F` (empty when no
/// feature is rendered) and `∂L/∂w_i` per sample (empty when no loss reads the weights, e.g.
/// the regulariser's weight suppression does).
#[derive(Clone, Copy, Debug, Default)]
pub struct Upstream<'a> {
    pub depth: f32,
    pub accumulation: f32,
    pub feature: &'a [f32],
    pub weights: &'a [f32],
}

/// Gradients of the composite: ∂L/∂α_i and ∂L/∂f_i (row per sample).
pub fn composite_backward(
    alphas: &[f32],
    taus_m: &[f32],
    features: &[f32],
    dim: usize,
    forward: &Composite,
    up: &Upstream,
) -> (Vec<f32>, Vec<f32>) {
    let n = alphas.len();
    let dim = if up.feature.len() >= dim { dim } else { 0 };
    let g: Vec<f32> = (0..n)
        .map(|i| {
            up.depth * taus_m[i]
                + up.accumulation
                + up.weights.get(i).copied().unwrap_or(0.0)
                + (0..dim)
                    .map(|c| up.feature[c] * features[i * dim + c])
                    .sum::<f32>()
        })
        .collect();
    let mut d_alpha = vec![0.0; n];
    let mut r = 0.0f32;
    for k in (0..n).rev() {
        d_alpha[k] = forward.transmittance[k] * (g[k] - r);
        r = alphas[k] * g[k] + (1.0 - alphas[k]) * r;
    }
    let mut d_features = vec![0.0; n * dim];
    for i in 0..n {
        for c in 0..dim {
            d_features[i * dim + c] = forward.weights[i] * up.feature[c];
        }
    }
    (d_alpha, d_features)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setup() -> (Vec<f32>, Vec<f32>, Vec<f32>) {
        let n = 12;
        let sdf: Vec<f32> = (0..n).map(|i| 0.45 - 0.08 * i as f32).collect();
        let taus: Vec<f32> = (0..n).map(|i| 5.0 + 0.1 * i as f32).collect();
        let feats: Vec<f32> = (0..n * 3).map(|k| ((k as f32) * 0.37).sin()).collect();
        (sdf, taus, feats)
    }

    fn loss(sdf: &[f32], beta: f32, taus: &[f32], feats: &[f32]) -> f32 {
        let alphas: Vec<f32> = sdf.iter().map(|s| alpha_from_sdf(*s, beta).0).collect();
        let c = composite(&alphas, taus, feats, 3);
        let weights: f32 = (c.weights.iter().enumerate())
            .map(|(i, w)| w * 0.3 * (i as f32 * 0.9).cos())
            .sum();
        0.7 * c.depth_m - 1.3 * c.accumulation + c.feature[0] * 0.5 - c.feature[2] * 0.9 + weights
    }

    #[test]
    fn a_wall_stops_the_ray_at_its_surface() {
        // SDF of a wall 6 m ahead, sampled every 10 cm, β = 50: depth ≈ 6 m, A ≈ 1.
        let taus: Vec<f32> = (0..100).map(|i| i as f32 * 0.1).collect();
        let alphas: Vec<f32> = taus
            .iter()
            .map(|t| alpha_from_sdf(6.0 - t, 50.0).0)
            .collect();
        let c = composite(&alphas, &taus, &[], 0);
        assert!((c.accumulation - 1.0).abs() < 1e-3, "{}", c.accumulation);
        assert!((c.depth_m - 6.0).abs() < 0.1, "{}", c.depth_m);
    }

    #[test]
    fn backward_matches_finite_differences() {
        let (sdf, taus, feats) = setup();
        let beta = 8.0;
        let alphas: Vec<f32> = sdf.iter().map(|s| alpha_from_sdf(*s, beta).0).collect();
        let fwd = composite(&alphas, &taus, &feats, 3);
        let d_w: Vec<f32> = (0..sdf.len())
            .map(|i| 0.3 * (i as f32 * 0.9).cos())
            .collect();
        let (d_alpha, d_feat) = composite_backward(
            &alphas,
            &taus,
            &feats,
            3,
            &fwd,
            &Upstream {
                depth: 0.7,
                accumulation: -1.3,
                feature: &[0.5, 0.0, -0.9],
                weights: &d_w,
            },
        );
        let eps = 1e-3;
        let mut d_beta = 0.0;
        for i in 0..sdf.len() {
            let (_, da_ds, da_db) = alpha_from_sdf(sdf[i], beta);
            d_beta += d_alpha[i] * da_db;
            let mut up = sdf.clone();
            up[i] += eps;
            let mut down = sdf.clone();
            down[i] -= eps;
            let fd =
                (loss(&up, beta, &taus, &feats) - loss(&down, beta, &taus, &feats)) / (2.0 * eps);
            let an = d_alpha[i] * da_ds;
            assert!(
                (fd - an).abs() < 5e-3 * (1.0 + fd.abs()),
                "s[{i}] {fd} vs {an}"
            );
            for c in 0..3 {
                let mut up = feats.clone();
                up[i * 3 + c] += eps;
                let mut down = feats.clone();
                down[i * 3 + c] -= eps;
                let fd =
                    (loss(&sdf, beta, &taus, &up) - loss(&sdf, beta, &taus, &down)) / (2.0 * eps);
                assert!((fd - d_feat[i * 3 + c]).abs() < 5e-3 * (1.0 + fd.abs()));
            }
        }
        let fd = (loss(&sdf, beta + eps, &taus, &feats) - loss(&sdf, beta - eps, &taus, &feats))
            / (2.0 * eps);
        assert!(
            (fd - d_beta).abs() < 5e-3 * (1.0 + fd.abs()),
            "β {fd} vs {d_beta}"
        );
    }

    /// Mean rendered depth minus the truth for a plane at `hit_m` seen at incidence
    /// `cos_incidence`, 10 cm steps, averaged over 40 jitters.
    fn plane_bias(model: OpacityModel, beta: f32, cos_incidence: f32) -> f32 {
        let opacity = Opacity { model, beta };
        let hit_m = 20.0f32;
        let mut sum = 0.0;
        for j in 0..40 {
            let taus: Vec<f32> = (0..400)
                .map(|k| (k as f32 + j as f32 / 40.0) * 0.1)
                .collect();
            let sdfs: Vec<f32> = taus.iter().map(|t| (hit_m - t) * cos_incidence).collect();
            let (alphas, at) = opacity.alphas(&sdfs, &taus);
            let c = composite(&alphas, &at, &[], 0);
            sum += c.depth_m / c.accumulation - hit_m;
        }
        sum / 40.0
    }

    #[test]
    fn the_section_model_renders_a_plane_without_bias_at_any_incidence() {
        for beta in [20.0, 100.0, 400.0] {
            for cos in [1.0, 0.3, 0.1, 0.045] {
                let bias = plane_bias(OpacityModel::Interval, beta, cos);
                assert!(bias.abs() < 0.005, "β {beta} cos {cos}: {bias} m");
            }
        }
        // The per-sample model: half a step long head-on, short at grazing incidence.
        let head_on = plane_bias(OpacityModel::PerSample, 100.0, 1.0);
        assert!((head_on - 0.05).abs() < 0.005, "{head_on}");
        let grazing = plane_bias(OpacityModel::PerSample, 100.0, 0.045);
        assert!(grazing < -0.2, "{grazing}");
    }

    #[test]
    fn opacity_backward_matches_finite_differences() {
        let sdfs: Vec<f32> = (0..14)
            .map(|i| 0.5 - 0.09 * i as f32 + 0.05 * (i as f32 * 1.7).sin())
            .collect();
        let taus: Vec<f32> = (0..14).map(|i| 3.0 + 0.1 * i as f32).collect();
        let d_alpha: Vec<f32> = (0..14).map(|i| (i as f32 * 0.61).cos()).collect();
        for model in [OpacityModel::PerSample, OpacityModel::Interval] {
            let beta = 6.0;
            let loss = |s: &[f32], beta: f32| -> f64 {
                let (a, _) = Opacity { model, beta }.alphas(s, &taus);
                a.iter().zip(&d_alpha).map(|(a, g)| (a * g) as f64).sum()
            };
            let (d_sdf, d_beta) = Opacity { model, beta }.backward(&sdfs, &d_alpha);
            let eps = 1e-3;
            for i in 0..sdfs.len() {
                let (mut up, mut down) = (sdfs.clone(), sdfs.clone());
                up[i] += eps;
                down[i] -= eps;
                let fd = (loss(&up, beta) - loss(&down, beta)) / (2.0 * eps as f64);
                let an = d_sdf[i] as f64;
                assert!(
                    (fd - an).abs() < 2e-3 * (1.0 + fd.abs()),
                    "{model:?} s[{i}] {fd} vs {an}"
                );
            }
            let fd = (loss(&sdfs, beta + eps) - loss(&sdfs, beta - eps)) / (2.0 * eps as f64);
            assert!(
                (fd - d_beta).abs() < 2e-3 * (1.0 + fd.abs()),
                "{model:?} β {fd} vs {d_beta}"
            );
            // Marching settles each opacity once its section is closed.
            let (alphas, _) = Opacity { model, beta }.alphas(&sdfs, &taus);
            for n in 1..=sdfs.len() {
                let settled = Opacity { model, beta }.settled(&sdfs[..n]);
                let want = match model {
                    OpacityModel::PerSample => Some(alphas[n - 1]),
                    OpacityModel::Interval => (n >= 2).then(|| alphas[n - 2]),
                };
                assert_eq!(settled, want);
            }
        }
    }
}
