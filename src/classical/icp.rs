//! Point-to-plane ICP for a LiDAR–LiDAR pair (method.md §15.5; Low 2004), on stationary or
//! moving segments.
//!
//! How it works. The target LiDAR (fixed, usually the root) gives a cloud in the world frame:
//! every point moved with the trajectory at its own firing time (deskewed), voxel-downsampled
//! to [`IcpConfig::target_voxel_m`] (voxel centroids), each point with the normal of the least-squares plane of
//! its neighbours within 0.4 m (flat or gently curved neighbourhoods: [`IcpConfig::max_flatness`]; one pass
//! over the neighbourhood's moments, and only for target points a source point can reach). The
//! source LiDAR keeps its points in its own frame `p_i`, each with the vehicle pose `W_i` at its
//! firing time, so the unknown extrinsic `X = vehicle_from_source` enters every point as
//! `W_i X p_i` and a moving drive needs no per-sweep rigid approximation.
//!
//! One Gauss–Newton step: each source point's nearest target point `q` within the level's
//! correspondence distance gives the residual `r = n·(W X p − q)`. With the update
//! `X ← (I + [ω]×, τ) X` in the vehicle frame and `v = X p`, `m = R_Wᵀ n`, the Jacobian is
//! `[v × m, m]`; Huber weights (δ = [`IcpConfig::huber_m`]) make it robust, and the 6 × 6
//! normal equations are solved by Cholesky. Levels go coarse to fine: the source is thinned
//! by a voxel grid of each level's size and the correspondence distance shrinks with it (nearest
//! target points from a k-d tree built once, with ≤ 8-point leaves scanned linearly, each search
//! starting from the point's previous nearest neighbour); a level ends when the update is below 1e-6 rad / 1e-6 m or after its iteration budget.

use std::sync::atomic::{AtomicU32, Ordering};

use glam::DVec3;
use rayon::prelude::*;

use crate::eval::registration::plane_normal_from_moments;
use crate::geometry::{Rigid, so3};

/// How far beyond the widest correspondence distance a source point may move during a run (m):
/// target points farther than both from every starting source point get no normal.
const REACH_MARGIN_M: f64 = 2.0;
/// How many independent residuals an ICP result's information counts its points as.
pub const EFFECTIVE_POINTS: f64 = 200.0;
/// Points per parallel part of a sum over points; the parts are added in order, so a sum is
/// the same whatever the threads did.
pub const SUM_CHUNK: usize = 1024;
/// Radius of the neighbourhood a target normal is fitted to (m).
pub(crate) const NORMAL_RADIUS_M: f64 = 0.4;
/// Ranges this small are scanned linearly instead of descended (any order of a range is valid:
/// the tree is implicit in the array).
const LEAF: usize = 8;

/// A static k-d tree over the target points for nearest-neighbour queries: an implicit
/// balanced tree over a reordered array (the node of a range is its middle element, split on
/// the axis of the range's largest extent), built once by median selection.
pub(crate) struct KdTree {
    points: Vec<DVec3>,
    /// Original index of each reordered point.
    index: Vec<u32>,
    axis: Vec<u8>,
}

impl KdTree {
    pub(crate) fn new(points: &[DVec3]) -> Self {
        let mut order: Vec<(DVec3, u32)> = points.iter().copied().zip(0u32..).collect();
        let mut axis = vec![0u8; points.len()];
        Self::build(&mut order, &mut axis);
        Self {
            points: order.iter().map(|(p, _)| *p).collect(),
            index: order.iter().map(|(_, i)| *i).collect(),
            axis,
        }
    }

