//! Multiresolution hash encoding (Instant-NGP, method.md §15.1), on the CPU, with its backward
//! pass and its spatial gradient.
//!
//! How it works. Level `l` has `scale_l = 2^(l·log2 b)·N_min − 1` and `res_l = ⌈scale_l⌉ + 1`
//! cells per axis (b spaces the levels geometrically from N_min to N_max). A point x ∈ \[0,1\]³ sits
//! at `pos = x·scale_l + 0.5` (the half-cell offset staggers levels); its 8 surrounding lattice
//! corners are looked up — directly (x fastest) when the level's lattice fits in its table, else by
//! the spatial hash `(x·1 ⊕ y·2654435761 ⊕ z·805459861) mod T` — and trilinearly blended. Levels
//! are concatenated: `L·F` features. The layout (one flat f32 array, level offsets in entries,
//! F features per entry) is the one a GPU would take unchanged.
//!
//! Backward: d(loss)/d(entry) = Σ weight·d(loss)/d(feature), collected as a sparse list of
//! touched entries (a step touches a tiny fraction of the table; method.md §18). Spatial gradient:
//! the derivative of the trilinear weights times `scale_l`, used for pose gradients and Eikonal.
//! Both passes are compiled for AVX-512 and AVX2 as well and run as the CPU allows
//! ([`crate::sim::wide`]). While a [`Scaled`] sink lives on the thread, the encode also
//! prefetches the gradient accumulator's slots of the corners it reads
//! ([`super::grad_sink`]), so the backward of the same ray finds them in cache.

use crate::sim::wide::dispatch_wide;

pub use super::grad_sink::{ACC_BLOCK, GradAccumulator, GradSink, Scaled, SparseGrad};

/// Features per entry.
pub const F: usize = 2;

const PRIMES: [u32; 3] = [1, 2_654_435_761, 805_459_861];

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HashGridConfig {
    pub levels: usize,
    pub log2_table_size: u32,
    pub base_resolution: f32,
    pub max_resolution: f32,
}

impl Default for HashGridConfig {
    /// The CPU preset of method.md §18: L = 16, F = 2, T = 2^19, N_min = 16, N_max = 4096.
    fn default() -> Self {
        Self {
            levels: 16,
            log2_table_size: 19,
            base_resolution: 16.0,
            max_resolution: 4096.0,
        }
    }
}

#[derive(Clone, Debug)]
struct Level {
    scale: f32,
    resolution: u32,
    /// First entry of the level in the flat table.
    offset: usize,
    /// Entries in the level.
    size: usize,
    dense: bool,
}

/// The encoding's trainable table and its level layout.
#[derive(Clone, Debug)]
pub struct HashGrid {
    pub config: HashGridConfig,
    levels: Vec<Level>,
    /// `entries · F` features, f32.
    pub params: Vec<f32>,
    /// Per level, the factor its features enter the encoding with (1: fully open; see
    /// [`HashGrid::set_active_levels`]).
    level_weights: Vec<f32>,
}

/// Levels whose corners are found together before the table is read.
const LEVEL_CHUNK: usize = 16;

/// The 8 corners of one level: entry indices and trilinear weights, plus what the spatial
/// gradient needs.
#[derive(Clone, Copy, Default)]
struct Corners {
    entry: [u32; 8],
    weight: [f32; 8],
    frac: [f32; 3],
}

