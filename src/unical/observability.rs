//! Which directions of a camera's pose the correspondence term observes, and pose steps held to
//! them.
//!
//! Every match of the surface alignment term reprojects a rendered surface point into a camera
//! (main Eq. 12). Holding that point, the reprojection's Jacobian with respect to the camera's
//! pose is the one of a PnP problem: for `q = Rᵀ (x − c)` (the point `x` in the vehicle frame,
//! the camera at `c` turned by `R`) and a perturbation `R ← exp([ω]×) R`, `c ← c + v` in the
//! vehicle frame, `∂q/∂ω = Rᵀ [x − c]×` and `∂q/∂v = −Rᵀ`. Their Gauss–Newton information
//! `H = Σ Jᵀ J` (1920-wide pixels) is accumulated over the run with a forgetting factor, so it
//! follows the matches the current poses keep.
//!
//! A drive observes some combinations poorly: a sideways shift of a camera whose scene is far
//! away looks nearly like a turn, and on a straight drive a camera's pairs are its own frames
//! over time. Biases in the other terms then push the pose along such a direction unopposed
//! (the real PandaSet drive's back camera slides 20–40 cm sideways while turning by about a
//! degree). Solution remapping (Zhang, Kaess and Singh, "On degeneracy of optimization-based
//! state estimation problems", ICRA 2016) keeps a step only along the eigenvectors of `H`
//! whose eigenvalue is at least a fraction of the largest, so a poorly observed direction stays
//! where the initial guess put it. Rotations are counted in metres at a lever of
//! [`LEVER_M`] so the two halves of the pose are compared on one scale.

use glam::{DMat3, DVec3};

use crate::geometry::so3;
use crate::geometry::spd::symmetric_eigen;

/// Rotations are counted as the displacement they cause at this distance (m), about the depth
/// of a street's façades from a camera.
pub const LEVER_M: f64 = 10.0;

/// The information of one camera's pose from the reprojections into it, in the scaled
/// coordinates `(LEVER_M · ω, v)`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PoseInformation {
    h: [[f64; 6]; 6],
    /// How many reprojections it holds (weighted by the forgetting factor).
    pub count: f64,
}

impl PoseInformation {
    /// Add one reprojection: `jacobian_px` is `∂π/∂q` (2 × 3, in the units the information is
    /// counted in), `rotation` the camera's `vehicle_from_camera` rotation and `offset_m` the
    /// point minus the camera centre, in the vehicle frame.
    pub fn add_reprojection(
        &mut self,
        jacobian_px: [[f64; 3]; 2],
        rotation: DMat3,
        offset_m: DVec3,
    ) {
        let rt = rotation.transpose();
        let dq_domega = rt * so3::hat(offset_m) * (1.0 / LEVER_M);
        let dq_dv = -rt;
        for row in jacobian_px {
            let g = DVec3::from_array(row);
            // Row of J: gᵀ ∂q/∂(·), i.e. (∂q/∂(·))ᵀ g.
            let a = dq_domega.transpose() * g;
            let b = dq_dv.transpose() * g;
            let j = [a.x, a.y, a.z, b.x, b.y, b.z];
            for (r, jr) in self.h.iter_mut().zip(j) {
                for (h, jc) in r.iter_mut().zip(j) {
                    *h += jr * jc;
                }
            }
        }
        self.count += 1.0;
    }

    /// Add another camera's information (the same camera, another batch).
    pub fn merge(&mut self, other: &PoseInformation) {
        for (r, o) in self.h.iter_mut().zip(&other.h) {
            for (h, x) in r.iter_mut().zip(o) {
                *h += x;
            }
        }
        self.count += other.count;
    }

    /// Scale everything held by `factor` (forgetting).
    pub fn decay(&mut self, factor: f64) {
        self.h.iter_mut().flatten().for_each(|h| *h *= factor);
        self.count *= factor;
    }

    /// Eigenvalues (ascending) and unit eigenvectors of the information, per reprojection.
    pub fn directions(&self) -> Vec<(f64, [f64; 6])> {
        let n = self.count.max(1e-12);
        let mut h = self.h;
        h.iter_mut().flatten().for_each(|x| *x /= n);
        let (values, vectors) = symmetric_eigen(h);
        let mut out: Vec<(f64, [f64; 6])> = (0..6)
            .map(|k| (values[k], std::array::from_fn(|i| vectors[i][k])))
            .collect();
        out.sort_by(|a, b| a.0.total_cmp(&b.0));
        out
    }

    /// The part of a pose step (`omega_rad`, `v_m`, vehicle frame) along the directions whose
    /// eigenvalue is at least `ratio` times the largest; the step unchanged while fewer than
    /// `min_count` reprojections are held.
    pub fn observed_step(
        &self,
        (omega_rad, v_m): (DVec3, DVec3),
        ratio: f64,
        min_count: f64,
    ) -> (DVec3, DVec3) {
        if self.count < min_count {
            return (omega_rad, v_m);
        }
        let directions = self.directions();
        let largest = directions.last().map_or(0.0, |d| d.0);
        if largest <= 0.0 {
            return (omega_rad, v_m);
        }
        let s = omega_rad * LEVER_M;
        let step = [s.x, s.y, s.z, v_m.x, v_m.y, v_m.z];
        let mut kept = [0.0; 6];
        for (value, u) in &directions {
            if *value < ratio * largest {
                continue;
            }
            let along: f64 = u.iter().zip(&step).map(|(a, b)| a * b).sum();
            kept.iter_mut().zip(u).for_each(|(k, x)| *k += along * x);
        }
        (
            DVec3::new(kept[0], kept[1], kept[2]) / LEVER_M,
            DVec3::new(kept[3], kept[4], kept[5]),
        )
    }
}