    fn build(items: &mut [(DVec3, u32)], axis: &mut [u8]) {
        if items.len() <= 1 {
            return;
        }
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for (p, _) in items.iter() {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        let extent = hi - lo;
        let a = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let m = items.len() / 2;
        items.select_nth_unstable_by(m, |x, y| x.0[a].total_cmp(&y.0[a]));
        axis[m] = a as u8;
        let (left, rest) = items.split_at_mut(m);
        let (left_axis, rest_axis) = axis.split_at_mut(m);
        Self::build(left, left_axis);
        Self::build(&mut rest[1..], &mut rest_axis[1..]);
    }

    /// [`Self::nearest`] starting from the point found last time for the same query point
    /// (`hint`, a position in the tree's order, updated): after the first iterations the
    /// answer barely moves, and a tight starting bound prunes most of the descent.
    pub(crate) fn nearest_hinted(&self, p: DVec3, max_m: f64, hint: &AtomicU32) -> Option<u32> {
        let mut best = (max_m * max_m, u32::MAX);
        let h = hint.load(Ordering::Relaxed);
        if let Some(q) = self.points.get(h as usize) {
            let d2 = q.distance_squared(p);
            if d2 <= best.0 {
                best = (d2, h);
            }
        }
        self.search(0, self.points.len(), p, &mut best);
        hint.store(best.1, Ordering::Relaxed);
        (best.1 != u32::MAX).then(|| self.index[best.1 as usize])
    }

    /// Original index of the nearest point within `max_m` of `p`.
    pub(crate) fn nearest(&self, p: DVec3, max_m: f64) -> Option<u32> {
        let mut best = (max_m * max_m, u32::MAX);
        self.search(0, self.points.len(), p, &mut best);
        (best.1 != u32::MAX).then(|| self.index[best.1 as usize])
    }

    /// Count, `Σ (q − p)` and `Σ (q − p)(q − p)ᵀ` over the points `q` within `radius_m` of `p`.
    pub(crate) fn moments(&self, p: DVec3, radius_m: f64) -> (usize, DVec3, glam::DMat3) {
        let mut m = (0, DVec3::ZERO, glam::DMat3::ZERO);
        self.moments_in(0, self.points.len(), p, radius_m * radius_m, &mut m);
        m
    }

    fn moments_in(
        &self,
        lo: usize,
        hi: usize,
        p: DVec3,
        r2: f64,
        m: &mut (usize, DVec3, glam::DMat3),
    ) {
        let mut add = |q: DVec3| {
            let d = q - p;
            if d.length_squared() <= r2 {
                m.0 += 1;
                m.1 += d;
                m.2 += so3::outer(d, d);
            }
        };
        if hi - lo <= LEAF {
            self.points[lo..hi].iter().for_each(|q| add(*q));
            return;
        }
        let mid = lo + (hi - lo) / 2;
        add(self.points[mid]);
        let a = self.axis[mid] as usize;
        let diff = p[a] - self.points[mid][a];
        if diff < 0.0 || diff * diff <= r2 {
            self.moments_in(lo, mid, p, r2, m);
        }
        if diff >= 0.0 || diff * diff <= r2 {
            self.moments_in(mid + 1, hi, p, r2, m);
        }
    }

    fn search(&self, lo: usize, hi: usize, p: DVec3, best: &mut (f64, u32)) {
        if hi - lo <= LEAF {
            for (k, q) in self.points[lo..hi].iter().enumerate() {
                let d2 = q.distance_squared(p);
                if d2 <= best.0 {
                    *best = (d2, (lo + k) as u32);
                }
            }
            return;
        }
        let m = lo + (hi - lo) / 2;
        let q = self.points[m];
        let d2 = q.distance_squared(p);
        if d2 <= best.0 {
            *best = (d2, m as u32);
        }
        let a = self.axis[m] as usize;
        let diff = p[a] - q[a];
        let (near, far) = if diff < 0.0 {
            ((lo, m), (m + 1, hi))
        } else {
            ((m + 1, hi), (lo, m))
        };
        self.search(near.0, near.1, p, best);
        if diff * diff <= best.0 {
            self.search(far.0, far.1, p, best);
        }
    }
}

/// `|cos|` of 75° of incidence. Grazing returns (the ground tens of metres ahead) carry the
/// range bias of an elongated footprint and, at long range, each beam's elevation error as a
/// height error: on the real PandaSet drive they alone tilt the PandarGT by 0.3° against the
/// Pandar64, while the returns above the ground agree with the reference within 0.03° of
/// pitch (docs/experiments/robustness-protocol.md, "Grazing returns").
pub const MIN_INCIDENCE_COS: f64 = 0.26;

/// The least share of the information, in every direction, the steep correspondences must
/// hold for the grazing ones to be left out ([`IcpProblem::new`]).
pub const MIN_STEEP_INFORMATION: f64 = 0.2;

#[derive(Clone, Debug, PartialEq)]
pub struct IcpConfig {
    /// Per level, coarse to fine: (source voxel size, correspondence distance), metres.
    pub levels: Vec<(f64, f64)>,
    pub iterations_per_level: usize,
    pub target_voxel_m: f64,
    pub huber_m: f64,
    /// A target point gets a normal when the variance across its neighbourhood's plane is at
    /// most this fraction of the total (⅓: any neighbourhood). 0.15 keeps gently curved
    /// surfaces (car bodies, poles) that pin the translation, and drops corners and clutter;
    /// the evaluation metric is stricter ([`crate::eval::registration::MAX_FLATNESS`]).
    pub max_flatness: f64,
    /// A correspondence is used only where the source ray meets the target plane at least this
    /// steeply: `|cos|` of the angle between the ray and the plane's normal (0: every one;
    /// default [`MIN_INCIDENCE_COS`]).
    pub min_incidence_cos: f64,
}

impl Default for IcpConfig {
    fn default() -> Self {
        Self {
            levels: vec![(0.8, 2.0), (0.4, 1.0), (0.2, 0.5), (0.1, 0.25)],
            iterations_per_level: 15,
            target_voxel_m: 0.1,
            huber_m: 0.1,
            max_flatness: 0.15,
            min_incidence_cos: MIN_INCIDENCE_COS,
        }
    }
}

/// A source point: in its sensor frame, with the vehicle pose at its firing time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SourcePoint {
    pub in_sensor: DVec3,
    pub world_from_vehicle: Rigid,
}

