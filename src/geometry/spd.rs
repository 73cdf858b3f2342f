//! Symmetric matrices: positive definite linear systems by Cholesky (the 6 × 6 normal equations
//! of ICP and of UniCal's LiDAR pose steps, the larger ones of pose graphs) and eigen-systems
//! by cyclic Jacobi rotations (essential matrices, homographies).

/// Solve `A x = b` for a symmetric positive definite `A` (n × n, row-major, `a.len() == n²`).
/// `None` when `A` is not positive definite (to rounding) or the sizes disagree.
pub fn solve(a: &[f64], b: &[f64]) -> Option<Vec<f64>> {
    let n = b.len();
    if a.len() != n * n {
        return None;
    }
    let mut l = vec![0.0f64; n * n];
    for i in 0..n {
        for j in 0..=i {
            let sum: f64 = (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum();
            if i == j {
                let d = a[i * n + i] - sum;
                if d.is_nan() || d <= 1e-12 {
                    return None;
                }
                l[i * n + i] = d.sqrt();
            } else {
                l[i * n + j] = (a[i * n + j] - sum) / l[j * n + j];
            }
        }
    }
    let mut y = vec![0.0f64; n];
    for i in 0..n {
        let sum: f64 = (0..i).map(|k| l[i * n + k] * y[k]).sum();
        y[i] = (b[i] - sum) / l[i * n + i];
    }
    let mut x = vec![0.0f64; n];
    for i in (0..n).rev() {
        let sum: f64 = (i + 1..n).map(|k| l[k * n + i] * x[k]).sum();
        x[i] = (y[i] - sum) / l[i * n + i];
    }
    Some(x)
}

/// [`solve`] for the 6 × 6 systems of rigid-body steps.
pub fn solve6(a: [f64; 36], b: [f64; 6]) -> Option<[f64; 6]> {
    let x = solve(&a, &b)?;
    let mut out = [0.0; 6];
    out.copy_from_slice(&x);
    Some(out)
}

/// Eigenvalues and eigenvectors (columns) of a symmetric matrix by cyclic Jacobi rotations.
pub fn symmetric_eigen<const N: usize>(mut a: [[f64; N]; N]) -> ([f64; N], [[f64; N]; N]) {
    let mut v = [[0.0; N]; N];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..60 {
        let off: f64 = (0..N)
            .flat_map(|i| (0..N).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        if off < 1e-30 {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..N {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..N {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in v.iter_mut() {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut values = [0.0; N];
    for (i, val) in values.iter_mut().enumerate() {
        *val = a[i][i];
    }
    (values, v)
}

/// The inverse of a symmetric 6 × 6 information `h` on its observed directions (eigenvalues
/// above `floor` times the largest), the axes an unobserved direction touches (a component
/// over 0.3), and the largest eigenvalue.
pub fn observed_inverse(h: [[f64; 6]; 6], floor: f64) -> ([[f64; 6]; 6], [bool; 6], f64) {
    let (values, vectors) = symmetric_eigen(h);
    let largest = values.iter().cloned().fold(0.0f64, f64::max);
    let mut unobserved = [false; 6];
    let mut inv = [[0.0; 6]; 6];
    for e in 0..6 {
        let v: [f64; 6] = std::array::from_fn(|r| vectors[r][e]);
        if largest > 0.0 && values[e] > floor * largest {
            for r in 0..6 {
                for c in 0..6 {
                    inv[r][c] += v[r] * v[c] / values[e];
                }
            }
        } else {
            for (axis, x) in v.iter().enumerate() {
                if x.abs() > 0.3 {
                    unobserved[axis] = true;
                }
            }
        }
    }
    (inv, unobserved, largest)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_known_system_and_refuses_an_indefinite_one() {
        // A = M Mᵀ + I for a fixed M; x known, b = A x.
        let n = 5;
        let m: Vec<f64> = (0..n * n)
            .map(|i| ((i * 7 + 3) % 11) as f64 - 5.0)
            .collect();
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                a[i * n + j] = (0..n).map(|k| m[i * n + k] * m[j * n + k]).sum::<f64>()
                    + if i == j { 1.0 } else { 0.0 };
            }
        }
        let x: Vec<f64> = (0..n).map(|i| i as f64 - 1.5).collect();
        let b: Vec<f64> = (0..n)
            .map(|i| (0..n).map(|j| a[i * n + j] * x[j]).sum())
            .collect();
        let solved = solve(&a, &b).unwrap_or_default();
        assert_eq!(solved.len(), n);
        for (s, e) in solved.iter().zip(&x) {
            assert!((s - e).abs() < 1e-9, "{s} vs {e}");
        }
        assert!(solve(&[1.0, 2.0, 2.0, 1.0], &[1.0, 1.0]).is_none());
        assert!(solve(&[1.0, 0.0, 0.0], &[1.0, 1.0]).is_none());
        assert!(solve6([0.0; 36], [1.0; 6]).is_none());
    }

    #[test]
    fn jacobi_diagonalises_a_symmetric_matrix() {
        let a = [[4.0, 1.0, 2.0], [1.0, 3.0, 0.5], [2.0, 0.5, 5.0]];
        let (values, v) = symmetric_eigen(a);
        for k in 0..3 {
            for i in 0..3 {
                let av: f64 = (0..3).map(|j| a[i][j] * v[j][k]).sum();
                assert!((av - values[k] * v[i][k]).abs() < 1e-10);
            }
        }
    }
}
