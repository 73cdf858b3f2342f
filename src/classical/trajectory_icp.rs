//! One LiDAR registered to the vehicle trajectory by its own sweeps (hand–eye calibration by
//! self-consistency): with the right `vehicle_from_lidar`, sweeps taken at different vehicle
//! poses land on the same surfaces when every point is moved into the world with the
//! trajectory at its firing time; a wrong one smears them apart, differently for every turn
//! the vehicle made between them. This is what puts the reference LiDAR where the trajectory
//! says it is before the other sensors are registered to it (pairwise ICP alone can only make
//! the rig agree with itself).
//!
//! How it works. The sweeps (spread over the drive, in time order) are split into two
//! interleaved sets; every point keeps its sensor-frame position `p` and the vehicle pose `W`
//! at its firing time. One Gauss–Newton step: under the current `X`, each set's points in the
//! world (one real point per 10 cm voxel) form a k-d tree; every point of the other set,
//! thinned per level as in [`super::icp`], finds its nearest neighbour `b` within the level's
//! correspondence distance, the normal `n` of the plane fitted around it (flat
//! neighbourhoods only), and the residual `r = n·(W_a X p_a − W_b X p_b)`. Both points move
//! with `X`, so with `X ← (I + [ω]×, τ) X` in the vehicle frame, `v = X p` and `m = R_Wᵀ n`,
//! the Jacobian is the difference of the two sides, `[v_a × m_a − v_b × m_b, m_a − m_b]`: it
//! vanishes between sweeps taken at the same pose, and only the vehicle's motion between
//! them makes `X` observable. A direction the drive does not excite (the LiDAR's height on a
//! flat drive: a vertical shift moves every sweep alike; every translation and the roll on a
//! straight one) has little or no curvature, and noise would move it by metres: the step is
//! solved only in the eigen-directions of the normal equations that the data observe, so the
//! others keep their start ([`TrajectoryIcp::unobserved`] names them). Huber weights,
//! coarse-to-fine levels and the convergence rule are [`super::icp`]'s.

use glam::DVec3;
use rayon::prelude::*;

use super::icp::{
    EFFECTIVE_POINTS, IcpConfig, IcpStats, KdTree, NORMAL_RADIUS_M, SourcePoint, apply_step,
    next_level, voxel_thin,
};
use crate::eval::registration::plane_normal_from_moments;
use crate::geometry::Rigid;

/// Lever arm that puts rotations on the scale of translations (m): a rotation of ω rad
/// counts as a displacement of ω · this.
const LEVER_M: f64 = 10.0;
/// A direction of the (scaled) normal equations whose standard deviation would exceed this
/// (m; rotations as displacements at [`LEVER_M`]) is not observed by the drive and gets no
/// step. With the residuals' RMS σ (at least 1 cm) and the points counted as
/// [`EFFECTIVE_POINTS`] independent ones, an eigenvalue λ of `JᵀJ` gives σ / √(λ · 200 / n).
/// On the simulator's figure-8 every direction but the height is within 1 cm; on the real
/// PandaSet drive (straight) three are within 1–5 cm and the others at 0.3–18 m.
const MAX_STD_M: f64 = 0.1;

/// The registration of one LiDAR against the trajectory.
pub struct TrajectoryIcp {
    /// Both sets' points, one real point per target voxel (under the start).
    targets: [Vec<SourcePoint>; 2],
    /// Per level, both sets' points thinned by the level's voxel.
    sources: Vec<[Vec<SourcePoint>; 2]>,
    pub config: IcpConfig,
    pub vehicle_from_lidar: Rigid,
    pub level: usize,
    pub iteration: usize,
    pub done: bool,
    pub last: IcpStats,
    /// Per direction (roll, pitch, yaw, x, y, z): whether the last step left it out, as the
    /// dominant part of an unobserved direction of the normal equations.
    unobserved: [bool; 6],
}

