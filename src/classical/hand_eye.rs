//! A camera's extrinsic from its own motion: hand-eye calibration against the vehicle's
//! trajectory, the initialiser for starts too far off for the neural scene (10° or a metre).
//!
//! How it works. Two images of one camera taken a few metres apart are matched (oriented FAST
//! and steered BRIEF, mutual nearest neighbours, ratio test) and verified by RANSAC on the
//! essential matrix ([`crate::features::epipolar`]), which is split into the camera's rotation
//! and the direction it moved in ([`relative_motion`]; of its four solutions the one that puts
//! the most matches in front of both cameras). The trajectory gives the vehicle's motion
//! between the two stamps. With `X = vehicle_from_camera`, `V = vehicle_i_from_vehicle_j` and
//! `C = camera_i_from_camera_j`, the rig is rigid, so `V X = X C`:
//!
//! - rotation: `R_V R_X = R_X R_C`, so the rotation vectors satisfy `ω_V = R_X ω_C`;
//! - translation: `R_X t_C = (R_V − I) p_X + t_V`, where the images give `t_C` only up to
//!   scale, so `R_X t̂_C` is parallel to `(R_V − I) p_X + t_V`.
//!
//! [`solve`] first alternates two closed-form steps. `R_X` is the rotation that best maps the
//! camera's rotation vectors and motion directions onto the vehicle's (Wahba's problem, by
//! Davenport's q-method; directions of pairs that turn count less, as they depend on `p_X`).
//! `p_X` is then linear: with `u = R_X t̂_C` and `P = I − u uᵀ`, `P (R_V − I) p_X = −P t_V`
//! for every pair, by least squares with a weak pull to the start. Pairs whose residual is far
//! above the median are dropped. Then `refine` fits all six parameters to every pair's
//! matches directly: each pair's predicted motion `X⁻¹ V X` gives an essential matrix, and the
//! matches' Sampson distances to it are minimised (Levenberg–Marquardt, Cauchy weights). A
//! scene that is mostly one façade leaves a free essential matrix ill-posed, not this one;
//! on the simulator it takes the cameras from 0.1–6° after the closed form to 0.03–0.36°.
//!
//! A drive that only turns about the vertical cannot observe the height (`(R_V − I)` has no
//! vertical row), and without the images' scale the sideways offset (vehicle y) is barely seen,
//! since a turn moves it along the drive, where only the unknown scale of the motion would show
//! it; such directions stay where they started and are named in [`HandEyeFit::unobserved`].

use glam::{DMat3, DQuat, DVec3};
use rayon::prelude::*;

use crate::features::epipolar::verify;
use crate::features::matching::match_mutual;
use crate::geometry::{Rigid, so3, spd};

/// Pairs of one camera's images whose vehicle poses are this far apart, at least (m): below it
/// the direction of motion drowns in the matching noise.
pub const MIN_BASELINE_M: f64 = 1.0;
/// At most this far apart (m): further, the views share too little.
pub const MAX_BASELINE_M: f64 = 8.0;
/// Verified matches a pair needs.
const MIN_INLIERS: usize = 30;
/// RANSAC inlier threshold on the Sampson distance (normalised image units, about 1 px at a
/// 1000 px focal length).
const RANSAC_THRESHOLD: f64 = 1.0e-3;
const RANSAC_ITERATIONS: usize = 400;
/// Weight of the pull to the start per unit of translation (against pairs whose `(R_V − I)`
/// entries are the turn in radians, 0.05–0.5).
const PRIOR_WEIGHT: f64 = 0.03;
/// A translation direction whose information is below this (per pair, in the closed form's
/// units) is reported as not observed (the refinement has its own, [`OBSERVED_RELATIVE`]).
const OBSERVED_INFORMATION: f64 = 2.0e-3;

/// One image pair of a camera: its motion seen in the images, the vehicle's from the trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionPair {
    /// `camera_i_from_camera_j`'s rotation, from the essential matrix.
    pub camera_rotation: DQuat,
    /// Where camera `j` sits seen from camera `i`, as a unit direction (the scale is unknown).
    pub camera_direction: DVec3,
    /// `vehicle_i_from_vehicle_j`, from the trajectory.
    pub vehicle_motion: Rigid,
    /// Up to [`RAYS_PER_PAIR`] of its verified matches, as unit rays in camera `i` and camera `j`.
    pub rays: Vec<(DVec3, DVec3)>,
    /// Which of the frames image `i` is ([`motion_pairs`] sets it; 0 from
    /// [`pair_from_keypoints`]).
    pub first_image: usize,
}