/// Scenes with a known information, shared by this module's tests and the hold's in
/// `depth_calib`.
#[cfg(test)]
pub(crate) mod fixtures {
    use super::*;

    /// A camera looking along vehicle +x (optical z → vehicle x).
    pub fn camera_rotation() -> DMat3 {
        DMat3::from_cols(
            DVec3::new(0.0, -1.0, 0.0),
            DVec3::new(0.0, 0.0, -1.0),
            DVec3::X,
        )
    }

    /// `∂π/∂q` of a pinhole with focal length `focal_px` at the camera-frame point `q`.
    pub fn pinhole_jacobian(q: DVec3, focal_px: f64) -> [[f64; 3]; 2] {
        let z = q.z;
        [
            [focal_px / z, 0.0, -focal_px * q.x / (z * z)],
            [0.0, focal_px / z, -focal_px * q.y / (z * z)],
        ]
    }

    /// The information of [`camera_rotation`]'s camera (focal length 1000 px) from points at
    /// these offsets from its centre, in the vehicle frame.
    pub fn information_of(offsets: &[DVec3]) -> PoseInformation {
        let rotation = camera_rotation();
        let mut info = PoseInformation::default();
        for p in offsets {
            let q = rotation.transpose() * *p;
            info.add_reprojection(pinhole_jacobian(q, 1000.0), rotation, *p);
        }
        info
    }

    /// Points on a wall `depth_m` ahead, spread over ±`half_m` sideways and up on a
    /// `(2n + 1)²` grid.
    pub fn wall(depth_m: f64, half_m: f64, n: i32) -> Vec<DVec3> {
        let mut out = Vec::new();
        for i in -n..=n {
            for j in -n..=n {
                let (y, z) = (half_m * i as f64 / n as f64, half_m * j as f64 / n as f64);
                out.push(DVec3::new(depth_m, y, z));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::fixtures::*;
    use super::*;

    /// How many of the six directions are held at `ratio` (0 before `min_count`).
    fn held(info: &PoseInformation, ratio: f64, min_count: f64) -> usize {
        if info.count < min_count {
            return 0;
        }
        let directions = info.directions();
        let largest = directions.last().map_or(0.0, |d| d.0);
        directions.iter().filter(|d| d.0 < ratio * largest).count()
    }

    #[test]
    fn a_far_wall_leaves_the_turn_and_the_sideways_shift_one_direction() {
        let info = information_of(&wall(40.0, 4.0, 4));
        // A sideways shift v and the turn about the vertical that moves the wall's centre as
        // much (ω = v / depth) nearly cancel: that step is dropped, its opposite kept.
        let v = DVec3::new(0.0, 0.1, 0.0);
        let omega = DVec3::new(0.0, 0.0, -0.1 / 40.0);
        let (w, t) = info.observed_step((omega, v), 0.05, 10.0);
        assert!(t.length() < 0.02, "kept {t:?} of the coupled step");
        assert!(w.length() < 0.02 / 40.0, "kept {w:?} of the coupled step");
        // The best observed direction passes unchanged, and keeping is a projection.
        let (_, u) = info.directions()[5];
        let strong = (
            DVec3::new(u[0], u[1], u[2]) * (0.01 / LEVER_M),
            DVec3::new(u[3], u[4], u[5]) * 0.01,
        );
        let (w, t) = info.observed_step(strong, 0.05, 10.0);
        assert!((w - strong.0).length() < 1e-12 && (t - strong.1).length() < 1e-12);
        let once = info.observed_step((omega * 3.0, v), 0.05, 10.0);
        assert!(once != (omega * 3.0, v));
        let twice = info.observed_step(once, 0.05, 10.0);
        assert!((twice.0 - once.0).length() < 1e-12 && (twice.1 - once.1).length() < 1e-12);
        assert!(held(&info, 0.05, 10.0) >= 1);
    }

    #[test]
    fn a_deep_scene_observes_every_direction_and_steps_pass_unchanged() {
        let mut points = wall(5.0, 3.0, 4);
        points.extend(wall(12.0, 6.0, 4));
        points.extend(wall(30.0, 12.0, 4));
        let info = information_of(&points);
        assert_eq!(held(&info, 1e-3, 10.0), 0);
        let step = (
            DVec3::new(0.001, -0.002, 0.0005),
            DVec3::new(0.03, -0.01, 0.02),
        );
        let (w, t) = info.observed_step(step, 1e-3, 10.0);
        assert!((w - step.0).length() < 1e-12 && (t - step.1).length() < 1e-12);
    }

    #[test]
    fn too_few_reprojections_hold_nothing_and_forgetting_keeps_the_directions() {
        let mut info = information_of(&wall(40.0, 4.0, 4)[..5]);
        let step = (DVec3::new(0.0, 0.0, 0.01), DVec3::new(0.0, 0.1, 0.0));
        assert_eq!(info.observed_step(step, 0.05, 10.0), step);
        assert_eq!(held(&info, 0.05, 10.0), 0);
        let full = information_of(&wall(40.0, 4.0, 4));
        let before = full.directions();
        let mut scaled = full.clone();
        scaled.decay(0.5);
        let after = scaled.directions();
        for (a, b) in before.iter().zip(&after) {
            assert!((a.0 - b.0).abs() <= 1e-9 * a.0.abs().max(1.0));
        }
        info.merge(&full);
        assert_eq!(info.count, 5.0 + 81.0);
    }
}
