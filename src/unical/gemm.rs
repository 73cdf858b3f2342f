//! Small dense matrix products for the networks' batched passes ([`super::mlp`]), compiled for
//! the best instruction set the CPU has (AVX-512 or AVX2 with FMA, chosen once at run time as
//! the simulator's kernels are: [`crate::sim::wide`]).
//!
//! How it works. `C (m×p) += A (m×k) · B (k×p)` with B and C row-major and A read through two
//! strides, so that `Aᵀ` costs no copy (the weight gradient reads the output gradient
//! transposed). Blocks of six rows of C by sixteen columns are held in registers while `k` runs:
//! each step loads one row segment of B and broadcasts one element of A per row, so a loaded
//! vector feeds six fused multiply-adds, enough independent chains to hide their latency. Rows
//! left over after the last whole block go one at a time, columns past the last whole sixteen
//! through a plain loop. The wide copies use fused multiply-adds, the
//! baseline copy a multiply and an add: results differ in the last bits between instruction
//! sets but not between runs on one machine.

use crate::sim::wide::dispatch_wide;

/// Rows of C per register block: with [`LANES`] columns, six AVX-512 accumulators or twelve
/// AVX2 ones, enough independent chains to hide the multiply-add latency.
const ROWS: usize = 6;
/// Columns of C per register block (one AVX-512 vector, two AVX2 ones).
const LANES: usize = 16;

/// The shape of `C (m×p) += A (m×k) · B (k×p)` and how A is laid out: element (r, j) of A is
/// `a[r·a_row + j·a_col]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shape {
    pub m: usize,
    pub k: usize,
    pub p: usize,
    pub a_row: usize,
    pub a_col: usize,
}

impl Shape {
    /// A row-major `m × k` A.
    pub fn row_major(m: usize, k: usize, p: usize) -> Self {
        Self {
            m,
            k,
            p,
            a_row: k,
            a_col: 1,
        }
    }

    /// A stored transposed: A = Sᵀ with S row-major `k × m`.
    pub fn transposed(m: usize, k: usize, p: usize) -> Self {
        Self {
            m,
            k,
            p,
            a_row: 1,
            a_col: m,
        }
    }
}

dispatch_wide! {
    /// `c += A · b` for the [`Shape`] (b row-major `k × p`, c row-major `m × p`).
    pub fn gemm_acc(shape: Shape, a: &[f32], b: &[f32], c: &mut [f32]) -> () => gemm_inner
}

#[inline(always)]
fn fma<const WIDE: bool>(x: f32, y: f32, z: f32) -> f32 {
    if WIDE { x.mul_add(y, z) } else { x * y + z }
}

#[inline(always)]
fn gemm_inner<const WIDE: bool>(shape: Shape, a: &[f32], b: &[f32], c: &mut [f32]) {
    let Shape { m, k, p, .. } = shape;
    if m == 0 || p == 0 || k == 0 {
        return;
    }
    let (b, c) = (&b[..k * p], &mut c[..m * p]);
    let whole = m / ROWS * ROWS;
    for r0 in (0..whole).step_by(ROWS) {
        rows_of_c::<WIDE, ROWS>(shape, a, b, r0, &mut c[r0 * p..(r0 + ROWS) * p]);
    }
    for r0 in whole..m {
        rows_of_c::<WIDE, 1>(shape, a, b, r0, &mut c[r0 * p..(r0 + 1) * p]);
    }
}