/// Matches per pair kept for the refinement.
pub const RAYS_PER_PAIR: usize = 150;

/// The camera's extrinsic that fits its motion, and how well.
#[derive(Clone, Debug, PartialEq)]
pub struct HandEyeFit {
    pub vehicle_from_camera: Rigid,
    /// Pairs the solve kept (after dropping outliers) and those it was given.
    pub pairs_used: usize,
    pub pairs_given: usize,
    /// Median disagreement of the kept pairs: rotation (degrees) and motion direction (degrees).
    pub rotation_residual_deg: f64,
    pub direction_residual_deg: f64,
    /// Translation directions of the vehicle frame the pairs did not observe (left at the
    /// start): some of "x", "y", "z".
    pub unobserved: Vec<&'static str>,
    /// The rotation's 1-σ about the camera's own x, y, z (degrees), cluster-robust over the
    /// pairs (infinite when the fit had no matches to refine on).
    pub rotation_sigma_deg: DVec3,
}

/// Why a camera could not be fitted.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum HandEyeError {
    #[error("only {found} image pairs with verified motion (at least {needed} needed)")]
    TooFewPairs { found: usize, needed: usize },
    #[error(
        "the vehicle turns at most {max_turn_deg:.1}° between paired images: its motion does not fix the camera's rotation"
    )]
    TooStraight { max_turn_deg: f64 },
}

/// How far off a camera's translation may be while its rotation is fitted (m).
const TRANSLATION_UNCERTAINTY_M: f64 = 0.5;
/// The images' own noise on a direction of motion (rad, about 0.5°).
const DIRECTION_NOISE_RAD: f64 = 0.0087;

/// Pairs a solve needs at least.
pub const MIN_PAIRS: usize = 4;
/// Largest turn between paired images (degrees) below which the rotation is not fixed.
const MIN_TURN_DEG: f64 = 3.0;

/// The camera's motion from matched rays (unit, in each camera's frame) of two images:
/// `camera_a_from_camera_b`'s rotation and the unit direction of camera `b` seen from `a`,
/// with the verified matches (`rays_a`, `rays_b`). `None` when RANSAC finds fewer than
/// `MIN_INLIERS` agreeing matches, or fewer lie in front of both cameras.
pub fn relative_motion(
    rays_a: &[DVec3],
    rays_b: &[DVec3],
    seed: u64,
) -> Option<(DQuat, DVec3, Vec<(DVec3, DVec3)>)> {
    let verified = verify(
        rays_a,
        rays_b,
        RANSAC_THRESHOLD,
        RANSAC_ITERATIONS,
        MIN_INLIERS,
        seed,
    )?;
    let inliers: Vec<(DVec3, DVec3)> = rays_a
        .iter()
        .zip(rays_b)
        .zip(&verified.inliers)
        .filter(|(_, keep)| **keep)
        .map(|((a, b), _)| (*a, *b))
        .collect();
    // `n_bᵀ E n_a = 0` with `E = [t]× R` for `x_b = R x_a + t` (b_from_a).
    let (rotation_b_from_a, t_b_from_a, in_front) = decompose(verified.essential, &inliers)?;
    if in_front < MIN_INLIERS {
        return None;
    }
    // a_from_b = (b_from_a)⁻¹: rotation Rᵀ, translation −Rᵀ t.
    let rotation_a_from_b = rotation_b_from_a.transpose();
    let direction = (-(rotation_a_from_b * t_b_from_a)).try_normalize()?;
    Some((
        so3::quat_from_matrix_orthonormalized(rotation_a_from_b),
        direction,
        inliers,
    ))
}

