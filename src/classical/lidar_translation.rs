//! A camera's translation measured against the LiDAR map: the metric part a hand-eye fit
//! cannot observe on a level drive (the height, mostly the sideways offset).
//!
//! How it works. The hand-eye fit ([`super::hand_eye`]) leaves a camera's rotation within a
//! few tenths of a degree but its translation only partly fixed. Its verified matches say more:
//! with the vehicle's motion between two images from the trajectory, the camera's own motion
//! `C = X⁻¹ V X` is metric, so each match triangulates to a point at its true distance
//! (midpoint of the two rays; matches with little parallax, far points or rays that miss each
//! other are dropped). Placed in the world through the vehicle pose of the first image,
//! `P = W_i X p`, those points sit on the LiDAR map when the camera's translation is right, and
//! a translation error `Δ` (vehicle frame) shifts every point of image `i` by `R_{W_i} Δ`. So
//! the translation is registered to the map by point-to-plane ICP with three unknowns: the
//! residual of a point with map neighbour `q` and normal `n` is `n·(P − q)`, its Jacobian
//! `(R_{W_i}ᵀ n)ᵀ`, Huber weights, and correspondence distances shrinking from 2 m to 0.25 m, so
//! a start a metre off still finds the ground and the façades. After each step the points are
//! triangulated again (a pair that turns moves with the translation too). The ground pins the
//! height; façades and poles the horizontal directions. A direction the points do not observe
//! (an eigenvalue of the 3 × 3 normal equations below about 30 points' worth) stays where it
//! started.

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use super::hand_eye::MotionPair;
use super::icp::{KdTree, NORMAL_RADIUS_M};
use crate::eval::registration::plane_normal_from_moments;
use crate::geometry::Rigid;
use crate::geometry::so3::outer;

/// Correspondence distances, coarse to fine (m).
const LEVELS_M: [f64; 4] = [2.0, 1.0, 0.5, 0.25];
const ITERATIONS_PER_LEVEL: usize = 10;
/// Huber threshold on the point-to-plane residual (m).
const HUBER_M: f64 = 0.1;
/// Triangulated points further than this from the first camera are not used (m): depth noise
/// grows with its square.
const MAX_DEPTH_M: f64 = 25.0;
const MIN_DEPTH_M: f64 = 1.0;
/// Least angle between a match's two rays (rad, about 1.5°).
const MIN_PARALLAX_RAD: f64 = 0.026;
/// Largest gap between a match's two rays at their closest, relative to the depth.
const MAX_GAP_RELATIVE: f64 = 0.01;
/// Map neighbourhoods flatter than this get a normal (as ICP's targets).
const MAX_FLATNESS: f64 = 0.15;
/// A direction whose information is below this stays at the start: about as many points
/// whose normals lie fully along it (each point adds at most 1). Absolute, not relative to the
/// best-observed direction: a side camera facing a long façade has thousands of points across
/// the drive and a few hundred on the ground, which still fix its height.
const MIN_INFORMATION: f64 = 30.0;
/// Points a fit needs.
const MIN_POINTS: usize = 50;

/// The LiDAR map in the world frame, with a k-d tree and the normals of its flat parts.
pub struct LidarMap {
    points: Vec<DVec3>,
    normals: Vec<Option<DVec3>>,
    tree: KdTree,
}

impl LidarMap {
    /// The map of world points `points` (already thinned, e.g. by
    /// [`crate::optim::photo_consistency::lidar_map`]).
    pub fn new(points: Vec<DVec3>) -> Self {
        let tree = KdTree::new(&points);
        let normals = points
            .par_iter()
            .map(|&p| {
                let (n, sum, outer) = tree.moments(p, NORMAL_RADIUS_M);
                plane_normal_from_moments(n, sum, outer, MAX_FLATNESS)
            })
            .collect();
        Self {
            points,
            normals,
            tree,
        }
    }

    /// The nearest map point within `max_m` of `p` that has a normal: `(point, normal)`.
    fn plane_near(&self, p: DVec3, max_m: f64) -> Option<(DVec3, DVec3)> {
        let k = self.tree.nearest(p, max_m)? as usize;
        Some((self.points[k], self.normals[k]?))
    }
}

/// The translation fitted to the map, and how.
#[derive(Clone, Debug, PartialEq)]
pub struct TranslationFit {
    pub vehicle_from_camera: Rigid,
    /// Triangulated points used at the last step, and their median |point-to-plane| distance
    /// (m).
    pub points: usize,
    pub median_residual_m: f64,
    /// Directions of the vehicle frame left at the start (weakly observed by the points).
    pub unobserved: Vec<&'static str>,
}

