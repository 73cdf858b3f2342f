//! A camera's translation, or its whole pose, measured against the LiDAR map: the metric part a
//! hand-eye fit cannot observe on a level drive (the height, mostly the sideways offset), with
//! the turns its motion observes weakly (a side camera's tilt, which trades against the height),
//! and on a drive too straight for a hand-eye, the rotation too.
//!
//! How it works. The hand-eye fit ([`super::hand_eye`]) leaves a camera's rotation within a
//! few tenths of a degree but its translation only partly fixed. Its verified matches say more:
//! with the vehicle's motion between two images from the trajectory, the camera's own motion
//! `C = X⁻¹ V X` is metric, so each match triangulates to a point at its true distance
//! (midpoint of the two rays; matches with little parallax, far points or rays that miss each
//! other are dropped). Placed in the world through the vehicle pose of the first image,
//! `P = W_i X p`, those points sit on the LiDAR map when the camera's extrinsic is right. A
//! translation error `Δ` (vehicle frame) shifts every point of image `i` by `R_{W_i} Δ`; a turn
//! `ω` of the camera about its centre (vehicle frame) moves it by `R_{W_i} (ω × o)`, `o` the
//! point's offset from the camera. So the extrinsic is registered to the map by point-to-plane
//! ICP: the residual of a point with map neighbour `q` and normal `n` is `n·(P − q)`, its
//! Jacobian `(R_{W_i}ᵀ n)ᵀ` in `Δ` and `(o × R_{W_i}ᵀ n)ᵀ` in `ω` ([`fit_translation`] keeps
//! the rotation; [`fit_translation_and_turns`] frees the turns about the camera axes a hand-eye
//! fit observes weakly; [`fit_pose`] frees it all), Huber weights, and correspondence distances shrinking
//! from 2 m to 0.25 m, so a start a metre off still finds the ground and the façades. After
//! each step the points are triangulated again (a pair that turns moves with the translation
//! too). The ground pins the height; façades and poles the horizontal directions. A direction
//! the points do not observe (an eigenvalue of the normal equations below about 30 points'
//! worth, rotations counted in metres at 5 m) stays where it started.
//!
//! What the pose fit is worth (docs/experiments/hand-eye-start.md): side cameras of the simulator's figure-8 drive
//! come to the same pose from every start up to 2° / 20 cm, 0.14–0.25° and ≤ 3.6 cm from the
//! truth; the front and back cameras, whose matches have little parallax, do not; on PandaSet's
//! straight drive (16 images per camera) it is not accurate enough to start UniCal from.

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use super::hand_eye::MotionPair;
use super::icp::{KdTree, NORMAL_RADIUS_M};
use crate::eval::registration::plane_normal_from_moments;
use crate::geometry::Rigid;
use crate::geometry::so3;

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

/// The extrinsic fitted to the map, and how.
#[derive(Clone, Debug, PartialEq)]
pub struct MapFit {
    pub vehicle_from_camera: Rigid,
    /// Triangulated points used at the last step, and their median |point-to-plane| distance
    /// (m).
    pub points: usize,
    pub median_residual_m: f64,
    /// What the fit moved but the points do not observe, left at the start: translations along
    /// the vehicle's "x", "y", "z", rotations about them ("roll", "pitch", "yaw").
    pub unobserved: Vec<&'static str>,
}

/// Why no fit was made.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MapFitError {
    #[error("only {found} triangulated points lie near the LiDAR map (at least {needed} needed)")]
    TooFewPoints { found: usize, needed: usize },
}

/// A match triangulated with the camera at some extrinsic, placed in the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangulated {
    /// The point in the world (m).
    pub world: DVec3,
    /// `world_from_vehicle`'s rotation at the pair's first image.
    pub world_rotation: DMat3,
    /// From the camera's centre to the point, in the vehicle frame of that image (m): the lever
    /// arm a rotation of the camera moves the point by.
    pub from_camera: DVec3,
}

