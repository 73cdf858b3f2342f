//! Adam (method.md §12): dense for the small networks and poses, sparse for the hash table.
//!
//! The sparse variant updates only the entries a step touched (Instant-NGP skips entries whose
//! gradient is exactly zero, method.md §15.1/§18): untouched entries keep their moments, and the
//! bias correction uses the global step count, as tiny-cuda-nn does. The hash-table defaults are
//! β1 0.9, β2 0.99, ε 1e-15.

use super::hash_grid::{F, SparseGrad};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamConfig {
    pub beta1: f32,
    pub beta2: f32,
    pub epsilon: f32,
}

impl AdamConfig {
    /// Instant-NGP's settings for hash tables and MLPs.
    pub const NGP: Self = Self {
        beta1: 0.9,
        beta2: 0.99,
        epsilon: 1e-15,
    };
    /// The usual defaults (used for poses).
    pub const STANDARD: Self = Self {
        beta1: 0.9,
        beta2: 0.999,
        epsilon: 1e-8,
    };
}

/// Adam state for a dense parameter vector.
#[derive(Clone, Debug)]
pub struct DenseAdam {
    pub config: AdamConfig,
    m: Vec<f32>,
    v: Vec<f32>,
    step: i32,
}

impl DenseAdam {
    pub fn new(len: usize, config: AdamConfig) -> Self {
        Self {
            config,
            m: vec![0.0; len],
            v: vec![0.0; len],
            step: 0,
        }
    }

    /// One update `params -= lr · m̂ / (√v̂ + ε)`.
    pub fn step(&mut self, params: &mut [f32], grads: &[f32], lr: f32) {
        self.step += 1;
        let c = self.config;
        let bc1 = 1.0 - c.beta1.powi(self.step);
        let bc2 = 1.0 - c.beta2.powi(self.step);
        for i in 0..params.len().min(grads.len()) {
            let g = grads[i];
            self.m[i] = c.beta1 * self.m[i] + (1.0 - c.beta1) * g;
            self.v[i] = c.beta2 * self.v[i] + (1.0 - c.beta2) * g * g;
            params[i] -= lr * (self.m[i] / bc1) / ((self.v[i] / bc2).sqrt() + c.epsilon);
        }
    }
}

/// Adam state for the hash table, updated sparsely.
#[derive(Clone, Debug)]
pub struct SparseAdam {
    pub config: AdamConfig,
    m: Vec<f32>,
    v: Vec<f32>,
    step: i32,
}

impl SparseAdam {
    pub fn new(len: usize, config: AdamConfig) -> Self {
        Self {
            config,
            m: vec![0.0; len],
            v: vec![0.0; len],
            step: 0,
        }
    }

    /// Update the touched entries of `params` (`entries · F`); `grad` must be merged.
    pub fn step(&mut self, params: &mut [f32], grad: &SparseGrad, lr: f32) {
        self.step += 1;
        let c = self.config;
        let bc1 = 1.0 - c.beta1.powi(self.step);
        let bc2 = 1.0 - c.beta2.powi(self.step);
        for &(entry, g) in &grad.entries {
            for (f, &gf) in g.iter().enumerate() {
                if gf == 0.0 {
                    continue;
                }
                let i = entry as usize * F + f;
                if i >= params.len() {
                    continue;
                }
                self.m[i] = c.beta1 * self.m[i] + (1.0 - c.beta1) * gf;
                self.v[i] = c.beta2 * self.v[i] + (1.0 - c.beta2) * gf * gf;
                params[i] -= lr * (self.m[i] / bc1) / ((self.v[i] / bc2).sqrt() + c.epsilon);
            }
        }
    }
}

/// Exponential decay from `lr0` to `lr0 · final_factor` over `total` steps (method.md §12).
pub fn decayed_lr(lr0: f32, final_factor: f32, step: usize, total: usize) -> f32 {
    let s = (step as f32 / total.max(1) as f32).min(1.0);
    lr0 * final_factor.powf(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dense_adam_minimises_a_quadratic() {
        let mut p = vec![3.0f32, -2.0];
        let mut opt = DenseAdam::new(2, AdamConfig::STANDARD);
        for _ in 0..500 {
            let g = [2.0 * (p[0] - 1.0), 2.0 * (p[1] + 0.5)];
            opt.step(&mut p, &g, 0.05);
        }
        assert!(
            (p[0] - 1.0).abs() < 1e-2 && (p[1] + 0.5).abs() < 1e-2,
            "{p:?}"
        );
    }

    #[test]
    fn sparse_adam_touches_only_touched_entries() {
        let mut p = vec![0.5f32; 10 * F];
        let mut opt = SparseAdam::new(p.len(), AdamConfig::NGP);
        let mut g = SparseGrad::default();
        g.entries.push((3, [1.0, 0.0]));
        g.entries.push((3, [1.0, -1.0]));
        g.merge();
        opt.step(&mut p, &g, 0.01);
        for (i, v) in p.iter().enumerate() {
            let touched = i == 3 * F || i == 3 * F + 1;
            assert_eq!(*v != 0.5, touched, "entry value {i}");
        }
        // First Adam step moves by lr against the gradient's sign.
        assert!((p[3 * F] - 0.49).abs() < 1e-6 && (p[3 * F + 1] - 0.51).abs() < 1e-6);
    }

    #[test]
    fn learning_rate_decays_to_the_final_factor() {
        assert!((decayed_lr(0.01, 0.1, 0, 100) - 0.01).abs() < 1e-9);
        assert!((decayed_lr(0.01, 0.1, 100, 100) - 0.001).abs() < 1e-9);
        assert!((decayed_lr(0.01, 0.1, 50, 100) - 0.01 * 0.1f32.sqrt()).abs() < 1e-7);
    }
}