/// Why no translation was fitted.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TranslationError {
    #[error("only {found} triangulated points lie near the LiDAR map (at least {needed} needed)")]
    TooFewPoints { found: usize, needed: usize },
}

/// The matches of `pairs` triangulated with the camera at `vehicle_from_camera`, in the world:
/// `(point, world_from_vehicle rotation of the pair's first image)`. `world_from_vehicle[i]` is
/// the vehicle pose of image `i` ([`MotionPair::first_image`]); a pair whose first image has
/// none is skipped.
pub fn triangulate(
    pairs: &[MotionPair],
    world_from_vehicle: &[Option<Rigid>],
    vehicle_from_camera: Rigid,
) -> Vec<(DVec3, DMat3)> {
    let camera_from_vehicle = vehicle_from_camera.inverse();
    pairs
        .par_iter()
        .filter_map(|pair| {
            let w = world_from_vehicle
                .get(pair.first_image)
                .copied()
                .flatten()?;
            let world_from_camera = w * vehicle_from_camera;
            let i_from_j = camera_from_vehicle * pair.vehicle_motion * vehicle_from_camera;
            let rotation = DMat3::from_quat(w.rotation);
            Some(
                pair.rays
                    .iter()
                    .filter_map(|&(a, b)| midpoint(i_from_j, a, b))
                    .map(|p| (world_from_camera.transform_point(p), rotation))
                    .collect::<Vec<_>>(),
            )
        })
        .flatten()
        .collect()
}

/// The point two unit rays meet at, in camera `i`'s frame: `a` from camera `i`'s centre, `b`
/// from camera `j`'s (in its frame); `None` when they are nearly parallel, meet behind either
/// camera, too near or too far, or pass too far apart.
fn midpoint(i_from_j: Rigid, a: DVec3, b: DVec3) -> Option<DVec3> {
    let c = i_from_j.translation;
    let b = i_from_j.rotation * b;
    let k = a.dot(b);
    if k > MIN_PARALLAX_RAD.cos() {
        return None;
    }
    // s a − u b ≈ c by least squares.
    let (ac, bc) = (a.dot(c), b.dot(c));
    let u = (bc - k * ac) / (k * k - 1.0);
    let s = ac + k * u;
    if !(MIN_DEPTH_M..=MAX_DEPTH_M).contains(&s) || u <= 0.0 {
        return None;
    }
    let (on_a, on_b) = (a * s, c + b * u);
    (on_a.distance(on_b) <= MAX_GAP_RELATIVE * s).then(|| (on_a + on_b) * 0.5)
}

/// Register the translation of `start` (its rotation kept) to `map` by its triangulated
/// matches (module docs).
pub fn fit_translation(
    map: &LidarMap,
    pairs: &[MotionPair],
    world_from_vehicle: &[Option<Rigid>],
    start: Rigid,
) -> Result<TranslationFit, TranslationError> {
    let mut translation = start.translation;
    let mut last = (0, 0.0, DMat3::ZERO);
    for &radius in &LEVELS_M {
        for _ in 0..ITERATIONS_PER_LEVEL {
            let camera = Rigid::new(start.rotation, translation);
            let points = triangulate(pairs, world_from_vehicle, camera);
            let (h, information, g, used, median) = normal_equations(map, &points, radius);
            last = (used, median, information);
            if used < MIN_POINTS {
                break;
            }
            let step = solve_observed(h, information, -g);
            translation += step;
            if step.length() < 1e-4 {
                break;
            }
        }
    }
    let (used, median, information) = last;
    if used < MIN_POINTS {
        return Err(TranslationError::TooFewPoints {
            found: used,
            needed: MIN_POINTS,
        });
    }
    let weak = weak_directions(information);
    // A weak direction keeps the start: undo whatever the steps did along it.
    for &axis in &weak {
        translation -= axis * axis.dot(translation - start.translation);
    }
    let unobserved = ["x", "y", "z"]
        .into_iter()
        .zip([DVec3::X, DVec3::Y, DVec3::Z])
        .filter(|(_, e)| weak.iter().any(|w| w.dot(*e).abs() > 0.7))
        .map(|(n, _)| n)
        .collect();
    Ok(TranslationFit {
        vehicle_from_camera: Rigid::new(start.rotation, translation),
        points: used,
        median_residual_m: median,
        unobserved,
    })
}

