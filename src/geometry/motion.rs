//! How much a stretch of trajectory excites calibration: speed, yaw rate and turns.
//!
//! The paper's trajectory study (method.md, supplementary) shows straight driving constrains
//! extrinsics less than turning; the studio shows this summary per selected segment. Yaw rate
//! comes from heading differences of poses sampled every 0.1 s (vehicle x axis projected on the
//! ground plane); a *turn* is a maximal run of |yaw rate| above 5 °/s whose heading change is at
//! least 20°.

use super::Trajectory;

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MotionSummary {
    pub duration_s: f64,
    pub distance_m: f64,
    pub mean_speed_mps: f64,
    pub max_speed_mps: f64,
    pub mean_abs_yaw_rate_deg_s: f64,
    pub max_abs_yaw_rate_deg_s: f64,
    /// Sum of |heading change| over the segment.
    pub total_turn_deg: f64,
    pub turns: usize,
}

const STEP_NANOS: i64 = 100_000_000;
/// Longer segments are sampled more sparsely (a day-long log every 4.3 s).
const MOST_SAMPLES: usize = 20_000;
const TURN_RATE_DEG_S: f64 = 5.0;
const TURN_MIN_DEG: f64 = 20.0;

impl MotionSummary {
    /// Summarise `[start, end]` (clamped to the trajectory's range); `None` if empty.
    pub fn of(trajectory: &Trajectory, start_nanos: i64, end_nanos: i64) -> Option<Self> {
        let (lo, hi) = trajectory.time_range_nanos()?;
        let (t0, t1) = (start_nanos.max(lo), end_nanos.min(hi));
        if t1 <= t0 {
            return None;
        }
        let stamps = Trajectory::sample_stamps(t0, t1, STEP_NANOS, MOST_SAMPLES);
        let poses: Vec<_> = stamps
            .iter()
            .filter_map(|&t| trajectory.world_from_vehicle(t).ok().map(|p| (t, p)))
            .collect();
        let mut s = MotionSummary {
            duration_s: (t1 - t0) as f64 * 1e-9,
            ..Self::default()
        };
        let (mut turn_run, mut yaw_sum) = (0.0f64, 0.0f64);
        for w in poses.windows(2) {
            let ((ta, a), (tb, b)) = (w[0], w[1]);
            let dt = (tb - ta) as f64 * 1e-9;
            if dt <= 0.0 {
                continue;
            }
            let d = (b.translation - a.translation).length();
            s.distance_m += d;
            s.max_speed_mps = s.max_speed_mps.max(d / dt);
            let heading = |p: crate::geometry::Rigid| {
                let x = p.rotation * glam::DVec3::X;
                x.y.atan2(x.x)
            };
            let mut dh = heading(b) - heading(a);
            dh = (dh + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            let dh_deg = dh.to_degrees();
            let rate = dh_deg.abs() / dt;
            yaw_sum += dh_deg.abs();
            s.max_abs_yaw_rate_deg_s = s.max_abs_yaw_rate_deg_s.max(rate);
            if rate > TURN_RATE_DEG_S {
                turn_run += dh_deg.abs();
            } else {
                if turn_run >= TURN_MIN_DEG {
                    s.turns += 1;
                }
                turn_run = 0.0;
            }
        }
        if turn_run >= TURN_MIN_DEG {
            s.turns += 1;
        }
        s.total_turn_deg = yaw_sum;
        s.mean_speed_mps = s.distance_m / s.duration_s;
        s.mean_abs_yaw_rate_deg_s = yaw_sum / s.duration_s;
        Some(s)
    }

    /// A one-line verdict on how well the segment constrains calibration.
    pub fn verdict(&self) -> &'static str {
        if self.distance_m < 1.0 {
            "stationary: only targets or overlap constrain extrinsics"
        } else if self.total_turn_deg < 15.0 {
            "straight: constrains less (rotations about the driving direction are weakly observed)"
        } else if self.turns >= 2 || self.total_turn_deg >= 60.0 {
            "turning: well excited"
        } else {
            "gentle curves: moderately excited"
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Rigid;
    use glam::{DQuat, DVec3};

    /// 10 s: 4 s straight along x at 10 m/s, then a 90° left turn in 2 s, then 4 s straight.
    fn drive() -> Trajectory {
        let mut poses = Vec::new();
        let (mut p, mut yaw) = (DVec3::ZERO, 0.0f64);
        for k in 0..=1000 {
            let t = k as f64 * 0.01;
            poses.push(((t * 1e9) as i64, Rigid::new(DQuat::from_rotation_z(yaw), p)));
            let rate = if (4.0..6.0).contains(&t) {
                45f64.to_radians()
            } else {
                0.0
            };
            yaw += rate * 0.01;
            p += DVec3::new(yaw.cos(), yaw.sin(), 0.0) * 10.0 * 0.01;
        }
        Trajectory::new(poses)
    }

    #[test]
    fn a_straight_stretch_is_straight() {
        let s = MotionSummary::of(&drive(), 0, 3_000_000_000).unwrap();
        assert!((s.mean_speed_mps - 10.0).abs() < 0.05, "{s:?}");
        assert!(s.total_turn_deg < 0.5 && s.turns == 0, "{s:?}");
        assert!(s.verdict().starts_with("straight"));
    }

    #[test]
    fn a_right_angle_turn_is_one_turn_of_90_degrees() {
        let s = MotionSummary::of(&drive(), 0, 10_000_000_000).unwrap();
        assert_eq!(s.turns, 1, "{s:?}");
        assert!((s.total_turn_deg - 90.0).abs() < 1.5, "{s:?}");
        assert!((s.max_abs_yaw_rate_deg_s - 45.0).abs() < 2.0, "{s:?}");
        assert!((s.distance_m - 100.0).abs() < 0.5, "{s:?}");
        assert!(s.verdict().starts_with("turning"));
    }

    #[test]
    fn empty_or_outside_ranges_have_no_summary() {
        assert!(MotionSummary::of(&drive(), 5, 5).is_none());
        assert!(MotionSummary::of(&drive(), 20_000_000_000, 30_000_000_000).is_none());
    }
}