/// The four `(R, t)` of an essential matrix (`x_b = R x_a + t`, `|t| = 1`), and the one that
/// puts the most of `pairs` (rays a, rays b) in front of both cameras, with that count.
fn decompose(essential: DMat3, pairs: &[(DVec3, DVec3)]) -> Option<(DMat3, DVec3, usize)> {
    // SVD from the eigen-system of EᵀE: V its eigenvectors (largest first), U from E V.
    let ete = essential.transpose() * essential;
    let m = [
        [ete.x_axis.x, ete.y_axis.x, ete.z_axis.x],
        [ete.x_axis.y, ete.y_axis.y, ete.z_axis.y],
        [ete.x_axis.z, ete.y_axis.z, ete.z_axis.z],
    ];
    let (values, vectors) = spd::symmetric_eigen(m);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| values[j].total_cmp(&values[i]));
    let column = |k: usize| DVec3::new(vectors[0][k], vectors[1][k], vectors[2][k]);
    let (v1, v2) = (column(order[0]), column(order[1]));
    let v3 = v1.cross(v2);
    let u1 = (essential * v1).try_normalize()?;
    let u2 = (essential * v2).try_normalize()?;
    let u3 = u1.cross(u2);
    let u = DMat3::from_cols(u1, u2, u3);
    let v = DMat3::from_cols(v1, v2, v3);
    let w = DMat3::from_cols(DVec3::Y, -DVec3::X, DVec3::Z);
    let rotations = [u * w * v.transpose(), u * w.transpose() * v.transpose()];
    let mut best: Option<(DMat3, DVec3, usize)> = None;
    for r in rotations {
        for t in [u3, -u3] {
            let count = pairs.iter().filter(|(a, b)| in_front(r, t, *a, *b)).count();
            if best.as_ref().is_none_or(|b| count > b.2) {
                best = Some((r, t, count));
            }
        }
    }
    best
}

/// Whether the point seen along `a` (camera a) and `b` (camera b) triangulates in front of
/// both, for `x_b = R x_a + t`: least squares in `s_a R a + t = s_b b`.
fn in_front(r: DMat3, t: DVec3, a: DVec3, b: DVec3) -> bool {
    let ra = r * a;
    // Normal equations of [ra, −b] [s_a, s_b]ᵀ = −t.
    let (aa, ab, bb) = (ra.dot(ra), -ra.dot(b), b.dot(b));
    let (ra_t, b_t) = (-ra.dot(t), b.dot(t));
    let det = aa * bb - ab * ab;
    if det.abs() < 1e-12 {
        return false;
    }
    let s_a = (ra_t * bb - ab * b_t) / det;
    let s_b = (aa * b_t - ab * ra_t) / det;
    s_a > 0.0 && s_b > 0.0
}

/// The pair of one camera's images `i` and `j` from their keypoints (positions in pixels of
/// the image `unproject` takes) and the trajectory's `vehicle_i_from_vehicle_j`.
pub fn pair_from_keypoints(
    keypoints_i: &[crate::features::orb::Keypoint],
    keypoints_j: &[crate::features::orb::Keypoint],
    unproject: &(dyn Fn(f64, f64) -> Option<DVec3> + Sync),
    vehicle_i_from_vehicle_j: Rigid,
    seed: u64,
) -> Option<MotionPair> {
    let matches = match_mutual(keypoints_i, keypoints_j, 0.8, 64);
    let (rays_i, rays_j): (Vec<DVec3>, Vec<DVec3>) = matches
        .iter()
        .filter_map(|&(a, b)| {
            let (ka, kb) = (&keypoints_i[a], &keypoints_j[b]);
            Some((
                unproject(ka.x as f64, ka.y as f64)?,
                unproject(kb.x as f64, kb.y as f64)?,
            ))
        })
        .unzip();
    let (camera_rotation, camera_direction, verified) = relative_motion(&rays_i, &rays_j, seed)?;
    Some(MotionPair {
        camera_rotation,
        camera_direction,
        vehicle_motion: vehicle_i_from_vehicle_j,
        rays: crate::log::spread_evenly(&verified, RAYS_PER_PAIR),
        first_image: 0,
    })
}