/// Huber-weighted point-to-plane normal equations `(H, g)` over `points` with map neighbours
/// within `radius_m`, the unweighted information `Σ m mᵀ` (what decides which directions are
/// observed: Huber weights would count a start a metre off as unobserved), the number used and
/// their median |residual|.
fn normal_equations(
    map: &LidarMap,
    points: &[(DVec3, DMat3)],
    radius_m: f64,
) -> (DMat3, DMat3, DVec3, usize, f64) {
    let terms: Vec<(DVec3, f64)> = points
        .par_iter()
        .filter_map(|&(p, world_rotation)| {
            let (q, n) = map.plane_near(p, radius_m)?;
            // d(P)/dΔ = R_W, so d r / dΔ = (R_Wᵀ n)ᵀ.
            Some((world_rotation.transpose() * n, n.dot(p - q)))
        })
        .collect();
    let (mut h, mut information, mut g) = (DMat3::ZERO, DMat3::ZERO, DVec3::ZERO);
    for &(m, r) in &terms {
        let w = if r.abs() <= HUBER_M {
            1.0
        } else {
            HUBER_M / r.abs()
        };
        let m_mt = outer(m, m);
        h += m_mt * w;
        information += m_mt;
        g += m * (w * r);
    }
    let mut residuals: Vec<f64> = terms.iter().map(|t| t.1.abs()).collect();
    residuals.sort_by(f64::total_cmp);
    let median = residuals.get(residuals.len() / 2).copied().unwrap_or(0.0);
    (h, information, g, terms.len(), median)
}

/// Unit eigen-directions of `information` whose eigenvalue is below [`MIN_INFORMATION`].
fn weak_directions(information: DMat3) -> Vec<DVec3> {
    let (values, vectors) = eigen(information);
    (0..3)
        .filter(|&k| values[k] < MIN_INFORMATION)
        .map(|k| vectors[k])
        .collect()
}

/// `h⁻¹ b` within the directions `information` observes (nothing along the weak ones): `h`
/// restricted to the observed subspace, the identity on the weak one.
fn solve_observed(h: DMat3, information: DMat3, b: DVec3) -> DVec3 {
    let weak = weak_directions(information);
    let weak_part: DMat3 = weak
        .iter()
        .map(|&w| outer(w, w))
        .fold(DMat3::ZERO, |a, m| a + m);
    let observed = DMat3::IDENTITY - weak_part;
    let a = observed * h * observed + weak_part;
    if a.determinant().abs() < 1e-12 {
        return DVec3::ZERO;
    }
    observed * (a.inverse() * (observed * b))
}