impl HashGrid {
    /// A grid with entries drawn uniformly from ±1e-4 (deterministic for a seed).
    pub fn new(config: HashGridConfig, seed: u64) -> Self {
        let table = 1usize << config.log2_table_size;
        let l_count = config.levels.max(1);
        let b = if l_count > 1 {
            ((config.max_resolution.ln() - config.base_resolution.ln()) / (l_count - 1) as f32)
                .exp()
        } else {
            1.0
        };
        let mut levels = Vec::with_capacity(l_count);
        let mut offset = 0usize;
        for l in 0..l_count {
            let scale = (l as f32 * b.log2()).exp2() * config.base_resolution - 1.0;
            let resolution = scale.ceil() as u32 + 1;
            let dense_size = (resolution as usize).pow(3);
            let size = dense_size.next_multiple_of(8).min(table);
            levels.push(Level {
                scale,
                resolution,
                offset,
                size,
                dense: dense_size <= size,
            });
            offset += size;
        }
        let mut state = seed ^ 0x9E37_79B9_7F4A_7C15;
        let mut params = super::table_memory::zeroed(offset * F);
        for p in &mut params {
            // splitmix64 → U(−1e-4, 1e-4)
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            *p = ((z >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0) * 1e-4;
        }
        Self {
            level_weights: vec![1.0; levels.len()],
            config,
            levels,
            params,
        }
    }

    /// Coarse-to-fine (BARF, Lin et al. 2021): with `active` levels in `[0, L]`, level `l` is
    /// weighted by `(1 − cos(π·clamp(active − l, 0, 1)))/2`, so levels open one after another
    /// (fully open at `active ≥ L`). Closed levels are skipped in every pass.
    pub fn set_active_levels(&mut self, active: f32) {
        for (l, w) in self.level_weights.iter_mut().enumerate() {
            let t = (active - l as f32).clamp(0.0, 1.0);
            *w = (1.0 - (std::f32::consts::PI * t).cos()) * 0.5;
        }
    }

    /// The weight of level `l` in the spatial gradient ∂L/∂x when only `levels` of them are to
    /// count (`None`: all): the same cosine ramp as [`HashGrid::set_active_levels`], so level
    /// `l` counts fully once `levels ≥ l + 1` and not at all while `levels ≤ l`.
    #[inline(always)]
    pub fn spatial_weight(levels: Option<f32>, l: usize) -> f32 {
        match levels {
            None => 1.0,
            Some(a) => {
                let t = (a - l as f32).clamp(0.0, 1.0);
                (1.0 - (std::f32::consts::PI * t).cos()) * 0.5
            }
        }
    }

    /// Level `l`'s gradient scaled by its weight, `None` when nothing flows through it.
    #[inline(always)]
    fn level_grad(&self, l: usize, d_out: &[f32]) -> Option<[f32; F]> {
        let w = self.level_weights[l];
        let g = &d_out[l * F..(l + 1) * F];
        if w == 0.0 || g.iter().all(|v| *v == 0.0) {
            return None;
        }
        let mut out = [0f32; F];
        for f in 0..F {
            out[f] = g[f] * w;
        }
        Some(out)
    }

    /// Output width `L·F`.
    pub fn output_dim(&self) -> usize {
        self.levels.len() * F
    }

    pub fn entry_count(&self) -> usize {
        self.params.len() / F
    }

    /// Level `l`'s lattice: (`scale_l`, points per axis, table slots, whether it is dense).
    pub fn level_layout(&self, l: usize) -> (f32, u32, usize, bool) {
        let level = &self.levels[l];
        (level.scale, level.resolution, level.size, level.dense)
    }

    /// The slot (within level `l`, not offset) that lattice point `c` is stored in: the same
    /// index [`HashGrid::encode`] reads for that corner.
    pub fn lattice_slot(&self, l: usize, c: [u32; 3]) -> usize {
        let level = &self.levels[l];
        let r = level.resolution;
        let index = if level.dense {
            c[0].wrapping_add(c[1].wrapping_mul(r))
                .wrapping_add(c[2].wrapping_mul(r.wrapping_mul(r)))
        } else {
            c[0].wrapping_mul(PRIMES[0])
                ^ c[1].wrapping_mul(PRIMES[1])
                ^ c[2].wrapping_mul(PRIMES[2])
        } as usize;
        index % level.size
    }

    #[inline(always)]
    fn corners(&self, level: &Level, x: [f32; 3]) -> Corners {
        let mut cell = [0u32; 3];
        let mut frac = [0f32; 3];
        for d in 0..3 {
            // pos ≥ 0.5, so truncation is the floor (without a libm call on baseline x86-64).
            let pos = x[d].clamp(0.0, 1.0) * level.scale + 0.5;
            cell[d] = pos as u32;
            frac[d] = pos - cell[d] as f32;
        }
        // Per axis, the lattice coordinate's contribution to the index and the trilinear
        // factor for the low (bit 0) and high (bit 1) corner.
        let r = level.resolution;
        let stride = if level.dense {
            [1, r, r.wrapping_mul(r)]
        } else {
            PRIMES
        };
        let mut term = [[0u32; 2]; 3];
        let mut factor = [[0f32; 2]; 3];
        for d in 0..3 {
            for bit in 0..2 {
                term[d][bit] = (cell[d] + bit as u32).wrapping_mul(stride[d]);
            }
            factor[d] = [1.0 - frac[d], frac[d]];
        }
        let mut entry = [0u32; 8];
        let mut weight = [0f32; 8];
        for k in 0..8 {
            let (b0, b1, b2) = (k & 1, (k >> 1) & 1, (k >> 2) & 1);
            weight[k] = factor[0][b0] * factor[1][b1] * factor[2][b2];
            let index = if level.dense {
                term[0][b0]
                    .wrapping_add(term[1][b1])
                    .wrapping_add(term[2][b2])
            } else {
                term[0][b0] ^ term[1][b1] ^ term[2][b2]
            };
            // Same as `index % size`, without a division on the hot path: dense indices are
            // in range except the clamped far corner, hashed levels have power-of-two sizes.
            let index = index as usize;
            let slot = if index < level.size {
                index
            } else if level.size.is_power_of_two() {
                index & (level.size - 1)
            } else {
                index % level.size
            };
            entry[k] = (level.offset + slot) as u32;
        }
        Corners {
            entry,
            weight,
            frac,
        }
    }

    /// Encode `x` ∈ \[0,1\]³ into `out` (length `L·F`). Every level's corners are found before
    /// any is read, so the table reads (random, into tens of megabytes) are independent loads
    /// the processor overlaps instead of each waiting behind the next level's arithmetic.
    pub fn encode(&self, x: [f32; 3], out: &mut [f32]) {
        encode_wide(self, x, out)
    }

    /// Accumulate d(loss)/d(entries) for one point given d(loss)/d(encoding).
    pub fn backward(&self, x: [f32; 3], d_out: &[f32], grad: &mut SparseGrad) {
        for (l, level) in self.levels.iter().enumerate() {
            let Some(g) = self.level_grad(l, d_out) else {
                continue;
            };
            let c = self.corners(level, x);
            for k in 0..8 {
                let mut e = [0f32; F];
                for f in 0..F {
                    e[f] = c.weight[k] * g[f];
                }
                grad.entries.push((c.entry[k], e));
            }
        }
    }

    /// d(loss)/dx for one point given d(loss)/d(encoding): the spatial gradient through the
    /// trilinear weights (zero across cell boundaries' kinks, as for any trilinear field).
    pub fn grad_x(&self, x: [f32; 3], d_out: &[f32]) -> [f32; 3] {
        self.backward_and_grad_x(x, d_out, None::<&mut SparseGrad>, None)
    }

    /// [`HashGrid::backward`] and [`HashGrid::grad_x`] in one pass over the corners (the hot
    /// path of every ray sample's backward pass); corners first, as in [`HashGrid::encode`].
    /// `spatial_levels` limits the spatial gradient to the coarsest levels
    /// ([`HashGrid::spatial_weight`]; `None`: all) while the table gradient takes every open
    /// level: a pose then follows the scene's coarse shape while the scene learns its detail.
    pub fn backward_and_grad_x<G: GradSink>(
        &self,
        x: [f32; 3],
        d_out: &[f32],
        grad: Option<&mut G>,
        spatial_levels: Option<f32>,
    ) -> [f32; 3] {
        backward_wide(self, x, d_out, grad, spatial_levels)
    }
}

dispatch_wide! {
    fn encode_wide(grid: &HashGrid, x: [f32; 3], out: &mut [f32]) -> () => encode_inner
}

dispatch_wide! {
    fn backward_wide<G: GradSink>(
        grid: &HashGrid,
        x: [f32; 3],
        d_out: &[f32],
        grad: Option<&mut G>,
        spatial_levels: Option<f32>,
    ) -> [f32; 3] => backward_inner
}

#[inline(always)]
fn encode_inner<const WIDE: bool>(grid: &HashGrid, x: [f32; 3], out: &mut [f32]) {
    let near = super::grad_sink::accumulator_near(&grid.params);
    for (chunk, levels) in grid.levels.chunks(LEVEL_CHUNK).enumerate() {
        let first = chunk * LEVEL_CHUNK;
        let mut corners = [Corners::default(); LEVEL_CHUNK];
        for (j, level) in levels.iter().enumerate() {
            if grid.level_weights[first + j] != 0.0 {
                corners[j] = grid.corners(level, x);
            }
        }
        for (j, c) in corners[..levels.len()].iter().enumerate() {
            let l = first + j;
            let w = grid.level_weights[l];
            if w == 0.0 {
                out[l * F..(l + 1) * F].fill(0.0);
                continue;
            }
            if let Some(near) = near {
                super::grad_sink::prefetch_slots(near, &c.entry);
            }
            let mut acc = [0f32; F];
            for k in 0..8 {
                let base = c.entry[k] as usize * F;
                for f in 0..F {
                    acc[f] += c.weight[k] * grid.params[base + f];
                }
            }
            for f in 0..F {
                out[l * F + f] = w * acc[f];
            }
        }
    }
}

#[inline(always)]
fn backward_inner<const WIDE: bool, G: GradSink>(
    grid: &HashGrid,
    x: [f32; 3],
    d_out: &[f32],
    mut grad: Option<&mut G>,
    spatial_levels: Option<f32>,
) -> [f32; 3] {
    let mut gx = [0f32; 3];
    for (chunk, levels) in grid.levels.chunks(LEVEL_CHUNK).enumerate() {
        let first = chunk * LEVEL_CHUNK;
        let mut work = [(Corners::default(), [0f32; F], 0f32); LEVEL_CHUNK];
        let mut n = 0;
        for (j, level) in levels.iter().enumerate() {
            if let Some(g) = grid.level_grad(first + j, d_out) {
                let spatial = HashGrid::spatial_weight(spatial_levels, first + j);
                work[n] = (grid.corners(level, x), g, level.scale * spatial);
                n += 1;
            }
        }
        // The table-gradient scatter of every level, then the spatial gradient's reads:
        // two runs of independent memory accesses.
        if let Some(grad) = grad.as_deref_mut() {
            for (c, g, _) in &work[..n] {
                for k in 0..8 {
                    let mut e = [0f32; F];
                    for f in 0..F {
                        e[f] = c.weight[k] * g[f];
                    }
                    grad.add(c.entry[k], e);
                }
            }
        }
        for (c, g, scale) in &work[..n] {
            if *scale == 0.0 {
                continue;
            }
            let mut v = [0f32; 8];
            for (k, v) in v.iter_mut().enumerate() {
                let base = c.entry[k] as usize * F;
                for f in 0..F {
                    *v += g[f] * grid.params[base + f];
                }
            }
            let d = trilinear_gradient(&v, c.frac);
            for (gx, d) in gx.iter_mut().zip(d) {
                *gx += scale * d;
            }
        }
    }
    gx
}

/// ∂/∂frac of the trilinear blend of the corner values `v` (corner `k`: bit 0 the x step,
/// bit 1 y, bit 2 z): along each axis, the four edges' differences weighted by the bilinear
/// weights across the other two.
#[inline(always)]
fn trilinear_gradient(v: &[f32; 8], [fx, fy, fz]: [f32; 3]) -> [f32; 3] {
    let (ox, oy, oz) = (1.0 - fx, 1.0 - fy, 1.0 - fz);
    [
        oy * oz * (v[1] - v[0])
            + fy * oz * (v[3] - v[2])
            + oy * fz * (v[5] - v[4])
            + fy * fz * (v[7] - v[6]),
        ox * oz * (v[2] - v[0])
            + fx * oz * (v[3] - v[1])
            + ox * fz * (v[6] - v[4])
            + fx * fz * (v[7] - v[5]),
        ox * oy * (v[4] - v[0])
            + fx * oy * (v[5] - v[1])
            + ox * fy * (v[6] - v[2])
            + fx * fy * (v[7] - v[3]),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> HashGrid {
        let mut g = HashGrid::new(
            HashGridConfig {
                levels: 4,
                log2_table_size: 10,
                base_resolution: 4.0,
                max_resolution: 64.0,
            },
            3,
        );
        // Larger values than the init so finite differences are well above f32 noise.
        for (i, p) in g.params.iter_mut().enumerate() {
            *p = ((i as f32 * 0.618).fract() - 0.5) * 2.0;
        }
        g
    }

    #[test]
    fn lattice_slots_are_the_entries_encode_reads() {
        let g = small();
        for l in 0..g.levels.len() {
            let level = &g.levels[l];
            for x in [[0.1f32, 0.7, 0.3], [0.93, 0.02, 0.5], [0.5, 0.5, 0.999]] {
                let c = g.corners(level, x);
                let cell = x.map(|v| (v * level.scale + 0.5) as u32);
                for k in 0..8 {
                    let corner = [
                        cell[0] + (k & 1),
                        cell[1] + ((k >> 1) & 1),
                        cell[2] + ((k >> 2) & 1),
                    ];
                    assert_eq!(
                        c.entry[k as usize] as usize,
                        level.offset + g.lattice_slot(l, corner)
                    );
                }
            }
        }
    }

    #[test]
    fn levels_follow_the_tcnn_layout() {
        let g = HashGrid::new(HashGridConfig::default(), 0);
        assert_eq!(g.levels.len(), 16);
        assert_eq!(g.levels[0].resolution, 16);
        assert!(g.levels[0].dense && !g.levels[15].dense);
        assert!(
            g.levels
                .iter()
                .all(|l| l.size <= 1 << 19 && l.size % 8 == 0)
        );
        assert!((g.levels[15].scale - 4095.0).abs() < 1.0);
        assert!(g.params.iter().all(|p| p.abs() <= 1e-4));
    }

    #[test]
    fn interpolation_reproduces_corner_values_and_is_linear_between() {
        let g = small();
        let mut a = vec![0.0; g.output_dim()];
        g.encode([0.3, 0.6, 0.2], &mut a);
        // Along one axis within a cell of the coarsest level the output is affine in x.
        let level = &g.levels[0];
        let h = 0.1 / level.scale;
        let (mut l, mut m, mut r) = (vec![0.0; 8], vec![0.0; 8], vec![0.0; 8]);
        g.encode([0.30 - h, 0.6, 0.2], &mut l);
        g.encode([0.30, 0.6, 0.2], &mut m);
        g.encode([0.30 + h, 0.6, 0.2], &mut r);
        assert!((l[0] + r[0] - 2.0 * m[0]).abs() < 1e-4);
    }

    #[test]
    fn backward_matches_finite_differences() {
        let mut g = small();
        let x = [0.37, 0.52, 0.81];
        let w: Vec<f32> = (0..g.output_dim()).map(|i| 0.3 + 0.1 * i as f32).collect();
        let loss = |g: &HashGrid| {
            let mut out = vec![0.0; g.output_dim()];
            g.encode(x, &mut out);
            out.iter().zip(&w).map(|(a, b)| a * b).sum::<f32>()
        };
        let mut grad = SparseGrad::default();
        g.backward(x, &w, &mut grad);
        grad.merge();
        assert!(!grad.entries.is_empty());
        for &(entry, ge) in grad.entries.iter().step_by(3) {
            for f in 0..F {
                let i = entry as usize * F + f;
                let p0 = g.params[i];
                let eps = 1e-2;
                g.params[i] = p0 + eps;
                let up = loss(&g);
                g.params[i] = p0 - eps;
                let down = loss(&g);
                g.params[i] = p0;
                let fd = (up - down) / (2.0 * eps);
                assert!(
                    (fd - ge[f]).abs() < 1e-3 * (1.0 + fd.abs()),
                    "entry {entry}: {fd} vs {}",
                    ge[f]
                );
            }
        }
    }

    /// Coarse-to-fine weights: closed levels give zeros and no gradient, a half-open level
    /// scales both its features and their gradients.
    #[test]
    fn level_weights_scale_features_and_gradients() {
        let mut grid = small();
        let x = [0.31, 0.52, 0.77];
        let mut full = vec![0.0; grid.output_dim()];
        grid.encode(x, &mut full);
        grid.set_active_levels(1.5);
        let mut part = vec![0.0; grid.output_dim()];
        grid.encode(x, &mut part);
        assert_eq!(&part[..F], &full[..F]);
        assert!((part[F] - 0.5 * full[F]).abs() < 1e-7);
        assert!(part[2 * F..].iter().all(|v| *v == 0.0));
        let d_out = vec![1.0; grid.output_dim()];
        let mut g = SparseGrad::default();
        grid.backward(x, &d_out, &mut g);
        // Two open levels × 8 corners, the second at half weight.
        assert_eq!(g.entries.len(), 16);
        // Trilinear weights sum to one: level 0 passes the gradient whole, level 1 half.
        let sum = |es: &[(u32, [f32; F])]| es.iter().map(|(_, e)| e[0]).sum::<f32>();
        assert!((sum(&g.entries[..8]) - 1.0).abs() < 1e-6);
        assert!((sum(&g.entries[8..]) - 0.5).abs() < 1e-6);
        grid.set_active_levels(100.0);
        let mut again = vec![0.0; grid.output_dim()];
        grid.encode(x, &mut again);
        assert_eq!(again, full);
    }

    #[test]
    fn spatial_gradient_matches_finite_differences() {
        let g = small();
        let w: Vec<f32> = (0..g.output_dim()).map(|i| 1.0 - 0.07 * i as f32).collect();
        let f = |x: [f32; 3]| {
            let mut out = vec![0.0; g.output_dim()];
            g.encode(x, &mut out);
            out.iter().zip(&w).map(|(a, b)| a * b).sum::<f32>()
        };
        for x in [[0.31, 0.47, 0.73], [0.62, 0.18, 0.44]] {
            let gx = g.grad_x(x, &w);
            for d in 0..3 {
                // A step far smaller than the finest cell (1/64) stays inside one cell.
                let eps = 2e-4;
                let mut up = x;
                up[d] += eps;
                let mut down = x;
                down[d] -= eps;
                let fd = (f(up) - f(down)) / (2.0 * eps);
                assert!(
                    (fd - gx[d]).abs() < 2e-2 * (1.0 + fd.abs()),
                    "d{d}: {fd} vs {}",
                    gx[d]
                );
            }
        }
    }

    /// A spatial gradient over the coarsest levels only is the sum of those levels' own
    /// spatial gradients (each from a `d_out` that is zero elsewhere), a half-counted level
    /// adding half of its own; the table gradient is the same whatever the spatial levels.
    #[test]
    fn spatial_levels_limit_the_spatial_gradient_alone() {
        let g = small();
        let x = [0.41, 0.27, 0.66];
        let w: Vec<f32> = (0..g.output_dim()).map(|i| 0.5 + 0.11 * i as f32).collect();
        let per_level: Vec<[f32; 3]> = (0..g.levels.len())
            .map(|l| {
                let mut only = vec![0.0; w.len()];
                only[l * F..(l + 1) * F].copy_from_slice(&w[l * F..(l + 1) * F]);
                g.grad_x(x, &only)
            })
            .collect();
        let mut full = SparseGrad::default();
        let all = g.backward_and_grad_x(x, &w, Some(&mut full), None);
        for (levels, expected_weights) in [(0.0, [0.0; 4]), (1.5, [1.0, 0.5, 0.0, 0.0])] {
            let mut table = SparseGrad::default();
            let gx = g.backward_and_grad_x(x, &w, Some(&mut table), Some(levels));
            assert_eq!(table.entries, full.entries);
            for d in 0..3 {
                let expected: f32 = per_level
                    .iter()
                    .zip(expected_weights)
                    .map(|(p, k)| k * p[d])
                    .sum();
                assert!((gx[d] - expected).abs() < 1e-5 * (1.0 + expected.abs()));
            }
        }
        let capped = g.backward_and_grad_x(x, &w, None::<&mut SparseGrad>, Some(100.0));
        assert_eq!(capped, all);
        assert!(all.iter().any(|v| v.abs() > 1e-3));
    }
}
