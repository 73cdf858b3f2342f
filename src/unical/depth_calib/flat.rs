//! Small helpers of the step: the seeded random draws (a 64-bit xorshift, uniform and
//! Gaussian values) and the decoders' parameters and gradients as flat arrays for Adam.

/// Uniform in [0, 1).
pub(super) fn unit(rng: &mut u64) -> f64 {
    (next(rng) >> 11) as f64 / (1u64 << 53) as f64
}

/// Two independent standard normal values (Box–Muller).
pub(super) fn gaussian_pair(rng: &mut u64) -> (f64, f64) {
    let u1 = unit(rng).max(1e-12);
    let u2 = unit(rng);
    let r = (-2.0 * u1.ln()).sqrt();
    let (s, c) = (2.0 * std::f64::consts::PI * u2).sin_cos();
    (r * c, r * s)
}

pub(super) fn next(rng: &mut u64) -> u64 {
    *rng = rng.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *rng;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

pub(super) fn mlp_flat(m: &crate::unical::mlp::Mlp) -> Vec<f32> {
    m.layers
        .iter()
        .flat_map(|l| l.weights().iter().chain(l.bias.iter()).copied())
        .collect()
}

pub(super) fn mlp_set(m: &mut crate::unical::mlp::Mlp, p: &[f32]) {
    let mut k = 0;
    for l in &mut m.layers {
        let (weights, bias) = l.params_mut();
        for v in weights.iter_mut().chain(bias.iter_mut()) {
            *v = p[k];
            k += 1;
        }
    }
}

pub(super) fn add_scaled(
    acc: &mut crate::unical::mlp::MlpGrad,
    g: &crate::unical::mlp::MlpGrad,
    w: f32,
) {
    for (a, b) in acc.weights.iter_mut().zip(&g.weights) {
        a.iter_mut().zip(b).for_each(|(x, y)| *x += y * w);
    }
    for (a, b) in acc.bias.iter_mut().zip(&g.bias) {
        a.iter_mut().zip(b).for_each(|(x, y)| *x += y * w);
    }
}

pub(super) fn grad_flat(g: &crate::unical::mlp::MlpGrad) -> Vec<f32> {
    g.weights
        .iter()
        .zip(&g.bias)
        .flat_map(|(w, b)| w.iter().chain(b.iter()).copied())
        .collect()
}
