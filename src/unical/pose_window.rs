//! The extrinsics averaged over the optimiser's latest iterations: what a run reports as its
//! result (Polyak–Ruppert averaging over a sliding window).
//!
//! How it works: every pose step follows a fresh random draw of rays, so a pose that has found
//! its place still jitters about it by the step noise (on the simulator's drives a camera moves
//! 0.05–0.15° and 1–2 cm between checkpoints half a minute apart mid-run; docs/experiments/colour-field-and-hash-grid.md). The mean of the last
//! iterates is closer to where the objective holds the pose than any single one: noise averages
//! out, a bias does not. Translations are averaged arithmetically; rotations by the normalised
//! sum of their quaternions, each first turned to the hemisphere of the newest (the chordal L2
//! mean, exact to second order for rotations a fraction of a degree apart, as a converging
//! run's iterates are). The window lags the live pose by half its length, so it is a small
//! fraction of the run ([`window_len`]).
//!
//! The live pose is untouched: the optimiser keeps stepping from its own iterate, the studio's
//! overlay shows it, and only the result reported as the run's best is the window's mean.

use crate::geometry::Rigid;
use glam::{DQuat, DVec3, DVec4};
use std::collections::VecDeque;

/// The last `capacity` iterates of every sensor's extrinsic.
#[derive(Clone, Debug)]
pub struct PoseWindow {
    capacity: usize,
    iterates: VecDeque<Vec<(String, Rigid)>>,
}

impl PoseWindow {
    /// A window of `capacity` iterates (at least 1: the mean is then the latest iterate).
    pub fn new(capacity: usize) -> Self {
        Self {
            capacity: capacity.max(1),
            iterates: VecDeque::new(),
        }
    }

    /// How many iterates the window holds now.
    pub fn len(&self) -> usize {
        self.iterates.len()
    }

    pub fn is_empty(&self) -> bool {
        self.iterates.is_empty()
    }

    /// Add the newest iterate of every sensor's extrinsic, dropping the oldest beyond the
    /// capacity.
    pub fn push(&mut self, extrinsics: Vec<(String, Rigid)>) {
        if self.iterates.len() == self.capacity {
            self.iterates.pop_front();
        }
        self.iterates.push_back(extrinsics);
    }

    /// Each sensor of the newest iterate with its pose averaged over the iterates that hold it;
    /// empty before the first [`Self::push`].
    pub fn mean(&self) -> Vec<(String, Rigid)> {
        let Some(newest) = self.iterates.back() else {
            return Vec::new();
        };
        newest
            .iter()
            .map(|(name, latest)| {
                let reference = latest.rotation.normalize();
                let (mut translation_m, mut quaternion, mut n) = (DVec3::ZERO, DVec4::ZERO, 0.0);
                for pose in self
                    .iterates
                    .iter()
                    .filter_map(|it| it.iter().find(|(k, _)| k == name).map(|(_, p)| p))
                {
                    let q = pose.rotation.normalize();
                    let q = if q.dot(reference) < 0.0 { -q } else { q };
                    translation_m += pose.translation;
                    quaternion += DVec4::from(q);
                    n += 1.0;
                }
                let rotation = DQuat::from_vec4(quaternion).normalize();
                (name.clone(), Rigid::new(rotation, translation_m / n))
            })
            .collect()
    }

    /// Forget every iterate (a new round starts from a fresh scene).
    pub fn clear(&mut self) {
        self.iterates.clear();
    }
}