/// Rows `r0..r0 + R` of C (`c_rows`), every column.
#[inline(always)]
fn rows_of_c<const WIDE: bool, const R: usize>(
    shape: Shape,
    a: &[f32],
    b: &[f32],
    r0: usize,
    c_rows: &mut [f32],
) {
    let Shape {
        k, p, a_row, a_col, ..
    } = shape;
    if a_col == 1 {
        // Row-major A: each row a slice of its own.
        let rows: [&[f32]; R] = std::array::from_fn(|r| &a[(r0 + r) * a_row..][..k]);
        let xs = (0..k).map(|j| std::array::from_fn(|r| rows[r][j]));
        columns::<WIDE, R>(xs, b, p, c_rows);
    } else if a_row == 1 {
        // Transposed A: the block's elements of one j side by side.
        let xs = a
            .chunks(a_col)
            .take(k)
            .map(|col| match col[r0..].first_chunk::<R>() {
                Some(x) => *x,
                None => [0.0; R],
            });
        columns::<WIDE, R>(xs, b, p, c_rows);
    } else {
        let xs = (0..k).map(|j| std::array::from_fn(|r| a[(r0 + r) * a_row + j * a_col]));
        columns::<WIDE, R>(xs, b, p, c_rows);
    }
}

/// Every column block of R rows of C, with `xs` yielding A's R elements for each j in turn.
#[inline(always)]
fn columns<const WIDE: bool, const R: usize>(
    xs: impl Iterator<Item = [f32; R]> + Clone,
    b: &[f32],
    p: usize,
    c_rows: &mut [f32],
) {
    let mut l0 = 0;
    while l0 + LANES <= p {
        let mut acc = [[0f32; LANES]; R];
        for (r, row) in acc.iter_mut().enumerate() {
            row.copy_from_slice(&c_rows[r * p + l0..][..LANES]);
        }
        for (x, b_row) in xs.clone().zip(b.chunks_exact(p)) {
            let Some(b_seg) = b_row[l0..].first_chunk::<LANES>() else {
                break;
            };
            for r in 0..R {
                for l in 0..LANES {
                    acc[r][l] = fma::<WIDE>(x[r], b_seg[l], acc[r][l]);
                }
            }
        }
        for (r, row) in acc.iter().enumerate() {
            c_rows[r * p + l0..][..LANES].copy_from_slice(row);
        }
        l0 += LANES;
    }
    if l0 < p {
        for (r, c_row) in c_rows.chunks_exact_mut(p).enumerate().take(R) {
            let c_seg = &mut c_row[l0..];
            for (x, b_row) in xs.clone().zip(b.chunks_exact(p)) {
                for (o, w) in c_seg.iter_mut().zip(&b_row[l0..]) {
                    *o = fma::<WIDE>(x[r], *w, *o);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive(shape: Shape, a: &[f32], b: &[f32], c: &mut [f32]) {
        for r in 0..shape.m {
            for l in 0..shape.p {
                let mut s = c[r * shape.p + l] as f64;
                for j in 0..shape.k {
                    s += a[r * shape.a_row + j * shape.a_col] as f64 * b[j * shape.p + l] as f64;
                }
                c[r * shape.p + l] = s as f32;
            }
        }
    }

    fn values(n: usize, seed: u32) -> Vec<f32> {
        (0..n)
            .map(|i| ((i as u32).wrapping_mul(2_654_435_761) ^ seed) as f32 / u32::MAX as f32 - 0.5)
            .collect()
    }

    /// Every block shape (whole, ragged rows, ragged columns, both), row-major and transposed
    /// A, accumulating onto a non-zero C: the same as a plain triple loop in f64.
    #[test]
    fn products_match_a_plain_triple_loop() {
        for (m, k, p) in [
            (1, 1, 1),
            (4, 32, 64),
            (7, 5, 3),
            (9, 64, 16),
            (13, 17, 33),
            (64, 3, 20),
        ] {
            for transposed in [false, true] {
                let shape = if transposed {
                    Shape::transposed(m, k, p)
                } else {
                    Shape::row_major(m, k, p)
                };
                let a = values(m * k, 1);
                let b = values(k * p, 2);
                let mut got = values(m * p, 3);
                let mut want = got.clone();
                gemm_acc(shape, &a, &b, &mut got);
                naive(shape, &a, &b, &mut want);
                for (g, w) in got.iter().zip(&want) {
                    assert!(
                        (g - w).abs() < 1e-5 * (1.0 + k as f32),
                        "{m}×{k}×{p}: {g} vs {w}"
                    );
                }
            }
        }
    }
}