/// Residual and Jacobian of one correspondence: the normal equations' contributions.
type Normal = ([f64; 36], [f64; 6], f64, usize);

fn add(mut a: Normal, b: Normal) -> Normal {
    a.0.iter_mut().zip(b.0).for_each(|(x, y)| *x += y);
    a.1.iter_mut().zip(b.1).for_each(|(x, y)| *x += y);
    (a.0, a.1, a.2 + b.2, a.3 + b.3)
}

impl TrajectoryIcp {
    /// `sweeps`: the LiDAR's points per sweep, in time order, each with the vehicle pose at
    /// its firing time; `start`: the initial `vehicle_from_lidar`. `None` with fewer than two
    /// sweeps.
    pub fn new(sweeps: &[Vec<SourcePoint>], start: Rigid, config: IcpConfig) -> Option<Self> {
        if sweeps.len() < 2 {
            return None;
        }
        let world = |s: &SourcePoint| {
            s.world_from_vehicle
                .transform_point(start.transform_point(s.in_sensor))
        };
        let set = |k: usize| -> Vec<SourcePoint> {
            sweeps
                .iter()
                .skip(k)
                .step_by(2)
                .flat_map(|s| s.iter().copied())
                .collect()
        };
        let sets = [set(0), set(1)];
        let targets = [
            voxel_thin(&sets[0], config.target_voxel_m, world),
            voxel_thin(&sets[1], config.target_voxel_m, world),
        ];
        let sources = config
            .levels
            .iter()
            .map(|(voxel, _)| {
                [
                    voxel_thin(&targets[0], *voxel, world),
                    voxel_thin(&targets[1], *voxel, world),
                ]
            })
            .collect();
        Some(Self {
            targets,
            sources,
            config,
            vehicle_from_lidar: start,
            level: 0,
            iteration: 0,
            done: false,
            last: IcpStats::default(),
            unobserved: [false; 6],
        })
    }

    /// The normal equations at the current extrinsic on `level`: both sets against the other.
    fn normal_equations(&self, level: usize) -> Normal {
        let x = self.vehicle_from_lidar;
        let (max_d, huber) = (self.config.levels[level].1, self.config.huber_m);
        let world = |s: &SourcePoint| {
            s.world_from_vehicle
                .transform_point(x.transform_point(s.in_sensor))
        };
        let zero = || ([0.0f64; 36], [0.0f64; 6], 0.0f64, 0usize);
        let mut total = zero();
        for set in 0..2 {
            let target = &self.targets[1 - set];
            let positions: Vec<DVec3> = target.par_iter().map(world).collect();
            let tree = KdTree::new(&positions);
            // Fixed chunks summed in order (deterministic; rayon's `fold` groups by stealing).
            let parts: Vec<_> = self.sources[level][set]
                .par_chunks(crate::classical::icp::SUM_CHUNK)
                .map(|chunk| {
                    chunk.iter().fold(zero(), |acc, a| {
                        let wa = world(a);
                        let Some(i) = tree.nearest(wa, max_d) else {
                            return acc;
                        };
                        let (b, wb) = (&target[i as usize], positions[i as usize]);
                        let (count, sum, outer) = tree.moments(wb, NORMAL_RADIUS_M);
                        let Some(n) =
                            plane_normal_from_moments(count, sum, outer, self.config.max_flatness)
                        else {
                            return acc;
                        };
                        let r = n.dot(wa - wb);
                        let (va, vb) = (
                            x.transform_point(a.in_sensor),
                            x.transform_point(b.in_sensor),
                        );
                        let ma = a.world_from_vehicle.rotation.inverse() * n;
                        let mb = b.world_from_vehicle.rotation.inverse() * n;
                        let (rot, trans) = (va.cross(ma) - vb.cross(mb), ma - mb);
                        let j = [rot.x, rot.y, rot.z, trans.x, trans.y, trans.z];
                        let w = if r.abs() <= huber {
                            1.0
                        } else {
                            huber / r.abs()
                        };
                        let (mut h, mut g, sq, k) = acc;
                        for (row, jr) in j.iter().enumerate() {
                            g[row] += w * jr * r;
                            for (col, jc) in j.iter().enumerate() {
                                h[row * 6 + col] += w * jr * jc;
                            }
                        }
                        (h, g, sq + r * r, k + 1)
                    })
                })
                .collect();
            total = parts.into_iter().fold(total, add);
        }
        total
    }