/// What one Gauss–Newton step saw.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct IcpStats {
    /// Source points with a planar target correspondence within the level's distance, as a
    /// share of the level's source points (Open3D's "fitness").
    pub fitness: f64,
    /// Root mean square point-to-plane distance of those inliers (m).
    pub inlier_rmse_m: f64,
    pub inliers: usize,
    pub level: usize,
    /// Size of the step just taken (rad, m).
    pub step_rad: f64,
    pub step_m: f64,
}

impl IcpStats {
    /// The statistics of `inliers` residuals with squared sum `sq` out of `points` on `level`
    /// (no step yet).
    pub(crate) fn of(inliers: usize, points: usize, sq: f64, level: usize) -> Self {
        Self {
            fitness: inliers as f64 / points.max(1) as f64,
            inlier_rmse_m: if inliers > 0 {
                (sq / inliers as f64).sqrt()
            } else {
                0.0
            },
            inliers,
            level,
            ..Self::default()
        }
    }
}

/// One LiDAR pair being registered.
pub struct IcpProblem {
    target: Vec<DVec3>,
    tree: KdTree,
    normals: Vec<DVec3>,
    /// Source points per level (voxel-thinned).
    sources: Vec<Vec<SourcePoint>>,
    /// Per level and source point: its last nearest target (tree order), to start the next
    /// search from.
    hints: Vec<Vec<AtomicU32>>,
    pub config: IcpConfig,
    pub vehicle_from_source: Rigid,
    pub level: usize,
    pub iteration: usize,
    pub done: bool,
    pub last: IcpStats,
    /// The grazing correspondences were kept: without them a direction was hardly observed.
    pub grazing_kept: bool,
}

/// One point per occupied voxel (the first one seen: deterministic, and a real point).
pub fn voxel_thin<T: Copy>(points: &[T], voxel_m: f64, position: impl Fn(&T) -> DVec3) -> Vec<T> {
    let mut seen = crate::util::FastSet::default();
    points
        .iter()
        .filter(|p| seen.insert((position(p) / voxel_m).floor().as_ivec3().to_array()))
        .copied()
        .collect()
}

