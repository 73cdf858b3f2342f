//! Where a hash grid's backward pass puts its table gradients: a list of (entry, gradient) pairs
//! ([`SparseGrad`]) for tests and small jobs, or, on the hot path, a dense per-thread
//! [`GradAccumulator`] reached through a [`Scaled`] sink.
//!
//! How it works. A step's rays are split into one chunk per thread; each chunk scatters into its
//! own accumulator (no locks, no list of millions of pairs), marking the blocks it touched, and
//! [`super::adam::SparseAdam::step_accumulated`] reads and clears the touched blocks of all of
//! them in index order, so the sum is the same whatever the threads did. The scatter is a
//! read-modify-write of lines spread over tens of megabytes; while a [`Scaled`] sink lives, the
//! grid's encode prefetches the slots it will add into (docs/experiments/unical-throughput.md,
//! "Prefetching the accumulator from the encode").

use std::cell::Cell;
use std::marker::PhantomData;

use super::hash_grid::{F, HashGrid};

/// Gradients of a batch with respect to table entries: (entry, dL/d features), unsorted, with
/// repeats. [`SparseGrad::merge`] sums repeats.
#[derive(Clone, Debug, Default)]
pub struct SparseGrad {
    pub entries: Vec<(u32, [f32; F])>,
}

impl SparseGrad {
    /// Sum repeated entries (sorted by entry).
    pub fn merge(&mut self) {
        self.entries.sort_unstable_by_key(|e| e.0);
        let mut out: Vec<(u32, [f32; F])> = Vec::with_capacity(self.entries.len());
        for &(i, g) in &self.entries {
            match out.last_mut() {
                Some(last) if last.0 == i => {
                    for f in 0..F {
                        last.1[f] += g[f];
                    }
                }
                _ => out.push((i, g)),
            }
        }
        self.entries = out;
    }

    pub fn append(&mut self, other: &mut SparseGrad) {
        self.entries.append(&mut other.entries);
    }
}

/// Where a backward pass puts hash-table gradients: a list of (entry, gradient) pairs
/// ([`SparseGrad`]) or, on the hot path, straight into a dense accumulator ([`Scaled`]).
pub trait GradSink {
    fn add(&mut self, entry: u32, g: [f32; F]);
}

impl GradSink for SparseGrad {
    #[inline]
    fn add(&mut self, entry: u32, g: [f32; F]) {
        self.entries.push((entry, g));
    }
}

/// `None` discards (e.g. no background field to train).
impl<G: GradSink> GradSink for Option<G> {
    #[inline]
    fn add(&mut self, entry: u32, g: [f32; F]) {
        if let Some(sink) = self {
            sink.add(entry, g);
        }
    }
}

/// Adds `scale ×` each gradient into a [`GradAccumulator`] as it is produced (one accumulator
/// per parallel chunk of rays, so no list of millions of pairs is built and re-read).
///
/// While it lives, the grid's encodes on this thread also prefetch the accumulator's slots of
/// the entries they read: the backward of the same ray, moments later,
/// then adds into lines already in cache instead of waiting for each from memory.
pub struct Scaled<'a> {
    acc: &'a mut GradAccumulator,
    scale: f32,
    table: usize,
    /// Registered on this thread, so dropped on it.
    _this_thread: PhantomData<*const ()>,
}

impl<'a> Scaled<'a> {
    /// A sink into `acc` for the gradients of `grid`'s table.
    pub fn new(grid: &HashGrid, acc: &'a mut GradAccumulator, scale: f32) -> Self {
        let table = grid.params.as_ptr() as usize;
        let slots = (acc.grad.as_ptr() as usize, acc.grad.len());
        NEAR.with(|near| {
            let mut pairs = near.get();
            // A free pair, else the second (two tables at most are trained together: the
            // scene's and the background's). The last sink of a table wins: dropping either of
            // two overlapping sinks ends the table's prefetching (lost hints, same results).
            let k = pairs
                .iter()
                .position(|p| p.0 == 0 || p.0 == table)
                .unwrap_or(1);
            pairs[k] = (table, slots.0, slots.1);
            near.set(pairs);
        });
        Self {
            acc,
            scale,
            table,
            _this_thread: PhantomData,
        }
    }
}