    /// One damped Gauss–Newton step at the current level; moves to the next level when
    /// converged.
    pub fn step(&mut self) -> IcpStats {
        if self.done || self.level >= self.config.levels.len() {
            self.done = true;
            return self.last;
        }
        let (h, g, sq, inliers) = self.normal_equations(self.level);
        let points = self.sources[self.level][0].len() + self.sources[self.level][1].len();
        let mut stats = IcpStats::of(inliers, points, sq, self.level);
        let step = if inliers >= 6 {
            let sigma_m = (sq / inliers as f64).sqrt().max(0.01);
            let (xi, unobserved) = observed_step(h, g, sigma_m, inliers);
            self.unobserved = unobserved;
            Some(xi)
        } else {
            None
        };
        let converged = apply_step(&mut self.vehicle_from_lidar, step, &mut stats);
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

    /// The directions (vehicle frame) the drive did not observe at the last step, by the name
    /// of each one's dominant part: `"roll"`, `"pitch"`, `"yaw"` (rotation about the vehicle's
    /// axes), `"x"`, `"y"`, `"z"` (translation along them). They stay at the start.
    pub fn unobserved(&self) -> Vec<&'static str> {
        let names = ["roll", "pitch", "yaw", "x", "y", "z"];
        (0..6)
            .filter(|&k| self.unobserved[k])
            .map(|k| names[k])
            .collect()
    }
}

/// The Gauss–Newton step `−H⁻¹ g` restricted to the directions the data observe: with
/// rotations scaled by [`LEVER_M`], the eigenvectors of `H` (from `inliers` residuals of RMS
/// `sigma_m`) whose standard deviation would exceed [`MAX_STD_M`] get no step (a
/// degeneracy-aware solve: on a straight drive noise would otherwise move the translation by
/// metres). Also which named direction dominates each left-out eigenvector.
fn observed_step(h: [f64; 36], g: [f64; 6], sigma_m: f64, inliers: usize) -> ([f64; 6], [bool; 6]) {
    let scale = [1.0 / LEVER_M, 1.0 / LEVER_M, 1.0 / LEVER_M, 1.0, 1.0, 1.0];
    let mut scaled = [[0.0; 6]; 6];
    for (r, row) in scaled.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = scale[r] * h[r * 6 + c] * scale[c];
        }
    }
    let gs: [f64; 6] = std::array::from_fn(|k| scale[k] * g[k]);
    let (values, vectors) = crate::geometry::spd::symmetric_eigen(scaled);
    // λ beyond which a direction's standard deviation is within MAX_STD_M.
    let needed = (sigma_m / MAX_STD_M).powi(2) * inliers as f64 / EFFECTIVE_POINTS;
    let mut y = [0.0; 6];
    let mut unobserved = [false; 6];
    for k in 0..6 {
        let v: [f64; 6] = std::array::from_fn(|r| vectors[r][k]);
        if values[k] > 0.0 && values[k] >= needed {
            let along = v.iter().zip(&gs).map(|(a, b)| a * b).sum::<f64>() / values[k];
            y.iter_mut().zip(&v).for_each(|(yi, vi)| *yi -= along * vi);
        } else {
            let dominant = (0..6)
                .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
                .unwrap_or(0);
            unobserved[dominant] = true;
        }
    }
    (std::array::from_fn(|k| scale[k] * y[k]), unobserved)
}

/// The least heading change (degrees) between the sweeps at which a drive observes every
/// direction of a LiDAR's pose but its height (on a level drive).
pub const MIN_TURN_DEG: f64 = 30.0;

