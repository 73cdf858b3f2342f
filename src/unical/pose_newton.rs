//! Preconditioned pose steps for LiDARs: Gauss–Newton on the depth term, with the
//! rendered scene as the surface (ICP against the learned scene), instead of Adam.
//!
//! Why: a LiDAR's rotation acts on its rays through their range (a 0.1° error moves a return
//! 50 m away by 9 cm) while its translation does not, and the two are coupled wherever the
//! sensor sees one side of the street more than the other. Adam scales each parameter by its
//! own gradient noise, so the rotation settles at once into the valley that best explains the
//! translation error and the translation then crawls along that valley; against a frozen scene
//! learned at the true extrinsics it did not recover 9 cm in 250 steps (docs/experiments/unical-lidar-terms.md). A
//! Gauss–Newton step takes the valley in one move.
//!
//! Each LiDAR ray whose rendered accumulation A exceeds 0.5 gives one row: the rendered surface
//! point `p = o + (D/A) d`, the unit normal `n` of the SDF there (over a 15 cm stencil: the
//! exact gradient of a hash-grid field is dominated by its finest cells), the signed point-to-plane
//! distance `e = (D/A − range)·|n·d|` and its Jacobian in the pose tangent. For a plane,
//! `∂D/∂o = −n/(n·d)` and `∂D/∂d = −D n/(n·d)`, so `∂e/∂o = −sign(n·d) n` and
//! `∂e/∂d = −sign(n·d) D n`. Rows are weighted by a Cauchy kernel whose scale follows the
//! batch's median |e| (with a floor), which anneals from coarse to fine as the pose converges,
//! and grazing rays (|n·d| small) are left out. The scene keeps learning from the full
//! objective; only the LiDAR poses take these steps. A pose stays fixed for `interval`
//! iterations while the scene settles around it, and one step is taken from the rows of all of
//! them (tracking against a map that is mapped with fixed poses, in SLAM terms).
//!
//! The tangent of a pose: `ω` rotates the sensor about its own origin (`R_s ← exp(ω) R_s`, in
//! the vehicle frame) and `v` translates it (`t_s ← t_s + v`). For a ray `o = P·t_s`,
//! `d = R_P R_s u`: `∂/∂v = R_Pᵀ ∂/∂o`, `∂/∂ω = (R_s u) × (R_Pᵀ ∂/∂d)`.

use glam::DVec3;

use super::pose::PoseParams;
use crate::geometry::{Rigid, so3, spd};

/// How LiDAR poses are updated.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum PoseUpdate {
    /// Adam on the 6D rotation and translation (the paper, §12).
    Adam,
    /// The preconditioned step of this module.
    Newton(NewtonConfig),
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NewtonConfig {
    /// Levenberg damping: `λ` times the diagonal of `H` is added to it.
    pub damping: f64,
    /// Fraction of the full step taken.
    pub step: f64,
    /// Iterations between steps: the pose stays fixed while the scene settles around it and
    /// the rows of every iteration in between are gathered into one system.
    pub interval: usize,
    /// Largest rotation (rad) and translation (m) of one step.
    pub max_rotation_rad: f64,
    pub max_translation_m: f64,
    /// Rays whose surface is seen more grazing than this (|n·d|) give no row.
    pub min_incidence_cos: f64,
    /// The surface normal is the SDF's gradient over a tetrahedral stencil this wide
    /// ([`super::regulariser::smoothed_gradient`]).
    pub normal_stencil_m: f64,
    /// The Cauchy kernel's scale: this many times the batch's median |e|, at least `floor`.
    pub robust_scale: f64,
    pub robust_floor_m: f64,
}

impl Default for NewtonConfig {
    fn default() -> Self {
        Self {
            damping: 0.1,
            step: 1.0,
            interval: 10,
            max_rotation_rad: 0.5f64.to_radians(),
            max_translation_m: 0.05,
            min_incidence_cos: 0.1,
            normal_stencil_m: 0.15,
            robust_scale: 3.0,
            robust_floor_m: 0.02,
        }
    }
}

/// One ray's point-to-plane residual (m) against the rendered surface and its Jacobian in
/// the pose tangent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseRow {
    pub jacobian: [f64; 6],
    pub residual_m: f64,
    /// Where the rendered surface of the row's ray is (world frame).
    pub surface_world: DVec3,
}