/// The centroid of the points in each occupied voxel (in order of first appearance): noise
/// averages out of the target surface (as Open3D's voxel downsampling does).
pub fn voxel_centroids(points: &[DVec3], voxel_m: f64) -> Vec<DVec3> {
    let mut slot: crate::util::FastMap<[i32; 3], usize> = Default::default();
    let mut sums: Vec<(DVec3, u32)> = Vec::new();
    for p in points {
        let key = (*p / voxel_m).floor().as_ivec3().to_array();
        let k = *slot.entry(key).or_insert_with(|| {
            sums.push((DVec3::ZERO, 0));
            sums.len() - 1
        });
        sums[k].0 += *p;
        sums[k].1 += 1;
    }
    sums.into_iter().map(|(s, n)| s / n as f64).collect()
}

/// Apply a Gauss–Newton step `(ω, τ)` as `X ← (exp ω, τ) X` (left, in the vehicle frame),
/// recording its size; whether the level has converged (no step, or one below 1e-6 rad / m).
pub(crate) fn apply_step(x: &mut Rigid, step: Option<[f64; 6]>, stats: &mut IcpStats) -> bool {
    let Some(xi) = step else {
        return true;
    };
    let omega = DVec3::new(xi[0], xi[1], xi[2]);
    let tau = DVec3::new(xi[3], xi[4], xi[5]);
    *x = Rigid::new(so3::exp(omega), tau) * *x;
    stats.step_rad = omega.length();
    stats.step_m = tau.length();
    stats.step_rad < 1e-6 && stats.step_m < 1e-6
}

/// `(level, iteration, done)` after an iteration of `level`: the next level once this one has
/// converged or spent its budget.
pub(crate) fn next_level(
    config: &IcpConfig,
    level: usize,
    iteration: usize,
    converged: bool,
) -> (usize, usize, bool) {
    let iteration = iteration + 1;
    if converged || iteration >= config.iterations_per_level {
        (level + 1, 0, level + 1 >= config.levels.len())
    } else {
        (level, iteration, false)
    }
}