/// The rotation `R` maximising `Σ w · target · (R source)` (Wahba's problem) by Davenport's
/// q-method: the eigenvector of the largest eigenvalue of a symmetric 4 × 4 matrix.
fn wahba(pairs: &[(DVec3, DVec3, f64)]) -> DQuat {
    // B = Σ w target sourceᵀ.
    let mut b = [[0.0f64; 3]; 3];
    for (target, source, w) in pairs {
        let (t, s) = (target.to_array(), source.to_array());
        for (i, row) in b.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x += w * t[i] * s[j];
            }
        }
    }
    let trace = b[0][0] + b[1][1] + b[2][2];
    let z = [b[1][2] - b[2][1], b[2][0] - b[0][2], b[0][1] - b[1][0]];
    let mut k = [[0.0f64; 4]; 4];
    for i in 0..3 {
        for j in 0..3 {
            k[i][j] = b[i][j] + b[j][i] - if i == j { trace } else { 0.0 };
        }
        k[i][3] = z[i];
        k[3][i] = z[i];
    }
    k[3][3] = trace;
    let (values, vectors) = spd::symmetric_eigen(k);
    let best = (0..4)
        .max_by(|&i, &j| values[i].total_cmp(&values[j]))
        .unwrap_or(0);
    let q = DQuat::from_xyzw(
        vectors[0][best],
        vectors[1][best],
        vectors[2][best],
        vectors[3][best],
    )
    .normalize();
    // The q-method's sign convention differs between texts: keep whichever of q and its
    // conjugate scores higher (they are the optimum and its inverse).
    let score = |r: DQuat| -> f64 { pairs.iter().map(|(t, s, w)| w * t.dot(r * *s)).sum::<f64>() };
    if score(q) >= score(q.conjugate()) {
        q
    } else {
        q.conjugate()
    }
}

/// Per pair: the rotation step's vector pairs (vehicle, camera, weight).
fn rotation_terms(pair: &MotionPair, translation: DVec3) -> Vec<(DVec3, DVec3, f64)> {
    let mut out = Vec::with_capacity(2);
    let omega_v = so3::log(pair.vehicle_motion.rotation);
    let omega_c = so3::log(pair.camera_rotation);
    let turn = omega_v.length();
    // Rotation axes: meaningful once the turn is well above the images' noise.
    let axis_weight = (turn / 5f64.to_radians()).min(1.0);
    if let (Some(v), Some(c)) = (omega_v.try_normalize(), omega_c.try_normalize()) {
        out.push((v, c, axis_weight));
    }
    // The vehicle-frame direction depends on the camera's translation through `(R_V − I) p`:
    // a pair that turns by θ over a baseline b moves it by up to θ · σ / b for a translation
    // known to σ, so turning pairs count less.
    if let Some(d) = motion_direction(pair, translation) {
        let baseline = pair.vehicle_motion.translation.length().max(1e-3);
        let spread_rad = turn * TRANSLATION_UNCERTAINTY_M / baseline;
        let w = 1.0 / (1.0 + (spread_rad / DIRECTION_NOISE_RAD).powi(2));
        out.push((d, pair.camera_direction, w));
    }
    out
}

/// The vehicle-frame direction camera `j` moved in, seen from camera `i`, for a camera at
/// `translation`: `(R_V − I) p + t_V`, normalised.
fn motion_direction(pair: &MotionPair, translation: DVec3) -> Option<DVec3> {
    let v = pair.vehicle_motion;
    (v.rotation * translation - translation + v.translation).try_normalize()
}

/// Residuals of one pair at `fit` (degrees): rotation, direction.
fn residuals(pair: &MotionPair, fit: Rigid) -> (f64, f64) {
    // C predicted = X⁻¹ V X.
    let predicted = fit.inverse() * pair.vehicle_motion * fit;
    let rotation = so3::angle_rad(predicted.rotation.inverse() * pair.camera_rotation).to_degrees();
    let direction = predicted.translation.try_normalize().map_or(180.0, |d| {
        d.dot(pair.camera_direction)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    });
    (rotation, direction)
}

