//! Geometric verification of matches: RANSAC on the essential matrix of two calibrated views.
//!
//! Matches are unit rays in each camera's frame (the camera model has undistorted them), taken
//! to the normalised image plane `n = (x/z, y/z, 1)`. Eight matches give `E` by the linear
//! eight-point method (the eigenvector of `AᵀA` with the smallest eigenvalue, Jacobi
//! eigen-solver), projected onto essential matrices (two equal singular values, one zero).
//! Inliers have a Sampson distance below the threshold (normalised units: pixels / focal).

use glam::{DMat3, DVec3};

use crate::geometry::so3;

/// The verified essential matrix (`n_bᵀ E n_a = 0`) and the inlier mask.
#[derive(Clone, Debug, PartialEq)]
pub struct Verified {
    pub essential: DMat3,
    pub inliers: Vec<bool>,
}

/// RANSAC over `iterations` samples of eight; `None` if fewer than `min_inliers` agree.
pub fn verify(
    rays_a: &[DVec3],
    rays_b: &[DVec3],
    threshold: f64,
    iterations: usize,
    min_inliers: usize,
    seed: u64,
) -> Option<Verified> {
    let normalise = |r: &DVec3| (r.z > 0.05).then(|| *r / r.z);
    let pairs: Vec<(usize, DVec3, DVec3)> = rays_a
        .iter()
        .zip(rays_b)
        .enumerate()
        .filter_map(|(i, (a, b))| Some((i, normalise(a)?, normalise(b)?)))
        .collect();
    if pairs.len() < min_inliers.max(8) {
        return None;
    }
    let mut state = seed | 1;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let inliers_of = |e: &DMat3| -> Vec<bool> {
        pairs
            .iter()
            .map(|(_, a, b)| sampson_sq(e, *a, *b) < threshold * threshold)
            .collect()
    };
    let mut best: Option<(DMat3, Vec<bool>, usize)> = None;
    for _ in 0..iterations {
        let mut pick: Vec<usize> = Vec::with_capacity(8);
        while pick.len() < 8 {
            let k = (next() % pairs.len() as u64) as usize;
            if !pick.contains(&k) {
                pick.push(k);
            }
        }
        let sample: Vec<(DVec3, DVec3)> = pick.iter().map(|&k| (pairs[k].1, pairs[k].2)).collect();
        let Some(e) = eight_point(&sample) else {
            continue;
        };
        let mask = inliers_of(&e);
        let count = mask.iter().filter(|m| **m).count();
        if best.as_ref().is_none_or(|b| count > b.2) {
            best = Some((e, mask, count));
        }
    }
    let (e, mask, count) = best?;
    if count < min_inliers {
        return None;
    }
    // Refit on every inlier, keep it if it agrees with at least as many.
    let all: Vec<(DVec3, DVec3)> = pairs
        .iter()
        .zip(&mask)
        .filter(|(_, m)| **m)
        .map(|(p, _)| (p.1, p.2))
        .collect();
    let (e, mask) = match eight_point(&all) {
        Some(refit) => {
            let m2 = inliers_of(&refit);
            if m2.iter().filter(|m| **m).count() >= count {
                (refit, m2)
            } else {
                (e, mask)
            }
        }
        None => (e, mask),
    };
    let mut inliers = vec![false; rays_a.len()];
    for ((i, _, _), m) in pairs.iter().zip(mask) {
        inliers[*i] = m;
    }
    Some(Verified {
        essential: e,
        inliers,
    })
}

/// Squared Sampson distance of the pair (normalised image points) to `n_bᵀ E n_a = 0`.
pub fn sampson_sq(e: &DMat3, a: DVec3, b: DVec3) -> f64 {
    let ea = *e * a;
    let etb = e.transpose() * b;
    let num = b.dot(ea);
    let den = ea.x * ea.x + ea.y * ea.y + etb.x * etb.x + etb.y * etb.y;
    if den <= 0.0 {
        f64::INFINITY
    } else {
        num * num / den
    }
}

