//! Adam (method.md §12): dense for the small networks and poses, sparse for the hash table.
//!
//! The sparse variant updates only the entries a step touched (Instant-NGP skips entries whose
//! gradient is exactly zero, method.md §15.1/§18): untouched entries keep their moments, and the
//! bias correction uses the global step count, as tiny-cuda-nn does. The hash-table defaults are
//! β1 0.9, β2 0.99, ε 1e-15.

use rayon::prelude::*;

use super::hash_grid::{ACC_BLOCK, F, GradAccumulator, SparseGrad};
use crate::sim::wide::dispatch_wide;

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
        self.step_grouped(params, grads, lr, &[]);
    }

    /// One update in which the coordinates of each `groups` range share a denominator, the
    /// root of their largest second moment: a coordinate whose gradient is small beside its
    /// group's steps proportionally less, instead of by `lr` like every other (Adam's
    /// per-coordinate scaling turns a direction the data hardly see into a random walk of the
    /// rate's size). Coordinates in no group are stepped as by [`Self::step`].
    pub fn step_grouped(
        &mut self,
        params: &mut [f32],
        grads: &[f32],
        lr: f32,
        groups: &[std::ops::Range<usize>],
    ) {
        self.step += 1;
        let c = self.config;
        let bc1 = 1.0 - c.beta1.powi(self.step);
        let bc2 = 1.0 - c.beta2.powi(self.step);
        let n = params.len().min(grads.len());
        for i in 0..n {
            let g = grads[i];
            self.m[i] = c.beta1 * self.m[i] + (1.0 - c.beta1) * g;
            self.v[i] = c.beta2 * self.v[i] + (1.0 - c.beta2) * g * g;
        }
        for i in 0..n {
            let v = match groups.iter().find(|r| r.contains(&i)) {
                Some(r) => {
                    let r = r.start..r.end.min(n);
                    self.v[r].iter().copied().fold(0.0, f32::max)
                }
                None => self.v[i],
            };
            params[i] -= lr * (self.m[i] / bc1) / ((v / bc2).sqrt() + c.epsilon);
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
            m: super::table_memory::zeroed(len),
            v: super::table_memory::zeroed(len),
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

    /// [`Self::step`] on the sum of `accs` (added in order, so the sums are deterministic),
    /// read and cleared block by block in parallel in index order instead of through a list of
    /// entries in touch order: the same sums and the same updates, in one pass over the table,
    /// its moments and the accumulators.
    pub fn step_accumulated(&mut self, params: &mut [f32], accs: &mut [GradAccumulator], lr: f32) {
        self.step += 1;
        let c = self.config;
        let bc1 = 1.0 - c.beta1.powi(self.step);
        let bc2 = 1.0 - c.beta2.powi(self.step);
        let block = ACC_BLOCK * F;
        // Block-major: block b of every accumulator at `parts[b·n..(b+1)·n]` (disjoint borrows).
        let n = accs.len().max(1);
        let mut blocks: Vec<_> = accs.iter_mut().map(|a| a.blocks_mut()).collect();
        let mut parts: Vec<(&mut [f32], &mut bool)> = Vec::new();
        'blocks: loop {
            for it in blocks.iter_mut() {
                match it.next() {
                    Some(part) => parts.push(part),
                    None => break 'blocks,
                }
            }
        }
        params
            .par_chunks_mut(block)
            .zip(self.m.par_chunks_mut(block))
            .zip(self.v.par_chunks_mut(block))
            .zip(parts.par_chunks_mut(n))
            .with_min_len(256)
            .for_each(|(((p, m), v), parts)| {
                let mut any = false;
                for (_, dirty) in parts.iter_mut() {
                    any |= std::mem::take(*dirty);
                }
                if !any {
                    return;
                }
                adam_block_wide(p, m, v, parts, c, [lr, bc1, bc2]);
            });
    }
}

dispatch_wide! {
    fn adam_block_wide(
        p: &mut [f32],
        m: &mut [f32],
        v: &mut [f32],
        parts: &mut [(&mut [f32], &mut bool)],
        c: AdamConfig,
        lr_bc: [f32; 3],
    ) -> () => adam_block
}