/// The translation step: least squares in `p` of `P (R_V − I) p = −P t_V` over the pairs, with
/// a weak pull to `start`; returns the solution and the information (normal matrix) per pair.
fn solve_translation(
    pairs: &[MotionPair],
    rotation: DQuat,
    start: DVec3,
) -> (DVec3, [[f64; 3]; 3]) {
    let mut normal = [[0.0f64; 3]; 3];
    let mut rhs = [0.0f64; 3];
    for pair in pairs {
        let u = rotation * pair.camera_direction;
        let project = DMat3::IDENTITY - so3::outer(u, u);
        let a = project * (DMat3::from_quat(pair.vehicle_motion.rotation) - DMat3::IDENTITY);
        let b = -(project * pair.vehicle_motion.translation);
        // Normal equations: AᵀA p = Aᵀ b (glam matrices are column-major: row i of A is
        // (a.x_axis[i], a.y_axis[i], a.z_axis[i])).
        let at = a.transpose();
        let ata = at * a;
        let atb = at * b;
        for i in 0..3 {
            for j in 0..3 {
                normal[i][j] += ata.col(j)[i];
            }
            rhs[i] += atb[i];
        }
    }
    let information = normal;
    let n = pairs.len().max(1) as f64;
    let prior = PRIOR_WEIGHT * PRIOR_WEIGHT * n;
    let mut a = Vec::with_capacity(9);
    for (i, row) in normal.iter().enumerate() {
        for (j, x) in row.iter().enumerate() {
            a.push(x + if i == j { prior } else { 0.0 });
        }
    }
    let b: Vec<f64> = (0..3).map(|i| rhs[i] + prior * start[i]).collect();
    let p = spd::solve(&a, &b).map_or(start, |x| DVec3::new(x[0], x[1], x[2]));
    (p, information)
}

/// One round of the alternation over `pairs` from `start`.
fn fit_once(pairs: &[MotionPair], start: Rigid) -> (Rigid, [[f64; 3]; 3]) {
    let mut fit = start;
    let mut information = [[0.0; 3]; 3];
    for _ in 0..8 {
        let terms: Vec<(DVec3, DVec3, f64)> = pairs
            .iter()
            .flat_map(|p| rotation_terms(p, fit.translation))
            .collect();
        let rotation = wahba(&terms);
        let (translation, info) = solve_translation(pairs, rotation, start.translation);
        let n = pairs.len().max(1) as f64;
        information = info.map(|row| row.map(|x| x / n));
        fit = Rigid::new(rotation, translation);
    }
    (fit, information)
}

/// Fit `vehicle_from_camera` to `pairs` from `start` (whose translation the unobserved
/// directions keep). Pairs whose residual exceeds three times the median (and 1°) are dropped
/// once and the fit repeated.
pub fn solve(pairs: &[MotionPair], start: Rigid) -> Result<HandEyeFit, HandEyeError> {
    require_turns(pairs.iter().map(|p| p.vehicle_motion))?;
    let (first, _) = fit_once(pairs, start);
    let scores: Vec<f64> = pairs
        .iter()
        .map(|p| {
            let (r, d) = residuals(p, first);
            r.max(d)
        })
        .collect();
    let limit = (3.0 * median(&mut scores.clone())).max(1.0);
    let kept: Vec<MotionPair> = pairs
        .iter()
        .zip(&scores)
        .filter(|(_, score)| **score <= limit)
        .map(|(p, _)| p.clone())
        .collect();
    if kept.len() < MIN_PAIRS {
        return Err(HandEyeError::TooFewPairs {
            found: kept.len(),
            needed: MIN_PAIRS,
        });
    }
    let (closed_form, closed_information) = fit_once(&kept, start);
    let (fit, observed, rotation_sigma) = if kept.iter().all(|p| p.rays.is_empty()) {
        let observed: [bool; 3] =
            std::array::from_fn(|i| closed_information[i][i] >= OBSERVED_INFORMATION);
        (closed_form, observed, DVec3::INFINITY)
    } else {
        let (fit, relative, sigma) = refine(&kept, closed_form, start.translation);
        let (fit, observed) = keep_observed(fit, relative, start.translation);
        (fit, observed, sigma)
    };
    let (mut rotation_res, mut direction_res): (Vec<f64>, Vec<f64>) =
        kept.iter().map(|p| residuals(p, fit)).unzip();
    let unobserved = ["x", "y", "z"]
        .into_iter()
        .enumerate()
        .filter(|(i, _)| !observed[*i])
        .map(|(_, name)| name)
        .collect();
    Ok(HandEyeFit {
        vehicle_from_camera: fit,
        pairs_used: kept.len(),
        pairs_given: pairs.len(),
        rotation_residual_deg: median(&mut rotation_res),
        direction_residual_deg: median(&mut direction_res),
        unobserved,
        rotation_sigma_deg: rotation_sigma * 180.0 / std::f64::consts::PI,
    })
}