/// The row of a ray of `pose` (vehicle at `world_from_vehicle`, sensor direction `u`, world
/// direction `d`) whose rendered surface at `surface_depth_m` has normal `normal` (any length,
/// either orientation), for a measured `range_m`: `None` when the ray grazes the surface (|n·d|
/// below `min_cos`) or the normal is degenerate.
pub fn plane_row(
    world_from_vehicle: Rigid,
    pose: &PoseParams,
    u: DVec3,
    d: DVec3,
    normal: DVec3,
    surface_depth_m: f64,
    range_m: f64,
    min_cos: f64,
) -> Option<PoseRow> {
    let n = normal.try_normalize()?;
    let cos = n.dot(d);
    if cos.is_nan() || cos.abs() < min_cos {
        return None;
    }
    let d_origin = -n * cos.signum();
    let origin = pose.ray(world_from_vehicle, u).0;
    Some(PoseRow {
        jacobian: to_tangent(
            world_from_vehicle,
            pose,
            u,
            d_origin,
            d_origin * surface_depth_m,
        ),
        residual_m: (surface_depth_m - range_m) * cos.abs(),
        surface_world: origin + d * surface_depth_m,
    })
}

/// The Gauss–Newton system of `rows` under a Cauchy kernel of scale `max(k·median|e|, floor)`:
/// `H = Σ wᵢ Jᵢ Jᵢᵀ`, `g = Σ wᵢ eᵢ Jᵢ` with `wᵢ = 1 / (1 + (eᵢ/c)²)`.
pub fn robust_system(rows: &[PoseRow], robust_scale: f64, floor_m: f64) -> TangentSystem {
    let mut system = TangentSystem::default();
    if rows.is_empty() {
        return system;
    }
    let mut abs: Vec<f64> = rows.iter().map(|r| r.residual_m.abs()).collect();
    let mid = abs.len() / 2;
    let median = *abs.select_nth_unstable_by(mid, f64::total_cmp).1;
    let c = (robust_scale * median).max(floor_m);
    for row in rows {
        let w = 1.0 / (1.0 + (row.residual_m / c).powi(2));
        system.add_curvature(row.jacobian, w);
        system.add_gradient(row.jacobian.map(|j| w * row.residual_m * j));
    }
    system
}

/// A batch's gradient and curvature in the pose tangent `(ω, v)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TangentSystem {
    /// Row-major 6 × 6.
    pub hessian: [f64; 36],
    pub gradient: [f64; 6],
}

impl Default for TangentSystem {
    fn default() -> Self {
        Self {
            hessian: [0.0; 36],
            gradient: [0.0; 6],
        }
    }
}

impl TangentSystem {
    /// `self += scale · other`.
    pub fn add_scaled(&mut self, other: &TangentSystem, scale: f64) {
        for (a, b) in self.hessian.iter_mut().zip(&other.hessian) {
            *a += b * scale;
        }
        for (a, b) in self.gradient.iter_mut().zip(&other.gradient) {
            *a += b * scale;
        }
    }

    /// Add `weight · j jᵀ` to the curvature.
    pub fn add_curvature(&mut self, j: [f64; 6], weight: f64) {
        for r in 0..6 {
            for c in 0..6 {
                self.hessian[r * 6 + c] += weight * j[r] * j[c];
            }
        }
    }

    pub fn add_gradient(&mut self, g: [f64; 6]) {
        for (a, b) in self.gradient.iter_mut().zip(g) {
            *a += b;
        }
    }
}

/// `(∂/∂o, ∂/∂d)` of one ray in the tangent of `pose` (vehicle at `world_from_vehicle`, sensor
/// direction `u`): `[(R_s u) × (R_Pᵀ ∂/∂d), R_Pᵀ ∂/∂o]`.
pub fn to_tangent(
    world_from_vehicle: Rigid,
    pose: &PoseParams,
    u: DVec3,
    d_origin: DVec3,
    d_direction: DVec3,
) -> [f64; 6] {
    let rpt = world_from_vehicle.rotation_matrix().transpose();
    let a = pose.rotation() * u;
    let w = a.cross(rpt * d_direction);
    let v = rpt * d_origin;
    [w.x, w.y, w.z, v.x, v.y, v.z]
}

/// The running state of one sensor's preconditioned steps: the rows gathered since its last
/// step.
#[derive(Clone, Debug)]
pub struct NewtonState {
    config: NewtonConfig,
    rows: Vec<PoseRow>,
    iterations: usize,
}

impl NewtonState {
    pub fn new(config: NewtonConfig) -> Self {
        Self {
            config,
            rows: Vec::new(),
            iterations: 0,
        }
    }