impl Drop for Scaled<'_> {
    fn drop(&mut self) {
        NEAR.with(|near| {
            let pairs = near
                .get()
                .map(|p| if p.0 == self.table { (0, 0, 0) } else { p });
            near.set(pairs);
        });
    }
}

impl GradSink for Scaled<'_> {
    #[inline]
    fn add(&mut self, entry: u32, g: [f32; F]) {
        self.acc.add_one(entry, g.map(|v| v * self.scale));
    }
}

thread_local! {
    /// The live [`Scaled`] sinks of this thread: (table address, accumulator address, its
    /// length in f32); a zero table address is a free pair.
    static NEAR: Cell<[(usize, usize, usize); 2]> = const { Cell::new([(0, 0, 0); 2]) };
}

/// The accumulator a live [`Scaled`] on this thread adds `table`'s gradients into, if any:
/// (address, length in f32). Looked up once per encoded point.
#[inline(always)]
pub(super) fn accumulator_near(table: &[f32]) -> Option<(usize, usize)> {
    let table = table.as_ptr() as usize;
    NEAR.with(|near| near.get().iter().find(|p| p.0 == table).map(|p| (p.1, p.2)))
}

/// Ask for the accumulator slots of `entries` (from [`accumulator_near`]) to be brought into
/// cache. A hint: no result changes, and nothing is read or written.
#[inline(always)]
#[allow(unsafe_code)]
pub(super) fn prefetch_slots((address, len): (usize, usize), entries: &[u32; 8]) {
    #[cfg(target_arch = "x86_64")]
    for &e in entries {
        let i = e as usize * F;
        if i < len {
            // SAFETY: `_mm_prefetch` reads and writes nothing and never faults, whatever the
            // address, and the pointer is formed with `wrapping_add`. The address is normally
            // in a live accumulator, but it may be stale (a leaked `Scaled`, a table reallocated
            // at the same address): then a useless hint, never a fault or a wrong result.
            unsafe {
                let p = (address as *const f32).wrapping_add(i) as *const i8;
                std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p);
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (address, len, entries);
}

/// Sums sparse gradients by scattering into a dense buffer (O(n), where sorting the millions of
/// (entry, gradient) pairs of a step was the step's largest cost), marking which blocks of
/// [`ACC_BLOCK`] entries were touched so only they are read back and cleared. Allocated once
/// per optimisation; [`super::adam::SparseAdam::step_accumulated`] reads and clears several in
/// one parallel pass in index order.
#[derive(Clone, Debug)]
pub struct GradAccumulator {
    grad: Vec<f32>,
    dirty: Vec<bool>,
}

/// Entries per dirty flag of a [`GradAccumulator`].
pub const ACC_BLOCK: usize = 64;

impl GradAccumulator {
    pub fn new(entries: usize) -> Self {
        Self {
            grad: super::table_memory::zeroed(entries * F),
            dirty: vec![false; entries.div_ceil(ACC_BLOCK)],
        }
    }

    /// Add `scale · g`.
    pub fn add(&mut self, g: &SparseGrad, scale: f32) {
        for &(entry, v) in &g.entries {
            self.add_one(entry, v.map(|x| x * scale));
        }
    }

    /// Add one entry's gradient.
    #[inline]
    pub fn add_one(&mut self, entry: u32, v: [f32; F]) {
        let e = entry as usize;
        let Some(slot) = self.grad.get_mut(e * F..e * F + F) else {
            return;
        };
        for f in 0..F {
            slot[f] += v[f];
        }
        self.dirty[e / ACC_BLOCK] = true;
    }

    /// Blocks of [`ACC_BLOCK`] entries: their gradients (`ACC_BLOCK · F` values) and whether
    /// any was touched, for a consumer that clears both.
    pub(crate) fn blocks_mut(&mut self) -> impl Iterator<Item = (&mut [f32], &mut bool)> {
        self.grad
            .chunks_mut(ACC_BLOCK * F)
            .zip(self.dirty.iter_mut())
    }

    /// Sum several accumulators (in order, so the result is deterministic) and empty them: the
    /// plain path [`super::adam::SparseAdam::step_accumulated`] fuses with the optimiser.
    pub fn drain_all(accs: &mut [GradAccumulator]) -> SparseGrad {
        let Some((first, rest)) = accs.split_first_mut() else {
            return SparseGrad::default();
        };
        for acc in rest {
            let g = acc.drain();
            first.add(&g, 1.0);
        }
        first.drain()
    }

    /// The summed gradient, in entry order: every entry of a touched block whose gradient is
    /// not zero (an entry whose contributions cancel exactly moves no optimiser either). The
    /// accumulator is empty afterwards.
    pub fn drain(&mut self) -> SparseGrad {
        let mut out = SparseGrad::default();
        for (block, (grads, dirty)) in self
            .grad
            .chunks_mut(ACC_BLOCK * F)
            .zip(self.dirty.iter_mut())
            .enumerate()
        {
            if !std::mem::take(dirty) {
                continue;
            }
            for (k, g) in grads.chunks_exact_mut(F).enumerate() {
                if g.iter().any(|v| *v != 0.0) {
                    let mut v = [0f32; F];
                    v.copy_from_slice(g);
                    g.fill(0.0);
                    out.entries.push(((block * ACC_BLOCK + k) as u32, v));
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accumulator_sums_like_merge() {
        let mut g = SparseGrad::default();
        for k in 0..200u32 {
            g.entries.push((k * 7 % 31, [k as f32, 1.0]));
        }
        let mut acc = GradAccumulator::new(40);
        acc.add(&g, 0.5);
        let mut a = acc.drain();
        a.entries.sort_unstable_by_key(|e| e.0);
        g.merge();
        assert_eq!(a.entries.len(), g.entries.len());
        for (x, y) in a.entries.iter().zip(&g.entries) {
            assert_eq!(x.0, y.0);
            assert!((x.1[0] - 0.5 * y.1[0]).abs() < 1e-3 && (x.1[1] - 0.5 * y.1[1]).abs() < 1e-6);
        }
        assert!(acc.drain().entries.is_empty());
    }

    /// A live sink registers its table's accumulator and a dropped one leaves no trace, so a
    /// later encode prefetches nothing stale; two tables' sinks live side by side.
    #[test]
    fn a_sink_registers_its_accumulator_while_it_lives() {
        let grid = HashGrid::new(
            crate::unical::hash_grid::HashGridConfig {
                levels: 4,
                log2_table_size: 10,
                ..Default::default()
            },
            1,
        );
        let other = HashGrid::new(
            crate::unical::hash_grid::HashGridConfig {
                levels: 2,
                log2_table_size: 8,
                ..Default::default()
            },
            2,
        );
        let (mut a, mut b) = (GradAccumulator::new(64), GradAccumulator::new(32));
        let a_at = (a.grad.as_ptr() as usize, a.grad.len());
        let b_at = (b.grad.as_ptr() as usize, b.grad.len());
        assert_eq!(accumulator_near(&grid.params), None);
        {
            let mut sink = Scaled::new(&grid, &mut a, 0.5);
            let _background = Scaled::new(&other, &mut b, 1.0);
            assert_eq!(accumulator_near(&grid.params), Some(a_at));
            assert_eq!(accumulator_near(&other.params), Some(b_at));
            // Entries past the accumulator's end are skipped (this only shows it does not fault).
            prefetch_slots(a_at, &[0, 1, 2, 3, 60, 63, 64, 1 << 30]);
            sink.add(3, [2.0, 4.0]);
        }
        assert_eq!(accumulator_near(&grid.params), None);
        assert_eq!(accumulator_near(&other.params), None);
        assert_eq!(a.drain().entries, vec![(3, [1.0, 2.0])]);
    }
}