impl IcpProblem {
    /// `target_world`: the fixed LiDAR's points in the world; `source`: the other LiDAR's points
    /// with their poses; `start`: the initial `vehicle_from_source`.
    pub fn new(
        target_world: &[DVec3],
        source: &[SourcePoint],
        start: Rigid,
        config: IcpConfig,
    ) -> Self {
        let thinned = voxel_centroids(target_world, config.target_voxel_m);
        let all = KdTree::new(&thinned);
        // Every source point in the world under the starting extrinsic, once: it decides both
        // where normals are needed and which points each level's thinning keeps.
        let source_world: Vec<DVec3> = source
            .par_iter()
            .map(|s| {
                s.world_from_vehicle
                    .transform_point(start.transform_point(s.in_sensor))
            })
            .collect();
        // Normals only where the source can reach: target points farther from every source
        // point (under the start) than the widest correspondence distance plus a margin for
        // the extrinsic's change can never be a nearest neighbour. Cells of that size, each
        // source cell with its 26 neighbours, contain every point that can.
        let reach_m = config.levels.iter().map(|l| l.1).fold(0.0, f64::max) + REACH_MARGIN_M;
        let mut reachable = crate::util::FastSet::default();
        for s in source {
            let w = s
                .world_from_vehicle
                .transform_point(start.transform_point(s.in_sensor));
            let c = (w / reach_m).floor().as_ivec3();
            if reachable.contains(&c.to_array()) {
                continue;
            }
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        reachable.insert((c + glam::IVec3::new(dx, dy, dz)).to_array());
                    }
                }
            }
        }
        let with_normals: Vec<(DVec3, DVec3)> = thinned
            .par_iter()
            .filter(|p| reachable.contains(&(**p / reach_m).floor().as_ivec3().to_array()))
            .filter_map(|p| {
                let (n, sum, outer) = all.moments(*p, NORMAL_RADIUS_M);
                Some((
                    *p,
                    plane_normal_from_moments(n, sum, outer, config.max_flatness)?,
                ))
            })
            .collect();
        let target: Vec<DVec3> = with_normals.iter().map(|(p, _)| *p).collect();
        // Thin the source in the world under the starting extrinsic (close enough to decide
        // which points are redundant).
        let indices: Vec<usize> = (0..source.len()).collect();
        let sources = config
            .levels
            .par_iter()
            .map(|(voxel, _)| {
                voxel_thin(&indices, *voxel, |&i| source_world[i])
                    .into_iter()
                    .map(|i| source[i])
                    .collect::<Vec<SourcePoint>>()
            })
            .collect::<Vec<_>>();
        let tree = KdTree::new(&target);
        let hints = sources
            .iter()
            .map(|level: &Vec<SourcePoint>| {
                (0..level.len()).map(|_| AtomicU32::new(u32::MAX)).collect()
            })
            .collect();
        let mut problem = Self {
            tree,
            hints,
            normals: with_normals.iter().map(|(_, n)| *n).collect(),
            target,
            sources,
            config,
            vehicle_from_source: start,
            level: 0,
            iteration: 0,
            done: false,
            last: IcpStats::default(),
            grazing_kept: false,
        };
        problem.keep_grazing_where_needed();
        problem
    }

    /// Leave the grazing correspondences out only where the steeper ones still observe every
    /// direction of the extrinsic: along each eigenvector of the information of all
    /// correspondences (first level, at the start), the steep ones must hold at least
    /// [`MIN_STEEP_INFORMATION`] of it. A scene of flat ground and little else (a parking lot
    /// of targets) keeps them; a street, with its walls, cars and poles, does not need them.
    fn keep_grazing_where_needed(&mut self) {
        if self.config.min_incidence_cos <= 0.0 || self.sources.is_empty() {
            return;
        }
        let (all, ..) = self.normal_equations_with(0, 0.0);
        let (steep, ..) = self.normal_equations_with(0, self.config.min_incidence_cos);
        let square = |h: [f64; 36]| {
            std::array::from_fn::<_, 6, _>(|r| std::array::from_fn(|c| h[r * 6 + c]))
        };
        let (values, vectors) = crate::geometry::spd::symmetric_eigen(square(all));
        let steep = square(steep);
        let held = (0..6)
            .map(|k| {
                let e: [f64; 6] = std::array::from_fn(|r| vectors[r][k]);
                let along: f64 = (0..6)
                    .map(|r| (0..6).map(|c| e[r] * steep[r][c] * e[c]).sum::<f64>())
                    .sum();
                along / values[k].max(1e-12)
            })
            .fold(f64::INFINITY, f64::min);
        if held < MIN_STEEP_INFORMATION {
            self.config.min_incidence_cos = 0.0;
            self.grazing_kept = true;
        }
    }

    pub fn target_points(&self) -> usize {
        self.target.len()
    }

    /// One Gauss–Newton step at the current level; moves to the next level when converged.
    /// The Huber-weighted normal equations at the current extrinsic on `level`'s points and
    /// correspondence distance: (JᵀWJ row-major, JᵀWr, Σ r², inliers).
    fn normal_equations(&self, level: usize) -> ([f64; 36], [f64; 6], f64, usize) {
        self.normal_equations_with(level, self.config.min_incidence_cos)
    }

    /// [`Self::normal_equations`] with incidence limit `min_cos`.
    fn normal_equations_with(
        &self,
        level: usize,
        min_cos: f64,
    ) -> ([f64; 36], [f64; 6], f64, usize) {
        let max_d = self.config.levels[level].1;
        let tree = &self.tree;
        let x = self.vehicle_from_source;
        let huber = self.config.huber_m;
        let source = &self.sources[level];
        let hints = &self.hints[level];
        let (target, normals) = (&self.target, &self.normals);
        // Per point: (H upper 6×6 as 36, g 6, weighted squared residual sum, count).
        // Fixed chunks summed in order: rayon's `fold` groups by how work was stolen, so its
        // sums (and every run after them) would differ in the last bits from run to run.
        let parts: Vec<_> = source
            .par_chunks(SUM_CHUNK)
            .zip(hints.par_chunks(SUM_CHUNK))
            .map(|(source, hints)| {
                source.iter().zip(hints).fold(
                    ([0.0f64; 36], [0.0f64; 6], 0.0f64, 0usize),
                    |(mut h, mut g, mut sq, mut n), (s, hint)| {
                        let v = x.transform_point(s.in_sensor);
                        let w = s.world_from_vehicle.transform_point(v);
                        if let Some(i) = tree.nearest_hinted(w, max_d, hint) {
                            let (q, normal) = (target[i as usize], normals[i as usize]);
                            if min_cos > 0.0 {
                                let ray = (w - s.world_from_vehicle.transform_point(x.translation))
                                    .normalize_or_zero();
                                if ray.dot(normal).abs() < min_cos {
                                    return (h, g, sq, n);
                                }
                            }
                            let r = normal.dot(w - q);
                            let m = s.world_from_vehicle.rotation.inverse() * normal;
                            let a = v.cross(m);
                            let j = [a.x, a.y, a.z, m.x, m.y, m.z];
                            let weight = if r.abs() <= huber {
                                1.0
                            } else {
                                huber / r.abs()
                            };
                            for (row, jr) in j.iter().enumerate() {
                                g[row] += weight * jr * r;
                                for (col, jc) in j.iter().enumerate() {
                                    h[row * 6 + col] += weight * jr * jc;
                                }
                            }
                            sq += r * r;
                            n += 1;
                        }
                        (h, g, sq, n)
                    },
                )
            })
            .collect();
        parts
            .into_iter()
            .fold(([0.0f64; 36], [0.0f64; 6], 0.0f64, 0usize), |mut a, b| {
                a.0.iter_mut().zip(b.0).for_each(|(x, y)| *x += y);
                a.1.iter_mut().zip(b.1).for_each(|(x, y)| *x += y);
                (a.0, a.1, a.2 + b.2, a.3 + b.3)
            })
    }

    /// Information of the result for a pose graph, in the update's tangent (left perturbation
    /// of `vehicle_from_source` in the vehicle frame, rotation first): `JᵀWJ / σ²` on the finest
    /// level, σ the inlier RMS (at least 1 cm), with the points counted as
    /// [`EFFECTIVE_POINTS`] independent ones (neighbouring LiDAR points share their errors, so
    /// 10⁵ points do not make a 10⁻⁵ m answer).
    pub fn information(&self) -> [f64; 36] {
        let level = self.config.levels.len().saturating_sub(1);
        if self.sources.is_empty() {
            return [0.0; 36];
        }
        let (h, _, sq, n) = self.normal_equations(level);
        if n == 0 {
            return [0.0; 36];
        }
        let sigma_sq = (sq / n as f64).max(0.01 * 0.01);
        let scale = (EFFECTIVE_POINTS / n as f64).min(1.0) / sigma_sq;
        h.map(|v| v * scale)
    }

    pub fn step(&mut self) -> IcpStats {
        if self.done || self.level >= self.config.levels.len() {
            self.done = true;
            return self.last;
        }
        let (h, g, sq, inliers) = self.normal_equations(self.level);
        let mut stats = IcpStats::of(inliers, self.sources[self.level].len(), sq, self.level);
        let step = if inliers >= 6 {
            crate::geometry::spd::solve6(h, g.map(|v| -v))
        } else {
            None
        };
        let converged = apply_step(&mut self.vehicle_from_source, step, &mut stats);
        (self.level, self.iteration, self.done) =
            next_level(&self.config, self.level, self.iteration, converged);
        self.last = stats;
        stats
    }

    /// Step until every level is done.
    pub fn run(&mut self) -> IcpStats {
        while !self.done {
            self.step();
        }
        self.last
    }
}

#[cfg(test)]
mod tests;