/// One block of [`SparseAdam::step_accumulated`]: the accumulators' sums (each cleared as it
/// is read), then Adam's update of every entry whose sum is not zero. Branch-free (an entry
/// with no gradient keeps its values by a select), so it vectorises; each entry's arithmetic
/// is the scalar update's, operation for operation, so the results are the same to the bit.
#[inline(always)]
fn adam_block<const WIDE: bool>(
    p: &mut [f32],
    m: &mut [f32],
    v: &mut [f32],
    parts: &mut [(&mut [f32], &mut bool)],
    c: AdamConfig,
    [lr, bc1, bc2]: [f32; 3],
) {
    let mut sums = [0.0f32; ACC_BLOCK * F];
    let len = p.len().min(sums.len());
    let sums = &mut sums[..len];
    for (part, _) in parts.iter_mut() {
        let k = part.len().min(len);
        for (sum, g) in sums[..k].iter_mut().zip(part[..k].iter_mut()) {
            *sum += std::mem::take(g);
        }
    }
    for (((p, m), v), &g) in p
        .iter_mut()
        .zip(m.iter_mut())
        .zip(v.iter_mut())
        .zip(sums.iter())
    {
        let m_new = c.beta1 * *m + (1.0 - c.beta1) * g;
        let v_new = c.beta2 * *v + (1.0 - c.beta2) * g * g;
        let p_new = *p - lr * (m_new / bc1) / ((v_new / bc2).sqrt() + c.epsilon);
        let untouched = g == 0.0;
        *m = if untouched { *m } else { m_new };
        *v = if untouched { *v } else { v_new };
        *p = if untouched { *p } else { p_new };
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
    fn a_grouped_step_scales_a_weak_coordinate_by_its_group() {
        let mut plain = DenseAdam::new(3, AdamConfig::STANDARD);
        let mut grouped = DenseAdam::new(3, AdamConfig::STANDARD);
        let (mut a, mut b) = ([0.0f32; 3], [0.0f32; 3]);
        // Coordinate 2 is outside the group; 0 sees a gradient 100 times 1's.
        let g = [1.0f32, 0.01, 0.01];
        for _ in 0..50 {
            plain.step(&mut a, &g, 0.1);
            grouped.step_grouped(&mut b, &g, 0.1, std::slice::from_ref(&(0..2)));
        }
        // Adam moves the weak coordinate as far as the strong one.
        assert!((a[0] - a[1]).abs() < 1e-3 * a[0].abs(), "{a:?}");
        // Grouped, it moves a hundredth as far, and the strong one as far as with Adam.
        let ratio = b[1] / b[0];
        assert!((ratio - 0.01).abs() < 1e-4, "{b:?}: ratio {ratio}");
        assert!((b[0] - a[0]).abs() < 1e-5, "{b:?} against {a:?}");
        // Outside every group it is Adam's step.
        assert!((b[2] - a[2]).abs() < 1e-6, "{b:?} against {a:?}");
    }

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

    /// The fused block-parallel step makes the very same updates as merging the accumulators'
    /// lists and stepping through them, over several steps (Adam's moments included).
    #[test]
    fn accumulated_step_matches_the_list_step() {
        let entries = 3 * super::ACC_BLOCK + 17;
        let fill = |accs: &mut [GradAccumulator], round: u32| {
            for (a, acc) in accs.iter_mut().enumerate() {
                for k in 0..90u32 {
                    let e = (k * 37 + a as u32 * 11 + round * 5) % entries as u32;
                    acc.add_one(e, [(k as f32 * 0.37).sin(), (a as f32 - 1.5) * 0.1]);
                }
            }
        };
        let mut p1 = vec![0.25f32; entries * F];
        let mut p2 = p1.clone();
        let mut o1 = SparseAdam::new(p1.len(), AdamConfig::NGP);
        let mut o2 = SparseAdam::new(p2.len(), AdamConfig::NGP);
        let mut accs1: Vec<_> = (0..3).map(|_| GradAccumulator::new(entries)).collect();
        let mut accs2 = accs1.clone();
        for round in 0..4 {
            fill(&mut accs1, round);
            fill(&mut accs2, round);
            let g = GradAccumulator::drain_all(&mut accs1);
            o1.step(&mut p1, &g, 0.01);
            o2.step_accumulated(&mut p2, &mut accs2, 0.01);
            assert_eq!(p1, p2, "round {round}");
        }
        assert!(p1.iter().any(|v| *v != 0.25));
        // Both leave their accumulators empty.
        for acc in accs1.iter_mut().chain(accs2.iter_mut()) {
            assert!(acc.drain().entries.is_empty());
        }
    }

    #[test]
    fn learning_rate_decays_to_the_final_factor() {
        assert!((decayed_lr(0.01, 0.1, 0, 100) - 0.01).abs() < 1e-9);
        assert!((decayed_lr(0.01, 0.1, 100, 100) - 0.001).abs() < 1e-9);
        assert!((decayed_lr(0.01, 0.1, 50, 100) - 0.01 * 0.1f32.sqrt()).abs() < 1e-7);
    }
}