/// The least distance (m) between the first and the last sweep at which a drive that turns
/// less than [`MIN_TURN_DEG`] is still fitted, in the directions its travel observes (a
/// straight drive: the LiDAR's pitch and yaw, through the direction of travel in its frame;
/// its roll about that direction and its position keep their start). Those two matter: sweeps
/// taken 50 m apart by a LiDAR pitched 1° wrong put one wall about 90 cm apart, a scene no
/// later stage can learn. Shorter, the direction of travel is known too poorly: on 4 s of the
/// real PandaSet drive the fit moved the Pandar64, which is that log's vehicle frame, 0.67° off
/// the identity (a LiDAR that is the vehicle frame is not fitted at all: the pipeline's plan).
pub const MIN_STRAIGHT_DISTANCE_M: f64 = 20.0;

/// What [`register_to_trajectory`] found.
#[derive(Clone, Debug, PartialEq)]
pub enum TrajectoryFit {
    /// The registered `vehicle_from_lidar` and the directions the drive did not observe
    /// (left at the start).
    Fitted {
        vehicle_from_lidar: Rigid,
        unobserved: Vec<&'static str>,
    },
    /// The drive turns too little between the sweeps (largest heading change, degrees) and
    /// travels too little (m) for its direction of travel to place the LiDAR: it is better
    /// left where it is.
    TooStraight { turn_deg: f64, distance_m: f64 },
    /// Too few consecutive sweeps share surfaces: `pairs` of them are near enough
    /// ([`super::trajectory_sweeps`]).
    TooSparse { pairs: usize },
}

/// Register LiDAR `name` of `rig` to `drive`'s trajectory on about `frames` sweeps over the
/// segments that share surfaces ([`super::trajectory_sweeps::pick`]; every second point),
/// reporting `(steps done, steps)`.
pub fn register_to_trajectory(
    drive: &crate::log::Drive,
    rig: &crate::calib::Rig,
    name: &str,
    frames: usize,
    segments_nanos: &[(i64, i64)],
    config: IcpConfig,
    report: &mut dyn FnMut(usize, usize),
) -> Result<TrajectoryFit, crate::error::RunError> {
    let start = rig
        .sensor(name)
        .ok_or_else(|| crate::error::RunError::no_sensor("LiDAR", name))?
        .vehicle_from_sensor;
    let picked = match super::trajectory_sweeps::pick(drive, name, frames, segments_nanos) {
        super::trajectory_sweeps::Picked::Sweeps(picked) => picked,
        super::trajectory_sweeps::Picked::TooSparse { pairs } => {
            return Ok(TrajectoryFit::TooSparse { pairs });
        }
    };
    // A sweep that does not decode is skipped (and reported by the drive).
    let sweeps: Vec<_> = picked
        .into_iter()
        .filter_map(|i| drive.sweep_or_skip(name, i))
        .map(|sweep| super::icp_calibrator::source_points(&sweep, &drive.trajectory, 2))
        .collect();
    let turn_deg = heading_change_rad(&sweeps).to_degrees();
    let distance_m = travel_m(&sweeps);
    if turn_deg < MIN_TURN_DEG && distance_m < MIN_STRAIGHT_DISTANCE_M {
        return Ok(TrajectoryFit::TooStraight {
            turn_deg,
            distance_m,
        });
    }
    let mut icp = TrajectoryIcp::new(&sweeps, start, config).ok_or_else(|| {
        crate::error::RunError::NotEnoughData(format!(
            "'{name}': fewer than two sweeps inside the trajectory and the selected segments"
        ))
    })?;
    let total = icp.config.levels.len() * icp.config.iterations_per_level;
    let mut done = 0;
    while !icp.done {
        icp.step();
        done += 1;
        report(done.min(total), total);
    }
    // The steps turn the LiDAR about the vehicle's origin, which also moves its position; a
    // position the drive does not observe keeps its start along that axis.
    let unobserved = icp.unobserved();
    let mut vehicle_from_lidar = icp.vehicle_from_lidar;
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        if unobserved.contains(axis) {
            vehicle_from_lidar.translation[k] = start.translation[k];
        }
    }
    Ok(TrajectoryFit::Fitted {
        vehicle_from_lidar,
        unobserved,
    })
}