/// Linear eight-point estimate from ≥ 8 normalised pairs, projected to an essential matrix.
fn eight_point(pairs: &[(DVec3, DVec3)]) -> Option<DMat3> {
    let mut ata = [[0.0f64; 9]; 9];
    for (a, b) in pairs {
        let (a, b) = (a.to_array(), b.to_array());
        let mut row = [0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                row[3 * i + j] = b[i] * a[j];
            }
        }
        for r in 0..9 {
            for c in 0..9 {
                ata[r][c] += row[r] * row[c];
            }
        }
    }
    let (values, vectors) = crate::geometry::spd::symmetric_eigen(ata);
    let k = (0..9).min_by(|&i, &j| values[i].total_cmp(&values[j]))?;
    let e: Vec<f64> = (0..9).map(|r| vectors[r][k]).collect();
    // Row-major e → columns of the matrix.
    let m = DMat3::from_cols(
        DVec3::new(e[0], e[3], e[6]),
        DVec3::new(e[1], e[4], e[7]),
        DVec3::new(e[2], e[5], e[8]),
    );
    project_essential(m)
}

/// The nearest matrix with singular values (1, 1, 0): `u1 v1ᵀ + u2 v2ᵀ`.
fn project_essential(m: DMat3) -> Option<DMat3> {
    let mtm = m.transpose() * m;
    let arr = [
        [mtm.x_axis.x, mtm.y_axis.x, mtm.z_axis.x],
        [mtm.x_axis.y, mtm.y_axis.y, mtm.z_axis.y],
        [mtm.x_axis.z, mtm.y_axis.z, mtm.z_axis.z],
    ];
    let (values, vectors) = crate::geometry::spd::symmetric_eigen(arr);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| values[j].total_cmp(&values[i]));
    let mut out = DMat3::ZERO;
    for &k in &order[..2] {
        let v = DVec3::new(vectors[0][k], vectors[1][k], vectors[2][k]);
        let u = (m * v).try_normalize()?;
        out += so3::outer(u, v);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    fn skew(t: DVec3) -> DMat3 {
        DMat3::from_cols(
            DVec3::new(0.0, t.z, -t.y),
            DVec3::new(-t.z, 0.0, t.x),
            DVec3::new(t.y, -t.x, 0.0),
        )
    }

    #[test]
    fn ransac_recovers_the_true_essential_matrix_and_rejects_outliers() {
        // Camera b sees points of camera a's frame as x_b = R x_a + t: E = [t]× R.
        let rotation = DQuat::from_euler(glam::EulerRot::YXZ, 0.3, -0.1, 0.05);
        let t = DVec3::new(-1.2, 0.1, 0.3);
        let mut state = 12345u64;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut ra, mut rb, mut truth) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..200 {
            let p = DVec3::new(rnd() * 20.0 - 10.0, rnd() * 8.0 - 4.0, 5.0 + rnd() * 30.0);
            let q = rotation * p + t;
            if k % 4 == 3 {
                // An outlier: a random ray in b.
                let wrong = DVec3::new(rnd() - 0.5, rnd() - 0.5, 1.0);
                ra.push(p.normalize_or_zero());
                rb.push(wrong.normalize_or_zero());
                truth.push(false);
            } else {
                ra.push(p.normalize_or_zero());
                rb.push(q.normalize_or_zero());
                truth.push(true);
            }
        }
        let v = verify(&ra, &rb, 1e-3, 300, 20, 7).expect("verified");
        let agree = v.inliers.iter().zip(&truth).filter(|(a, b)| a == b).count();
        assert!(agree >= 196, "{agree} of 200 classified right");
        let want = skew(t) * glam::DMat3::from_quat(rotation);
        let scale =
            |m: DMat3| m * (1.0 / m.to_cols_array().iter().map(|v| v * v).sum::<f64>().sqrt());
        let (got, want) = (scale(v.essential), scale(want));
        let diff = (got - want)
            .to_cols_array()
            .iter()
            .map(|v| v.abs())
            .fold(0.0, f64::max);
        let flipped = (got + want)
            .to_cols_array()
            .iter()
            .map(|v| v.abs())
            .fold(0.0, f64::max);
        assert!(diff.min(flipped) < 5e-3, "{got:?} vs {want:?}");
        assert!(verify(&ra[..5], &rb[..5], 1e-3, 10, 20, 7).is_none());
    }
}