/// Signed Sampson distance (normalised image units) of the match `(a, b)` (rays in cameras
/// `i`, `j`) to the epipolar geometry of `camera_i_from_camera_j`.
pub fn epipolar_residual(camera_i_from_camera_j: Rigid, a: DVec3, b: DVec3) -> f64 {
    // x_j = R x_i + t for j_from_i; E = [t]× R, n_jᵀ E n_i = 0.
    let j_from_i = camera_i_from_camera_j.inverse();
    let Some(t) = j_from_i.translation.try_normalize() else {
        return 0.0;
    };
    let e = so3::hat(t) * DMat3::from_quat(j_from_i.rotation);
    let (na, nb) = (a / a.z.max(1e-6), b / b.z.max(1e-6));
    let ea = e * na;
    let etb = e.transpose() * nb;
    let den = ea.x * ea.x + ea.y * ea.y + etb.x * etb.x + etb.y * etb.y;
    if den <= 0.0 {
        return 0.0;
    }
    nb.dot(ea) / den.sqrt()
}

/// Matches' Sampson distances above this (normalised units, about 3 px at a 1000 px focal
/// length) count less (Cauchy weights).
const ROBUST_SCALE: f64 = 3.0e-3;
/// The pull of the translation to the start, as the residual of one match per metre, times
/// the square root of the number of matches (so its weight does not depend on how many).
const REFINE_PRIOR_PER_M: f64 = 1.0e-4;