/// The matches of `pairs` triangulated with the camera at `vehicle_from_camera`, in the world.
/// `world_from_vehicle[i]` is the vehicle pose of image `i` ([`MotionPair::first_image`]); a
/// pair whose first image has none is skipped.
pub fn triangulate(
    pairs: &[MotionPair],
    world_from_vehicle: &[Option<Rigid>],
    vehicle_from_camera: Rigid,
) -> Vec<Triangulated> {
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
            let world_rotation = DMat3::from_quat(w.rotation);
            Some(
                pair.rays
                    .iter()
                    .filter_map(|&(a, b)| midpoint(i_from_j, a, b))
                    .map(|p| Triangulated {
                        world: world_from_camera.transform_point(p),
                        world_rotation,
                        from_camera: vehicle_from_camera.rotation * p,
                    })
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
) -> Result<MapFit, MapFitError> {
    fit(map, pairs, world_from_vehicle, start, &[])
}

/// Register the translation of `start` and its rotation about the camera's own axes `axes`
/// (0 = x, 1 = y, 2 = z), the rest of its rotation kept: for a camera whose hand-eye fit
/// observes those turns poorly (a side camera's tilt, mostly). A weak freed turn is named
/// `"rot x"` (and so on) in [`MapFit::unobserved`].
pub fn fit_translation_and_turns(
    map: &LidarMap,
    pairs: &[MotionPair],
    world_from_vehicle: &[Option<Rigid>],
    start: Rigid,
    axes: &[usize],
) -> Result<MapFit, MapFitError> {
    let mut axes = axes.to_vec();
    axes.sort_unstable();
    axes.dedup();
    let free: Vec<(DVec3, &'static str)> = axes
        .iter()
        .filter_map(|&k| {
            let name = *CAMERA_TURNS.get(k)?;
            Some((start.rotation * DVec3::AXES[k], name))
        })
        .collect();
    fit(map, pairs, world_from_vehicle, start, &free)
}

/// Names of turns about the camera's own axes.
const CAMERA_TURNS: [&str; 3] = ["rot x", "rot y", "rot z"];

/// Register the whole extrinsic of `start` to `map`: its translation and its rotation about
/// the camera's centre (module docs), for a camera no hand-eye fit could turn.
pub fn fit_pose(
    map: &LidarMap,
    pairs: &[MotionPair],
    world_from_vehicle: &[Option<Rigid>],
    start: Rigid,
) -> Result<MapFit, MapFitError> {
    let free = [(DVec3::X, "roll"), (DVec3::Y, "pitch"), (DVec3::Z, "yaw")];
    fit(map, pairs, world_from_vehicle, start, &free)
}

/// A rotation's unknowns are scaled by this lever (m), so that each of the six counts, as a
/// translation does, in metres a point moves: a camera turned by `ω` moves a point 5 m away (a
/// typical depth of the triangulated points) by about `5 ω`. [`MIN_INFORMATION`] then means the
/// same for all six.
const LEVER_M: f64 = 5.0;

/// Names of the translation unknowns: along the vehicle's axes.
const TRANSLATIONS: [&str; 3] = ["x", "y", "z"];

/// The Gauss–Newton loop behind [`fit_translation`], [`fit_translation_and_turns`] and
/// [`fit_pose`]: the unknowns are the translation step `Δ` and the rotation `ω` about the
/// camera's centre (vehicle frame, `R ← exp(ω) R`), scaled by [`LEVER_M`], `ω` only within the
/// span of the orthonormal directions `free` (vehicle frame, each named for the report).
fn fit(
    map: &LidarMap,
    pairs: &[MotionPair],
    world_from_vehicle: &[Option<Rigid>],
    start: Rigid,
    free: &[(DVec3, &'static str)],
) -> Result<MapFit, MapFitError> {
    let rotate = |turn: DVec3| -> DVec3 { free.iter().map(|(d, _)| *d * d.dot(turn)).sum() };
    let mut camera = start;
    let mut last = (0, 0.0, [[0.0; 6]; 6]);
    for &radius in &LEVELS_M {
        for _ in 0..ITERATIONS_PER_LEVEL {
            let points = triangulate(pairs, world_from_vehicle, camera);
            let (h, information, g, used, median) = normal_equations(map, &points, radius, &rotate);
            last = (used, median, information);
            if used < MIN_POINTS {
                break;
            }
            let step = solve_observed(h, information, g.map(|v| -v));
            camera = Rigid::new(
                so3::exp(DVec3::new(step[3], step[4], step[5]) / LEVER_M) * camera.rotation,
                camera.translation + DVec3::new(step[0], step[1], step[2]),
            );
            if step.iter().map(|v| v * v).sum::<f64>().sqrt() < 1e-4 {
                break;
            }
        }
    }
    let (used, median, information) = last;
    if used < MIN_POINTS {
        return Err(MapFitError::TooFewPoints {
            found: used,
            needed: MIN_POINTS,
        });
    }
    // A weak direction keeps the start: undo whatever the steps did along it.
    let weak = weak_directions(information);
    let turned = so3::log(camera.rotation * start.rotation.inverse()) * LEVER_M;
    let moved = camera.translation - start.translation;
    let mut total = [moved.x, moved.y, moved.z, turned.x, turned.y, turned.z];
    for w in &weak {
        let along: f64 = (0..6).map(|k| w[k] * total[k]).sum();
        (0..6).for_each(|k| total[k] -= w[k] * along);
    }
    // A held turn is a weak direction too (its rows are zero); only freed ones are named.
    let mut unobserved: Vec<&'static str> = (0..3)
        .filter(|&k| weak.iter().any(|w| w[k].abs() > 0.7))
        .map(|k| TRANSLATIONS[k])
        .collect();
    for (d, name) in free {
        if weak
            .iter()
            .any(|w| DVec3::new(w[3], w[4], w[5]).dot(*d).abs() > 0.7)
        {
            unobserved.push(name);
        }
    }
    Ok(MapFit {
        vehicle_from_camera: Rigid::new(
            so3::exp(DVec3::new(total[3], total[4], total[5]) / LEVER_M) * start.rotation,
            start.translation + DVec3::new(total[0], total[1], total[2]),
        ),
        points: used,
        median_residual_m: median,
        unobserved,
    })
}

type Mat6 = [[f64; 6]; 6];

/// Huber-weighted point-to-plane normal equations `(H, g)` over `points` with map neighbours
/// within `radius_m`, the unweighted information `Σ J Jᵀ` (what decides which directions are
/// observed: Huber weights would count a start a metre off as unobserved), the number used and
/// their median |residual|. `rotate` projects a turn onto the freed ones (the held turns' rows
/// are zero).
fn normal_equations(
    map: &LidarMap,
    points: &[Triangulated],
    radius_m: f64,
    rotate: &(dyn Fn(DVec3) -> DVec3 + Sync),
) -> (Mat6, Mat6, [f64; 6], usize, f64) {
    let terms: Vec<([f64; 6], f64)> = points
        .par_iter()
        .filter_map(|t| {
            let (q, n) = map.plane_near(t.world, radius_m)?;
            // d P / dΔ = R_W and d P / dω = −R_W [o]×, so d r / dΔ = (R_Wᵀ n)ᵀ and
            // d r / dω = (o × R_Wᵀ n)ᵀ.
            let m = t.world_rotation.transpose() * n;
            let turn = rotate(t.from_camera.cross(m) / LEVER_M);
            Some(([m.x, m.y, m.z, turn.x, turn.y, turn.z], n.dot(t.world - q)))
        })
        .collect();
    let (mut h, mut information, mut g) = ([[0.0; 6]; 6], [[0.0; 6]; 6], [0.0; 6]);
    for (j, r) in &terms {
        let w = if r.abs() <= HUBER_M {
            1.0
        } else {
            HUBER_M / r.abs()
        };
        for a in 0..6 {
            for b in 0..6 {
                h[a][b] += w * j[a] * j[b];
                information[a][b] += j[a] * j[b];
            }
            g[a] += w * r * j[a];
        }
    }
    let mut residuals: Vec<f64> = terms.iter().map(|t| t.1.abs()).collect();
    residuals.sort_by(f64::total_cmp);
    let median = residuals.get(residuals.len() / 2).copied().unwrap_or(0.0);
    (h, information, g, terms.len(), median)
}

/// Unit eigen-directions of `information` whose eigenvalue is below [`MIN_INFORMATION`] (a
/// fixed rotation's, with zero rows, among them).
fn weak_directions(information: Mat6) -> Vec<[f64; 6]> {
    let (values, v) = crate::geometry::spd::symmetric_eigen(information);
    (0..6)
        .filter(|&k| values[k] < MIN_INFORMATION)
        .map(|k| std::array::from_fn(|i| v[i][k]))
        .collect()
}

/// `h⁻¹ b` within the directions `information` observes (nothing along the weak ones): `h`
/// restricted to the observed subspace, the identity on the weak one.
fn solve_observed(h: Mat6, information: Mat6, b: [f64; 6]) -> [f64; 6] {
    let weak = weak_directions(information);
    let mut weak_part = [[0.0; 6]; 6];
    for w in &weak {
        for i in 0..6 {
            for j in 0..6 {
                weak_part[i][j] += w[i] * w[j];
            }
        }
    }
    let observed: Mat6 =
        std::array::from_fn(|i| std::array::from_fn(|j| f64::from(i == j) - weak_part[i][j]));
    let product = |x: &Mat6, y: &Mat6| -> Mat6 {
        std::array::from_fn(|i| std::array::from_fn(|j| (0..6).map(|k| x[i][k] * y[k][j]).sum()))
    };
    let apply = |x: &Mat6, v: &[f64; 6]| -> [f64; 6] {
        std::array::from_fn(|i| (0..6).map(|k| x[i][k] * v[k]).sum())
    };
    let restricted = product(&product(&observed, &h), &observed);
    let mut a = [0.0; 36];
    for i in 0..6 {
        for j in 0..6 {
            a[i * 6 + j] = restricted[i][j] + weak_part[i][j];
        }
    }
    match crate::geometry::spd::solve6(a, apply(&observed, &b)) {
        Some(x) => apply(&observed, &x),
        None => [0.0; 6],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classical::test_fixtures::left_camera;
    use crate::geometry::so3;
    use glam::DQuat;

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
            .map(|t| {
                let k = lidar.tree.nearest(t.world, 1.0).unwrap() as usize;
                lidar.points[k].distance(t.world)
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
    fn a_pose_a_degree_and_ten_centimetres_off_comes_back() {
        let (map, poses, camera) = (street(), drive(), left_camera());
        let pairs = pairs(camera, &poses, &map);
        let lidar = LidarMap::new(map);
        for (axis, offset) in [
            (DVec3::X, DVec3::new(0.0, 0.0, 0.1)),
            (DVec3::Y, DVec3::new(0.06, -0.06, 0.05)),
            (DVec3::Z, DVec3::new(-0.05, 0.07, -0.04)),
            (
                DVec3::new(0.2, -1.0, 1.0).normalize_or_zero(),
                DVec3::new(0.1, 0.0, 0.0),
            ),
        ] {
            let start = Rigid::new(
                so3::exp(axis * 1f64.to_radians()) * camera.rotation,
                camera.translation + offset,
            );
            let fit = fit_pose(&lidar, &pairs, &known(&poses), start).unwrap();
            let (rotation, translation) = fit.vehicle_from_camera.difference(camera);
            assert!(
                rotation.to_degrees() < 0.05 && translation < 0.02,
                "{axis} {offset}: {:.3}° / {:.1} cm ({fit:?})",
                rotation.to_degrees(),
                translation * 100.0
            );
            assert!(fit.unobserved.is_empty(), "{fit:?}");
        }
    }

    #[test]
    fn a_freed_turn_comes_back_with_the_height_and_the_held_turns_stay() {
        // The height-tilt valley: a side camera tilted up 0.5° about its own x and 5 cm low.
        // Freed about its x only, it comes back in both; a 0.3° turn about its own y, held,
        // is kept exactly.
        let (map, poses, camera) = (street(), drive(), left_camera());
        let pairs = pairs(camera, &poses, &map);
        let lidar = LidarMap::new(map);
        let held = so3::exp(DVec3::Y * 0.3f64.to_radians());
        let tilted = camera.rotation * so3::exp(DVec3::X * 0.5f64.to_radians()) * held;
        let start = Rigid::new(tilted, camera.translation - DVec3::Z * 0.05);
        let fit = fit_translation_and_turns(&lidar, &pairs, &known(&poses), start, &[0]).unwrap();
        let end = fit.vehicle_from_camera;
        let left = so3::log(camera.rotation.inverse() * end.rotation);
        // The held turn (a yaw) is made up for along the drive and sideways; the height is not.
        let height_error = end.translation.z - camera.translation.z;
        assert!(
            left.x.abs().to_degrees() < 0.03 && height_error.abs() < 0.01,
            "{left} {height_error} ({fit:?})"
        );
        // What is left of the rotation is the held turn about y (first order).
        assert!(
            (left.y.to_degrees() - 0.3).abs() < 0.01 && left.z.abs().to_degrees() < 0.01,
            "{left}"
        );
        assert!(fit.unobserved.is_empty(), "{fit:?}");
        // With nothing freed the tilt stays, and the height trades against it.
        let kept = fit_translation(&lidar, &pairs, &known(&poses), start).unwrap();
        let kept_height = kept.vehicle_from_camera.translation.z - camera.translation.z;
        assert!(
            kept_height.abs() > 0.02 && kept_height.abs() > 5.0 * height_error.abs(),
            "kept {kept_height}, freed {height_error}"
        );
    }

    #[test]
    fn on_the_ground_alone_the_pose_fit_names_and_keeps_what_it_cannot_see() {
        // Nothing in the ground fixes the position along it or the turn about its normal, so
        // those stay exactly where they started (the height, the roll and the pitch are
        // observed by it, more or less well depending on how far the points spread).
        let (poses, camera) = (drive(), left_camera());
        let ground: Vec<DVec3> = street()
            .into_iter()
            .filter(|p| p.z == 0.0 && p.y < 7.0)
            .collect();
        let pairs = pairs(camera, &poses, &ground);
        let lidar = LidarMap::new(ground);
        let turn = so3::exp(DVec3::new(1.0, 0.0, 1.0) * 1f64.to_radians());
        let offset = DVec3::new(0.1, 0.1, 0.1);
        let start = Rigid::new(turn * camera.rotation, camera.translation + offset);
        let fit = fit_pose(&lidar, &pairs, &known(&poses), start).unwrap();
        for name in ["x", "y", "yaw"] {
            assert!(fit.unobserved.contains(&name), "{name}: {fit:?}");
        }
        let end = fit.vehicle_from_camera;
        let moved = end.translation - camera.translation;
        assert!(
            (moved.x - 0.1).abs() < 1e-6 && (moved.y - 0.1).abs() < 1e-6,
            "{moved}"
        );
        let yaw = so3::log(end.rotation * camera.rotation.inverse()).z;
        assert!(
            (yaw.to_degrees() - 1.0).abs() < 0.01,
            "{}",
            yaw.to_degrees()
        );
        assert!(end.difference(camera).0 <= start.difference(camera).0 + 1e-9);
    }

    #[test]
    fn a_translation_fit_leaves_the_rotation_and_a_pose_fit_does_not() {
        // The same start, 1° off in yaw: the translation fit keeps the rotation exactly (and
        // moves the translation to make up for it as best it can); the pose fit turns it back.
        let (map, poses, camera) = (street(), drive(), left_camera());
        let pairs = pairs(camera, &poses, &map);
        let lidar = LidarMap::new(map);
        let start = Rigid::new(
            so3::exp(DVec3::Z * 1f64.to_radians()) * camera.rotation,
            camera.translation,
        );
        let kept = fit_translation(&lidar, &pairs, &known(&poses), start).unwrap();
        assert_eq!(kept.vehicle_from_camera.rotation, start.rotation);
        let turned = fit_pose(&lidar, &pairs, &known(&poses), start).unwrap();
        let error = |f: &MapFit| f.vehicle_from_camera.difference(camera).0.to_degrees();
        assert!(error(&turned) < 0.05, "{}", error(&turned));
        assert!(error(&kept) > 0.99, "{}", error(&kept));
    }

    /// The 6 × 6 diagonal information of points observing x, y, yaw well and the height
    /// `ground` times; roll and pitch `tilt` times.
    fn diagonal(ground: f64, tilt: f64) -> Mat6 {
        let d = [800.0, 5000.0, ground, tilt, tilt, 3000.0];
        std::array::from_fn(|i| std::array::from_fn(|j| if i == j { d[i] } else { 0.0 }))
    }

    #[test]
    fn a_direction_is_observed_by_enough_points_however_many_see_the_others() {
        // Thousands of points on a façade across the drive, sixty on the ground: the height is
        // observed; five are not enough.
        assert!(weak_directions(diagonal(60.0, 400.0)).is_empty());
        let weak = weak_directions(diagonal(5.0, 400.0));
        assert_eq!(weak.len(), 1);
        assert!(weak[0][2].abs() > 0.99, "{weak:?}");
        let h = diagonal(5.0, 400.0);
        let step = solve_observed(h, h, [800.0, 5000.0, 5.0, 400.0, 400.0, 3000.0]);
        let expected = [1.0, 1.0, 0.0, 1.0, 1.0, 1.0];
        assert!(
            (0..6).all(|k| (step[k] - expected[k]).abs() < 1e-9),
            "{step:?}"
        );
        // A fixed rotation (zero rows) moves nothing but the translation.
        let fixed = diagonal(60.0, 0.0);
        let mut fixed = fixed;
        fixed[5][5] = 0.0;
        let step = solve_observed(fixed, fixed, [800.0, 5000.0, 60.0, 0.0, 0.0, 0.0]);
        let expected = [1.0, 1.0, 1.0, 0.0, 0.0, 0.0];
        assert!(
            (0..6).all(|k| (step[k] - expected[k]).abs() < 1e-9),
            "{step:?}"
        );
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
        assert!(matches!(err, MapFitError::TooFewPoints { .. }), "{err}");
    }
}