    /// Add one iteration's rows; true when a step is due.
    pub fn gather(&mut self, rows: &mut Vec<PoseRow>) -> bool {
        self.rows.append(rows);
        self.iterations += 1;
        self.iterations >= self.config.interval.max(1)
    }

    /// Move `pose` by the step of the gathered rows, scaled by `schedule` ∈ [0, 1] (the decay of
    /// the pose learning rate), and start gathering anew. Returns the tangent step taken (zero
    /// when the system is singular).
    pub fn step(&mut self, pose: &mut PoseParams, schedule: f64) -> [f64; 6] {
        let system = robust_system(
            &self.rows,
            self.config.robust_scale,
            self.config.robust_floor_m,
        );
        self.rows.clear();
        self.iterations = 0;
        self.solve_and_apply(pose, &system, schedule)
    }

    /// The damped step of `system`, scaled and capped, applied to `pose`.
    pub fn solve_and_apply(
        &self,
        pose: &mut PoseParams,
        system: &TangentSystem,
        schedule: f64,
    ) -> [f64; 6] {
        let mut a = system.hessian;
        let trace: f64 = (0..6).map(|i| a[i * 6 + i]).sum();
        for i in 0..6 {
            a[i * 6 + i] += self.config.damping * a[i * 6 + i] + 1e-9 * trace.max(1e-12);
        }
        let Some(mut delta) = spd::solve6(a, system.gradient.map(|v| -v)) else {
            return [0.0; 6];
        };
        let scale = self.config.step * schedule.clamp(0.0, 1.0);
        delta.iter_mut().for_each(|v| *v *= scale);
        let mut omega = DVec3::new(delta[0], delta[1], delta[2]);
        let mut v = DVec3::new(delta[3], delta[4], delta[5]);
        if omega.length() > self.config.max_rotation_rad {
            omega *= self.config.max_rotation_rad / omega.length();
        }
        if v.length() > self.config.max_translation_m {
            v *= self.config.max_translation_m / v.length();
        }
        let rotation = so3::exp_mat(omega) * pose.rotation();
        *pose = PoseParams::from_rigid(Rigid::new(
            glam::DQuat::from_mat3(&rotation).normalize(),
            pose.translation_m + v,
        ));
        [omega.x, omega.y, omega.z, v.x, v.y, v.z]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    /// Rays from a sensor at `pose` (vehicle at the origin) to planes of a box-shaped room; the
    /// rendered range of a ray is its exact distance to the nearest plane.
    fn room_depth(o: DVec3, d: DVec3) -> Option<(f64, DVec3)> {
        // (inward normal n, c) of the planes n·x + c = 0: floor, walls at x = −8, 12,
        // y = −6, 9, ceiling at z = 5.
        let planes = [
            (DVec3::Z, 0.0),
            (DVec3::X, 8.0),
            (-DVec3::X, 12.0),
            (DVec3::Y, 6.0),
            (-DVec3::Y, 9.0),
            (-DVec3::Z, 5.0),
        ];
        planes
            .iter()
            .filter_map(|(n, c)| {
                let den = n.dot(d);
                let t = -(n.dot(o) + c) / den;
                (den < -1e-9 && t > 0.0).then_some((t, *n))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
    }

    fn directions() -> Vec<DVec3> {
        (0..400)
            .map(|i| {
                let az = i as f64 * 2.399963;
                let el = -0.5 + (i % 20) as f64 * 0.05;
                DVec3::new(az.cos() * el.cos(), az.sin() * el.cos(), el.sin())
            })
            .collect()
    }

    #[test]
    fn the_tangent_form_matches_finite_differences_of_the_pose() {
        let pose = PoseParams::from_rigid(Rigid::new(
            DQuat::from_euler(glam::EulerRot::XYZ, 0.1, -0.2, 0.3),
            DVec3::new(1.0, -0.5, 1.8),
        ));
        let wv = Rigid::new(DQuat::from_rotation_z(0.4), DVec3::new(3.0, 2.0, 0.0));
        let u = DVec3::new(0.6, 0.3, -0.2).normalize_or_zero();
        // A linear loss in (o, d): L = a·o + b·d.
        let (a, b) = (DVec3::new(0.3, -1.0, 0.7), DVec3::new(-2.0, 0.5, 1.5));
        let loss = |p: &PoseParams| {
            let (o, d) = p.ray(wv, u);
            a.dot(o) + b.dot(d)
        };
        let analytic = to_tangent(wv, &pose, u, a, b);
        let eps = 1e-6;
        for k in 0..6 {
            let moved = |sign: f64| {
                let mut delta = [0.0; 6];
                delta[k] = sign * eps;
                let w = DVec3::new(delta[0], delta[1], delta[2]);
                let v = DVec3::new(delta[3], delta[4], delta[5]);
                let r = so3::exp_mat(w) * pose.rotation();
                PoseParams::from_rigid(Rigid::new(
                    DQuat::from_mat3(&r).normalize(),
                    pose.translation_m + v,
                ))
            };
            let fd = (loss(&moved(1.0)) - loss(&moved(-1.0))) / (2.0 * eps);
            assert!(
                (fd - analytic[k]).abs() < 1e-6,
                "{k}: {fd} vs {}",
                analytic[k]
            );
        }
    }

    /// Depth residuals of a perturbed sensor in a room, one ray in ten a gross outlier (a
    /// return from something the scene does not have): steps on the robust point-to-plane
    /// system recover the pose from either direction of the perturbation.
    #[test]
    fn steps_recover_a_perturbed_pose_in_a_room_despite_outliers() {
        let truth = Rigid::new(DQuat::from_rotation_z(0.2), DVec3::new(0.5, -0.3, 1.5));
        let wv = Rigid::IDENTITY;
        let dirs = directions();
        let measured: Vec<Option<f64>> = dirs
            .iter()
            .enumerate()
            .map(|(i, u)| {
                let (o, d) = PoseParams::from_rigid(truth).ray(wv, *u);
                let outlier = if i % 10 == 3 { -2.5 } else { 0.0 };
                room_depth(o, d).map(|(t, _)| t + outlier)
            })
            .collect();
        for sign in [1.0, -1.0] {
            let start = truth.perturbed_right(
                DVec3::new(0.02, -0.015, 0.03) * sign,
                DVec3::new(0.15, -0.1, 0.12) * sign,
            );
            let mut pose = PoseParams::from_rigid(start);
            let config = NewtonConfig {
                interval: 1,
                max_rotation_rad: 1.0,
                max_translation_m: 1.0,
                ..NewtonConfig::default()
            };
            let mut state = NewtonState::new(config);
            for _ in 0..20 {
                let mut rows: Vec<PoseRow> = dirs
                    .iter()
                    .zip(&measured)
                    .filter_map(|(u, m)| {
                        let (o, d) = pose.ray(wv, *u);
                        let (t, n) = room_depth(o, d)?;
                        plane_row(wv, &pose, *u, d, n, t, (*m)?, config.min_incidence_cos)
                    })
                    .collect();
                assert!(state.gather(&mut rows));
                state.step(&mut pose, 1.0);
            }
            let (rot, trans) = truth.difference(pose.to_rigid());
            assert!(rot < 1e-4 && trans < 1e-3, "{sign}: {rot} rad, {trans} m");
        }
    }

    #[test]
    fn grazing_rays_and_degenerate_normals_give_no_row() {
        let (wv, pose) = (Rigid::IDENTITY, PoseParams::from_rigid(Rigid::IDENTITY));
        let d = DVec3::X;
        assert!(plane_row(wv, &pose, d, d, DVec3::Y, 5.0, 5.0, 0.1).is_none());
        assert!(plane_row(wv, &pose, d, d, DVec3::ZERO, 5.0, 5.0, 0.1).is_none());
        // Facing a wall 5 m ahead, measured at 4.8 m: the plane distance is 0.2 m and moving
        // forward (v along x) shortens it one for one, whichever way the normal points.
        for n in [-DVec3::X * 3.0, DVec3::X] {
            let row = plane_row(wv, &pose, d, d, n, 5.0, 4.8, 0.1);
            let row = row.unwrap_or(PoseRow {
                jacobian: [9.0; 6],
                residual_m: 9.0,
                surface_world: DVec3::ZERO,
            });
            assert!((row.residual_m - 0.2).abs() < 1e-12, "{row:?}");
            assert!((row.jacobian[3] + 1.0).abs() < 1e-12 && row.jacobian[4].abs() < 1e-12);
        }
    }

    #[test]
    fn a_singular_system_leaves_the_pose_alone() {
        let start = PoseParams::from_rigid(Rigid::IDENTITY);
        let mut pose = start;
        let mut state = NewtonState::new(NewtonConfig::default());
        let step = state.step(&mut pose, 1.0);
        assert_eq!(step, [0.0; 6]);
        assert_eq!(pose, start);
    }
}