/// Gauss–Newton (Levenberg damped, Cauchy-weighted) on every pair's matched rays: the
/// extrinsic whose predicted camera motions `X⁻¹ V X` put every match on its epipolar line,
/// no essential matrix in between (a scene that is mostly one plane leaves those ill-posed,
/// not this). Returns the fit, the translation's information relative to the prior's, and the
/// rotation's 1-σ about the camera's own axes (rad).
fn refine(
    pairs: &[MotionPair],
    start: Rigid,
    prior_translation: DVec3,
) -> (Rigid, [[f64; 3]; 3], DVec3) {
    let matches: usize = pairs.iter().map(|p| p.rays.len()).sum();
    let prior = REFINE_PRIOR_PER_M * (matches.max(1) as f64).sqrt();
    let apply = |x: Rigid, d: &[f64; 6]| {
        Rigid::new(
            (x.rotation * so3::exp(DVec3::new(d[0], d[1], d[2]))).normalize(),
            x.translation + DVec3::new(d[3], d[4], d[5]),
        )
    };
    let residuals = |x: Rigid| -> Vec<f64> {
        let inverse = x.inverse();
        pairs
            .par_iter()
            .flat_map_iter(|p| {
                let c = inverse * p.vehicle_motion * x;
                p.rays
                    .iter()
                    .map(move |(a, b)| epipolar_residual(c, *a, *b))
            })
            .collect()
    };
    let cost = |r: &[f64], x: Rigid| -> f64 {
        let data: f64 = r
            .iter()
            .map(|e| (1.0 + (e / ROBUST_SCALE).powi(2)).ln())
            .sum::<f64>()
            * ROBUST_SCALE
            * ROBUST_SCALE;
        data + (prior * (x.translation - prior_translation).length()).powi(2)
    };
    let mut x = start;
    let mut r = residuals(x);
    let mut current = cost(&r, x);
    let mut lambda = 1e-3;
    let mut information = [[0.0; 3]; 3];
    // Numeric Jacobian at `x` (residuals `r` there): six columns of residual differences.
    const STEP: f64 = 1e-6;
    let jacobian = |x: Rigid, r: &[f64]| -> Vec<Vec<f64>> {
        (0..6)
            .map(|k| {
                let mut d = [0.0; 6];
                d[k] = STEP;
                residuals(apply(x, &d))
                    .iter()
                    .zip(r)
                    .map(|(moved, here)| (moved - here) / STEP)
                    .collect()
            })
            .collect()
    };
    for _ in 0..30 {
        let columns = jacobian(x, &r);
        let mut jtj = [[0.0f64; 6]; 6];
        let mut jtr = [0.0f64; 6];
        for (i, e) in r.iter().enumerate() {
            // Cauchy weight.
            let w = 1.0 / (1.0 + (e / ROBUST_SCALE).powi(2));
            for a in 0..6 {
                let ja = columns[a][i];
                jtr[a] += w * ja * e;
                for b in a..6 {
                    jtj[a][b] += w * ja * columns[b][i];
                }
            }
        }
        for a in 0..6 {
            for b in 0..a {
                jtj[a][b] = jtj[b][a];
            }
        }
        for (k, row) in information.iter_mut().enumerate() {
            for (l, v) in row.iter_mut().enumerate() {
                *v = jtj[3 + k][3 + l] / (prior * prior);
            }
        }
        let offset = x.translation - prior_translation;
        for k in 0..3 {
            jtj[3 + k][3 + k] += prior * prior;
            jtr[3 + k] += prior * prior * offset[k];
        }
        let mut improved = false;
        while lambda < 1e6 {
            let mut a = Vec::with_capacity(36);
            for (i, row) in jtj.iter().enumerate() {
                for (j, v) in row.iter().enumerate() {
                    a.push(if i == j {
                        v * (1.0 + lambda) + 1e-12
                    } else {
                        *v
                    });
                }
            }
            let b: Vec<f64> = jtr.iter().map(|v| -v).collect();
            let Some(step) = spd::solve(&a, &b) else {
                lambda *= 10.0;
                continue;
            };
            let d = [step[0], step[1], step[2], step[3], step[4], step[5]];
            let candidate = apply(x, &d);
            let r2 = residuals(candidate);
            let c2 = cost(&r2, candidate);
            if c2 < current {
                let small = d.iter().map(|v| v.abs()).fold(0.0, f64::max) < 1e-9;
                (x, r, current) = (candidate, r2, c2);
                lambda = (lambda * 0.3).max(1e-9);
                improved = !small;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    // The rotation's spread, cluster-robust over pairs: a pair's matches share its motion's
    // errors (the trajectory's, the stamps'), so the pairs, not the matches, are taken as the
    // independent draws. Σ = H⁻¹ (Σ_p g_p g_pᵀ) H⁻¹ with g_p the pair's weighted gradient and
    // H the reweighted Gauss–Newton matrix. Pairs that share an image are not independent
    // either, so this σ is if anything low; it ranks the axes, it does not bound them.
    let columns = jacobian(x, &r);
    let mut h = [[0.0f64; 6]; 6];
    let mut meat = [[0.0f64; 6]; 6];
    let mut i = 0;
    for p in pairs {
        let mut g = [0.0f64; 6];
        for _ in 0..p.rays.len() {
            let e = r[i];
            let w = 1.0 / (1.0 + (e / ROBUST_SCALE).powi(2));
            for a in 0..6 {
                g[a] += w * columns[a][i] * e;
                for b in 0..6 {
                    h[a][b] += w * columns[a][i] * columns[b][i];
                }
            }
            i += 1;
        }
        for a in 0..6 {
            for b in 0..6 {
                meat[a][b] += g[a] * g[b];
            }
        }
    }
    for (k, row) in h.iter_mut().enumerate().skip(3) {
        row[k] += prior * prior;
    }
    // Σ = H⁻¹ M H⁻¹ on the directions H observes; a turn it does not is infinite.
    let (inverse, unobserved, _) = spd::observed_inverse(h, 1e-12);
    let rotation_sigma = DVec3::from_array(std::array::from_fn(|a| {
        if unobserved[a] {
            return f64::INFINITY;
        }
        let v: f64 = (0..6)
            .flat_map(|k| (0..6).map(move |l| (k, l)))
            .map(|(k, l)| inverse[a][k] * meat[k][l] * inverse[l][a])
            .sum();
        v.max(0.0).sqrt()
    }));
    (x, information, rotation_sigma)
}

/// The translation's information relative to the prior's above which an eigen-direction of it
/// counts as observed. On the simulator's figure-8 the front and back cameras' x reaches
/// 100–180, the side cameras' 0.3–20 (a sideways camera sees the turns' sideways shift as
/// motion along its optical axis), y 1e-4–1e-3 and z nothing.
const OBSERVED_RELATIVE: f64 = 3.0;

/// `fit` with its translation moved from `start` only along the eigen-directions of the
/// translation's information (relative to the prior's) that the images observe: in that basis
/// the directions are independent, so one the drive cannot see does not drag the others. Also
/// which vehicle axes are observed (their information, relative, as high).
fn keep_observed(fit: Rigid, relative: [[f64; 3]; 3], start: DVec3) -> (Rigid, [bool; 3]) {
    let (values, vectors) = spd::symmetric_eigen(relative);
    let moved = fit.translation - start;
    let mut kept = DVec3::ZERO;
    for k in 0..3 {
        if values[k] >= OBSERVED_RELATIVE {
            let e = DVec3::new(vectors[0][k], vectors[1][k], vectors[2][k]);
            kept += e * e.dot(moved);
        }
    }
    (
        Rigid::new(fit.rotation, start + kept),
        std::array::from_fn(|i| relative[i][i] >= OBSERVED_RELATIVE),
    )
}

fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

/// Image pairs `(i, j)` of frames stamped `stamps_nanos` whose vehicle poses are
/// [`MIN_BASELINE_M`]–[`MAX_BASELINE_M`] apart, each with `vehicle_i_from_vehicle_j`; frames
/// outside the trajectory are skipped.
pub fn candidate_pairs(
    trajectory: &crate::geometry::Trajectory,
    stamps_nanos: &[i64],
) -> Vec<(usize, usize, Rigid)> {
    let poses: Vec<Option<Rigid>> = stamps_nanos
        .iter()
        .map(|&t| trajectory.world_from_vehicle(t).ok())
        .collect();
    let mut out = Vec::new();
    for i in 0..poses.len() {
        for j in i + 1..poses.len() {
            if let (Some(a), Some(b)) = (poses[i], poses[j]) {
                let motion = a.inverse() * b;
                let baseline = motion.translation.length();
                if (MIN_BASELINE_M..=MAX_BASELINE_M).contains(&baseline) {
                    out.push((i, j, motion));
                }
            }
        }
    }
    out
}

/// Whether the candidate pairs' vehicle motions turn enough to fix a camera's rotation
/// (checked before any image is read: a straight drive is refused at once).
pub fn check_turns(candidates: &[(usize, usize, Rigid)]) -> Result<(), HandEyeError> {
    require_turns(candidates.iter().map(|(_, _, motion)| *motion))
}

/// Enough vehicle motions ([`MIN_PAIRS`]), one of which turns at least [`MIN_TURN_DEG`].
fn require_turns(motions: impl ExactSizeIterator<Item = Rigid>) -> Result<(), HandEyeError> {
    if motions.len() < MIN_PAIRS {
        return Err(HandEyeError::TooFewPairs {
            found: motions.len(),
            needed: MIN_PAIRS,
        });
    }
    let max_turn_deg = motions
        .map(|motion| so3::angle_rad(motion.rotation).to_degrees())
        .fold(0.0, f64::max);
    if max_turn_deg < MIN_TURN_DEG {
        return Err(HandEyeError::TooStraight { max_turn_deg });
    }
    Ok(())
}

/// Every candidate pair of one camera's frames turned into a [`MotionPair`] where its images
/// agree on a motion (in parallel), reporting `(pairs done, pairs)`.
pub fn motion_pairs(
    keypoints: &[Vec<crate::features::orb::Keypoint>],
    candidates: &[(usize, usize, Rigid)],
    unproject: &(dyn Fn(f64, f64) -> Option<DVec3> + Sync),
    report: &(dyn Fn(usize, usize) + Sync),
) -> Vec<MotionPair> {
    let done = std::sync::atomic::AtomicUsize::new(0);
    candidates
        .par_iter()
        .enumerate()
        .filter_map(|(k, &(i, j, motion))| {
            let pair = pair_from_keypoints(
                &keypoints[i],
                &keypoints[j],
                unproject,
                motion,
                0x4A4E_D000 ^ k as u64,
            );
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            report(n, candidates.len());
            pair.map(|p| MotionPair {
                first_image: i,
                ..p
            })
        })
        .collect()
}

#[cfg(test)]
mod tests;