/// The distance between the vehicle's positions at the first and the last sweep (m).
pub fn travel_m(sweeps: &[Vec<SourcePoint>]) -> f64 {
    let at = |s: Option<&Vec<SourcePoint>>| {
        s.and_then(|s| s.first())
            .map(|p| p.world_from_vehicle.translation)
    };
    match (at(sweeps.first()), at(sweeps.last())) {
        (Some(a), Some(b)) => a.distance(b),
        _ => 0.0,
    }
}

/// The largest rotation between the vehicle's poses at the sweeps' first points (rad).
pub fn heading_change_rad(sweeps: &[Vec<SourcePoint>]) -> f64 {
    let poses: Vec<Rigid> = sweeps
        .iter()
        .filter_map(|s| s.first().map(|p| p.world_from_vehicle))
        .collect();
    let mut largest: f64 = 0.0;
    for (i, a) in poses.iter().enumerate() {
        for b in &poses[i + 1..] {
            largest = largest.max(a.difference(*b).0);
        }
    }
    largest
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::so3;

    /// Points on a street-like scene (ground, two façades, a crossing wall, poles) seen by a
    /// LiDAR mounted at `x` on a level vehicle: `sweeps` sweeps along an S-curve (`turning`)
    /// or a straight 16 m, each the scene's points within 25 m of the vehicle, in the sensor
    /// frame.
    fn drive(x: Rigid, sweeps: usize, turning: bool) -> Vec<Vec<SourcePoint>> {
        let mut scene = Vec::new();
        for i in -60..60 {
            for j in -60..60 {
                let (a, b) = (i as f64 * 0.5, j as f64 * 0.5);
                scene.push(DVec3::new(a, b, 0.0));
                if j % 3 == 0 {
                    let z = 0.1 * (j + 60) as f64;
                    scene.push(DVec3::new(a, 12.0 + 0.1 * b.sin(), z));
                    scene.push(DVec3::new(a, -12.0, z));
                    scene.push(DVec3::new(25.0, a, z));
                    scene.push(DVec3::new(-25.0, a, z));
                }
            }
        }
        for k in 0..8 {
            let c = DVec3::new(
                -20.0 + 6.0 * k as f64,
                if k % 2 == 0 { 6.0 } else { -6.0 },
                0.0,
            );
            for h in 0..40 {
                for t in 0..12 {
                    let a = t as f64 * std::f64::consts::TAU / 12.0;
                    scene.push(c + DVec3::new(0.3 * a.cos(), 0.3 * a.sin(), 0.1 * h as f64));
                }
            }
        }
        (0..sweeps)
            .map(|s| {
                let phase = s as f64 / (sweeps - 1) as f64;
                // An S-curve (yaw ±69°, 24 m): a single arc of constant curvature would leave
                // a combination of yaw and translation along the arc unobserved.
                let (yaw, position) = if turning {
                    let yaw_at = |t: f64| 1.2 * (std::f64::consts::TAU * t).sin();
                    let mut position = DVec3::new(-12.0, -4.0, 0.0);
                    for k in 0..200 {
                        let t = phase * (k as f64 + 0.5) / 200.0;
                        let y = yaw_at(t);
                        position += DVec3::new(y.cos(), y.sin(), 0.0) * 24.0 * phase / 200.0;
                    }
                    (yaw_at(phase), position)
                } else {
                    (0.0, DVec3::new(16.0 * phase - 8.0, 0.0, 0.0))
                };
                let world_from_vehicle = Rigid::new(glam::DQuat::from_rotation_z(yaw), position);
                let sensor_from_world = (world_from_vehicle * x).inverse();
                scene
                    .iter()
                    .filter(|p| p.distance(position) < 25.0)
                    .map(|p| SourcePoint {
                        in_sensor: sensor_from_world.transform_point(*p),
                        world_from_vehicle,
                    })
                    .collect()
            })
            .collect()
    }

    fn truth() -> Rigid {
        Rigid::new(glam::DQuat::from_rotation_z(0.3), DVec3::new(1.2, 0.1, 1.8))
    }

    #[test]
    fn a_lidar_is_registered_to_the_trajectory_from_both_sides() {
        let sweeps = drive(truth(), 10, true);
        for sign in [1.0, -1.0] {
            let start = truth().perturbed_right(
                DVec3::new(1.2, -1.0, 1.4).normalize_or_zero() * sign * 2f64.to_radians(),
                DVec3::new(0.1, -0.12, 0.08) * sign,
            );
            let mut icp = TrajectoryIcp::new(&sweeps, start, IcpConfig::default()).unwrap();
            icp.run();
            let found = icp.vehicle_from_lidar;
            let (rot, _) = truth().difference(found);
            let off = found.translation - truth().translation;
            assert!(
                rot.to_degrees() < 0.02 && off.truncate().length() < 0.005,
                "sign {sign}: {:.3}° / {off:?} m",
                rot.to_degrees(),
            );
            // A level drive does not observe the height: no step moves it (the rotation's
            // correction about the vehicle's origin still carries the mount along).
            assert_eq!(icp.unobserved(), vec!["z"]);
            let step = found * start.inverse();
            assert!(step.translation.z.abs() < 2e-3, "{step:?}");
        }
    }

    #[test]
    fn a_straight_drive_keeps_the_translation_and_fixes_what_it_observes() {
        let sweeps = drive(truth(), 10, false);
        // Pitch and yaw in the vehicle frame, and a translation.
        let start = Rigid::new(
            so3::exp(DVec3::new(0.0, 0.02, 0.02)),
            DVec3::new(0.1, -0.12, 0.08),
        ) * truth();
        let mut icp = TrajectoryIcp::new(&sweeps, start, IcpConfig::default()).unwrap();
        icp.run();
        let step = icp.vehicle_from_lidar * start.inverse();
        let moved = step.translation.length();
        assert!(moved < 0.005, "translation stepped {moved} m");
        for name in ["x", "y", "z"] {
            assert!(icp.unobserved().contains(&name), "{:?}", icp.unobserved());
        }
        // The travel direction in the sensor frame fixes pitch and yaw.
        let (before, _) = truth().difference(start);
        let (after, _) = truth().difference(icp.vehicle_from_lidar);
        assert!(after < 0.05 * before, "{before} -> {after} rad");
    }

    #[test]
    fn a_drive_without_motion_leaves_the_start_and_says_so() {
        let one = drive(truth(), 8, true).remove(3);
        let sweeps = vec![one.clone(), one];
        let start = truth().perturbed_right(DVec3::new(0.0, 0.0, 0.02), DVec3::new(0.1, 0.0, 0.0));
        let mut icp = TrajectoryIcp::new(&sweeps, start, IcpConfig::default()).unwrap();
        icp.run();
        let (rot, trans) = start.difference(icp.vehicle_from_lidar);
        assert!(rot < 1e-9 && trans < 1e-9, "{rot} {trans}");
        assert_eq!(icp.unobserved().len(), 6, "{:?}", icp.unobserved());
        assert!(TrajectoryIcp::new(&sweeps[..1], start, IcpConfig::default()).is_none());
        assert_eq!(heading_change_rad(&sweeps), 0.0);
        // The S-curve turns by twice its 1.2 rad amplitude.
        let turn = heading_change_rad(&drive(truth(), 10, true));
        assert!((turn - 2.4).abs() < 0.1, "{turn}");
    }
}