/// Eigenvalues and unit eigenvectors of the symmetric `h`.
fn eigen(h: DMat3) -> ([f64; 3], [DVec3; 3]) {
    let (values, v) = crate::geometry::spd::symmetric_eigen(h.to_cols_array_2d());
    let column = |k: usize| DVec3::new(v[0][k], v[1][k], v[2][k]);
    (values, [column(0), column(1), column(2)])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::so3;
    use glam::DQuat;

    /// A side camera looking left (optical z along the vehicle's +y), 1.2 m forward, 0.8 m
    /// left, 1.7 m up.
    fn left_camera() -> Rigid {
        let vehicle_from_optical = DMat3::from_cols(DVec3::X, -DVec3::Z, DVec3::Y);
        Rigid::new(
            so3::quat_from_matrix_orthonormalized(vehicle_from_optical),
            DVec3::new(1.2, 0.8, 1.7),
        )
    }

    /// A street sampled every 10 cm: the ground (z = 0), a façade 8 m left of the drive
    /// (y = 8) and pillars in front of it every 5 m (1 m wide, 1 m deep, 6 m high), whose
    /// sides fix the position along the drive.
    fn street() -> Vec<DVec3> {
        let mut out = Vec::new();
        let heights = |x: f64, y: f64, out: &mut Vec<DVec3>| {
            (0..60).for_each(|k| out.push(DVec3::new(x, y, k as f64 * 0.1)));
        };
        for i in -100..500 {
            let x = i as f64 * 0.1;
            for j in -80..80 {
                out.push(DVec3::new(x, j as f64 * 0.1, 0.0));
            }
            heights(x, 8.0, &mut out);
        }
        for pillar in 0..10 {
            let x0 = pillar as f64 * 5.0;
            for d in 0..=10 {
                let d = d as f64 * 0.1;
                heights(x0, 7.0 + d, &mut out);
                heights(x0 + 1.0, 7.0 + d, &mut out);
                heights(x0 + d, 7.0, &mut out);
            }
        }
        out
    }

    /// Vehicle poses along the street (x from 0 to 30 m) with a gentle weave.
    fn drive() -> Vec<Rigid> {
        (0..16)
            .map(|k| {
                let x = k as f64 * 2.0;
                let heading = 0.05 * (k as f64 * 0.7).sin();
                Rigid::new(
                    DQuat::from_rotation_z(heading),
                    DVec3::new(x, 0.3 * heading, 0.0),
                )
            })
            .collect()
    }

    /// Every pose known (inside the trajectory).
    fn known(poses: &[Rigid]) -> Vec<Option<Rigid>> {
        poses.iter().copied().map(Some).collect()
    }

    /// Exact matches of `camera` between images `i` and `i + 2`, from map points it sees.
    fn pairs(camera: Rigid, poses: &[Rigid], map: &[DVec3]) -> Vec<MotionPair> {
        (0..poses.len() - 2)
            .map(|i| {
                let (wi, wj) = (poses[i], poses[i + 2]);
                let ci = (wi * camera).inverse();
                let cj = (wj * camera).inverse();
                let seen: Vec<(DVec3, DVec3)> = map
                    .iter()
                    .filter_map(|&p| {
                        let (a, b) = (ci.transform_point(p), cj.transform_point(p));
                        (a.z > 1.0 && b.z > 1.0 && a.x.abs() < a.z && a.y.abs() < 0.6 * a.z)
                            .then(|| (a.normalize_or_zero(), b.normalize_or_zero()))
                    })
                    .collect();
                let rays = crate::log::spread_evenly(&seen, 150);
                let motion = wi.inverse() * wj;
                MotionPair {
                    camera_rotation: DQuat::IDENTITY,
                    camera_direction: DVec3::X,
                    vehicle_motion: motion,
                    rays,
                    first_image: i,
                }
            })
            .collect()
    }

    #[test]
    fn triangulated_matches_lie_on_the_map_at_the_true_translation() {
        let (map, poses, camera) = (street(), drive(), left_camera());
        let pairs = pairs(camera, &poses, &map);
        let points = triangulate(&pairs, &known(&poses), camera);
        assert!(points.len() > 500, "{}", points.len());
        let lidar = LidarMap::new(map);
        let worst = points
            .iter()
            .map(|(p, _)| {
                let k = lidar.tree.nearest(*p, 1.0).unwrap() as usize;
                lidar.points[k].distance(*p)
            })
            .fold(0.0, f64::max);
        assert!(worst < 0.08, "{worst}");
        // A pair whose first image lies outside the trajectory gives no points.
        let mut partly = known(&poses);
        partly[pairs[0].first_image] = None;
        let fewer = triangulate(&pairs, &partly, camera).len();
        assert!(
            fewer < points.len() && fewer > 0,
            "{fewer} of {}",
            points.len()
        );
    }

    #[test]
    fn a_translation_a_metre_off_comes_back_in_every_direction() {
        let (map, poses, camera) = (street(), drive(), left_camera());
        let pairs = pairs(camera, &poses, &map);
        let lidar = LidarMap::new(map);
        for offset in [
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::new(0.0, 0.0, -1.0),
            DVec3::new(0.6, -0.6, 0.5),
            DVec3::new(-0.5, 0.7, -0.4),
        ] {
            let start = Rigid::new(camera.rotation, camera.translation + offset);
            let fit = fit_translation(&lidar, &pairs, &known(&poses), start).unwrap();
            let error = fit.vehicle_from_camera.translation - camera.translation;
            assert!(error.length() < 0.03, "{offset} -> {error} ({fit:?})");
            assert_eq!(fit.vehicle_from_camera.rotation, camera.rotation);
        }
    }

    #[test]
    fn a_direction_is_observed_by_enough_points_however_many_see_the_others() {
        // Thousands of points on a façade across the drive, sixty on the ground: the height is
        // observed; five are not enough.
        let h = |ground: f64| DMat3::from_diagonal(DVec3::new(800.0, 5000.0, ground));
        assert!(weak_directions(h(60.0)).is_empty());
        let weak = weak_directions(h(5.0));
        assert_eq!(weak.len(), 1);
        assert!(weak[0].z.abs() > 0.99, "{weak:?}");
        let step = solve_observed(h(5.0), h(5.0), DVec3::new(800.0, 5000.0, 5.0));
        assert!((step - DVec3::new(1.0, 1.0, 0.0)).length() < 1e-9, "{step}");
    }

    #[test]
    fn without_points_near_the_map_it_says_so() {
        let (map, poses, camera) = (street(), drive(), left_camera());
        let pairs = pairs(camera, &poses, &map);
        let far: Vec<DVec3> = map
            .iter()
            .map(|p| *p + DVec3::new(0.0, 0.0, 50.0))
            .collect();
        let lidar = LidarMap::new(far);
        let err = fit_translation(&lidar, &pairs, &known(&poses), camera).unwrap_err();
        assert!(
            matches!(err, TranslationError::TooFewPoints { .. }),
            "{err}"
        );
    }
}