/// The window for a run of `iterations`: `fraction` of them, rounded up, at least 1; 0 when
/// the fraction is 0, negative or not a number (no averaging: the result is the last iterate).
pub fn window_len(iterations: usize, fraction: f32) -> usize {
    if fraction.is_nan() || fraction <= 0.0 {
        return 0;
    }
    // Less a millionth of itself before rounding up: 0.1 as an f32 is a little above a tenth.
    let share = iterations as f64 * f64::from(fraction.min(1.0));
    let len = (share * (1.0 - 1e-6)).ceil() as usize;
    len.max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(axis: DVec3, angle_deg: f64, t: [f64; 3]) -> Rigid {
        Rigid::new(
            DQuat::from_axis_angle(axis.normalize_or_zero(), angle_deg.to_radians()),
            DVec3::from_array(t),
        )
    }

    #[test]
    fn jitter_about_a_pose_averages_to_that_pose() {
        let centre = pose(DVec3::new(0.3, -1.0, 0.5), 20.0, [1.0, -2.0, 0.5]);
        let mut window = PoseWindow::new(4);
        // Symmetric jitter: ± the same small turn and shift about the centre.
        for sign in [1.0, -1.0, 1.0, -1.0] {
            let turn =
                DQuat::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize_or_zero(), sign * 0.01);
            let shift = DVec3::new(0.02, -0.01, 0.03) * sign;
            window.push(vec![(
                "cam".into(),
                Rigid::new(turn * centre.rotation, centre.translation + shift),
            )]);
        }
        let (rot, trans) = window.mean()[0].1.difference(centre);
        assert!(rot < 1e-6, "rotation off by {rot} rad");
        assert!(trans < 1e-12, "translation off by {trans} m");
        // A single iterate is 0.57° and 3.7 cm from the centre: the mean is the point.
        let (rot1, trans1) = window.iterates[0][0].1.difference(centre);
        assert!(rot1 > 0.009 && trans1 > 0.03);
    }

    #[test]
    fn only_the_latest_iterates_count() {
        let old = pose(DVec3::X, 5.0, [1.0, 0.0, 0.0]);
        let new = pose(DVec3::Y, -2.0, [0.0, 2.0, 0.0]);
        let mut window = PoseWindow::new(3);
        window.push(vec![("lidar".into(), old)]);
        window.push(vec![("lidar".into(), old)]);
        for _ in 0..3 {
            window.push(vec![("lidar".into(), new)]);
        }
        assert_eq!(window.len(), 3);
        let (rot, trans) = window.mean()[0].1.difference(new);
        assert!(rot < 1e-12 && trans < 1e-12, "{rot} {trans}");
    }

    #[test]
    fn a_quaternion_of_the_other_sign_is_the_same_rotation() {
        let p = pose(DVec3::Z, 170.0, [0.0, 0.0, 0.0]);
        let flipped = Rigid::new(-p.rotation, p.translation);
        let mut window = PoseWindow::new(2);
        window.push(vec![("lidar".into(), p)]);
        window.push(vec![("lidar".into(), flipped)]);
        let (rot, _) = window.mean()[0].1.difference(p);
        assert!(rot < 1e-9, "{rot}");
    }

    #[test]
    fn every_sensor_is_averaged_on_its_own_and_clear_forgets() {
        let a = [
            pose(DVec3::X, 1.0, [0.1, 0.2, 0.3]),
            pose(DVec3::X, 3.0, [0.3, 0.2, 0.1]),
        ];
        let b = pose(DVec3::Y, -3.0, [-1.0, 0.0, 2.0]);
        let mut window = PoseWindow::new(10);
        for pa in a {
            window.push(vec![("a".into(), pa), ("b".into(), b)]);
        }
        let mean = window.mean();
        assert_eq!(mean.len(), 2);
        let (rot, trans) = mean[0].1.difference(pose(DVec3::X, 2.0, [0.2, 0.2, 0.2]));
        assert!(rot < 1e-9 && trans < 1e-12, "{rot} {trans}");
        assert!(mean[1].1.difference(b).0 < 1e-12 && mean[1].1.difference(b).1 < 1e-12);
        window.clear();
        assert!(window.is_empty() && window.mean().is_empty());
    }

    #[test]
    fn the_window_is_its_fraction_of_the_run() {
        assert_eq!(window_len(1400, 0.1), 140);
        assert_eq!(window_len(300, 0.1), 30);
        assert_eq!(window_len(1400, 5.0), 1400);
        assert_eq!(window_len(10, 0.01), 1, "at least the last iterate");
        assert_eq!(window_len(1400, 0.0), 0);
        assert_eq!(window_len(1400, f32::NAN), 0);
        assert_eq!(window_len(1400, -0.5), 0);
    }
}
