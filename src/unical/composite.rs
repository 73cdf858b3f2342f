//! Volume rendering along one ray (method.md §3, main Eq. 2) and its backward pass.
//!
//! Per sample i: opacity `α_i = sigmoid(−β·s_i)` from the signed distance s_i (β > 0 learnable,
//! 1/m), transmittance `T_i = Π_{j<i}(1 − α_j)`, weight `w_i = T_i·α_i`. A ray renders its
//! expected range `D = Σ w_i τ_i` (Eq. 5), accumulated opacity `A = Σ w_i` and feature
//! `F = Σ w_i f_i` (feature rendering: decoders then run once per ray, §4(a)).
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
}
