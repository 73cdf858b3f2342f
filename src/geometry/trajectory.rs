//! The vehicle trajectory `world_from_vehicle(t)`: timestamped poses, interpolated with SLERP on
//! rotation and linear on translation.
//!
//! Queries outside the covered time range are an error, except within an explicit, bounded
//! extrapolation margin (PandaSet's rear cameras fire up to 50 ms before the first pose).

use thiserror::Error;

use super::Rigid;

#[derive(Debug, Error, PartialEq)]
pub enum TrajectoryError {
    #[error("the trajectory is empty")]
    Empty,
    #[error(
        "time {stamp_nanos} ns is outside the trajectory [{start_nanos}, {end_nanos}] ns by {outside_ms:.1} ms (allowed extrapolation {allowed_ms:.1} ms)"
    )]
    OutOfRange {
        stamp_nanos: i64,
        start_nanos: i64,
        end_nanos: i64,
        outside_ms: f64,
        allowed_ms: f64,
    },
}

/// A stamp given two or more poses that disagree ([`conflicting_stamps`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StampConflict {
    pub stamp_nanos: i64,
    /// The largest translation (m) and rotation (rad) between the kept pose and another.
    pub translation_m: f64,
    pub rotation_rad: f64,
}

/// Stamps among `poses` (in the order given) that carry poses farther apart than a micrometre
/// or a microradian. [`Trajectory::new`] keeps the last pose given for each; an identical
/// pose sent twice is no conflict.
pub fn conflicting_stamps(poses: &[(i64, Rigid)]) -> Vec<StampConflict> {
    let mut order: Vec<usize> = (0..poses.len()).collect();
    order.sort_by_key(|&i| poses[i].0);
    let mut conflicts = Vec::new();
    for group in order.chunk_by(|&a, &b| poses[a].0 == poses[b].0) {
        let Some(&kept) = group.last() else { continue };
        let (mut translation_m, mut rotation_rad) = (0.0f64, 0.0f64);
        for &i in group {
            let (r, t) = poses[kept].1.difference(poses[i].1);
            rotation_rad = rotation_rad.max(r);
            translation_m = translation_m.max(t);
        }
        if translation_m > 1e-6 || rotation_rad > 1e-6 {
            conflicts.push(StampConflict {
                stamp_nanos: poses[kept].0,
                translation_m,
                rotation_rad,
            });
        }
    }
    conflicts
}

/// Poses sorted by time; duplicate stamps keep the last pose given.
#[derive(Clone, Debug, Default)]
pub struct Trajectory {
    stamps_nanos: Vec<i64>,
    world_from_vehicle: Vec<Rigid>,
    /// How far past either end a query may extrapolate, in nanoseconds.
    pub max_extrapolation_nanos: i64,
}

impl Trajectory {
    pub fn new(mut poses: Vec<(i64, Rigid)>) -> Self {
        poses.sort_by_key(|(t, _)| *t);
        let mut stamps_nanos: Vec<i64> = Vec::with_capacity(poses.len());
        let mut world_from_vehicle: Vec<Rigid> = Vec::with_capacity(poses.len());
        for (t, pose) in poses {
            if stamps_nanos.last() == Some(&t) {
                if let Some(last) = world_from_vehicle.last_mut() {
                    *last = pose;
                }
                continue;
            }
            stamps_nanos.push(t);
            world_from_vehicle.push(pose);
        }
        Self {
            stamps_nanos,
            world_from_vehicle,
            max_extrapolation_nanos: 0,
        }
    }

    /// Remove poses that lie farther from most of their four nearest poses (two either side
    /// where there are) than `max_speed_mps` allows: a corrupt message, not a fast vehicle. A
    /// pose is judged against poses, not a model of the drive, so a genuine jump of the whole
    /// trajectory (a relocalisation) removes nothing, and two or more bad poses in a row that
    /// agree with each other are found only while they are fewer than their good neighbours.
    /// Returns each removed pose's stamp and its distance (m) to the nearest good pose.
    pub fn remove_jumps(&mut self, max_speed_mps: f64) -> Vec<(i64, f64)> {
        let n = self.len();
        let far = |a: usize, b: usize| {
            let dt = (self.stamps_nanos[b] - self.stamps_nanos[a]).abs() as f64 * 1e-9;
            let d = (self.world_from_vehicle[b].translation
                - self.world_from_vehicle[a].translation)
                .length();
            d > max_speed_mps * dt
        };
        let nearest = |i: usize| -> Vec<usize> {
            let mut others: Vec<usize> = (i.saturating_sub(4)..(i + 5).min(n))
                .filter(|&j| j != i)
                .collect();
            others.sort_by_key(|&j| j.abs_diff(i));
            others.truncate(4);
            others
        };
        let bad: Vec<bool> = (0..n)
            .map(|i| {
                let others = nearest(i);
                others.len() >= 3
                    && 2 * others.iter().filter(|&&j| far(i, j)).count() > others.len()
            })
            .collect();
        let mut removed = Vec::new();
        for i in (0..n).filter(|&i| bad[i]) {
            // The nearest good pose, searched outward from i (not over every pose per bad one).
            let nearest_good = (1..n).find_map(|d| {
                [i.checked_sub(d), Some(i + d).filter(|&j| j < n)]
                    .into_iter()
                    .flatten()
                    .find(|&j| !bad[j])
            });
            let distance_m = nearest_good.map_or(f64::NAN, |j| {
                (self.world_from_vehicle[i].translation - self.world_from_vehicle[j].translation)
                    .length()
            });
            removed.push((self.stamps_nanos[i], distance_m));
        }
        let (stamps_nanos, world_from_vehicle) = self
            .stamps_nanos
            .iter()
            .zip(&self.world_from_vehicle)
            .zip(&bad)
            .filter(|(_, bad)| !**bad)
            .map(|((&t, &pose), _)| (t, pose))
            .unzip();
        self.stamps_nanos = stamps_nanos;
        self.world_from_vehicle = world_from_vehicle;
        removed
    }

    /// Remove poses at either end that lie apart from the rest by a gap of more than an hour
    /// and more than a thousand times the drive's median step, when they are few (at most a
    /// twentieth of the poses, or one): a stamp of 0, or one in another epoch, in a log
    /// stamped otherwise. Such poses stretch the drive over years, and everything that samples
    /// it in time would sample that span. A pause in the middle of a drive is kept. Returns
    /// the removed stamps.
    pub fn remove_time_outliers(&mut self) -> Vec<i64> {
        const HOUR_NANOS: i64 = 3_600_000_000_000;
        let gaps: Vec<i64> = self
            .stamps_nanos
            .windows(2)
            .map(|w| w[1].saturating_sub(w[0]))
            .collect();
        let mut sorted = gaps.clone();
        sorted.sort_unstable();
        let Some(&median) = sorted.get(sorted.len() / 2) else {
            return Vec::new();
        };
        let apart = |gap: i64| gap > HOUR_NANOS && gap / 1000 > median;
        let few = (self.len() / 20).max(1);
        // Poses before the first wide gap, and after the last, if they are few.
        let head = gaps.iter().position(|&g| apart(g)).map_or(0, |i| i + 1);
        let tail = gaps
            .iter()
            .rposition(|&g| apart(g))
            .map_or(0, |i| self.len() - i - 1);
        let head = if head <= few { head } else { 0 };
        let tail = if tail <= few && head + tail < self.len() {
            tail
        } else {
            0
        };
        let keep = head..self.len() - tail;
        let mut removed: Vec<i64> = self.stamps_nanos[..head].to_vec();
        removed.extend_from_slice(&self.stamps_nanos[keep.end..]);
        self.stamps_nanos = self.stamps_nanos[keep.clone()].to_vec();
        self.world_from_vehicle = self.world_from_vehicle[keep].to_vec();
        removed
    }

    /// Stamps from `start` to `end` (inclusive of both) every `step` ns, or at most `most` of
    /// them, evenly spread, where the span would take more: what plots and summaries sample,
    /// bounded whatever the span.
    pub fn sample_stamps(start: i64, end: i64, step: i64, most: usize) -> Vec<i64> {
        if end < start || most == 0 {
            return Vec::new();
        }
        let span = (i128::from(end) - i128::from(start)) as u128;
        let step = (step.max(1) as u128).max(span.div_ceil(most.max(2) as u128 - 1));
        let mut stamps: Vec<i64> = (0..)
            .map(|k: u128| k * step)
            .take_while(|&offset| offset < span)
            .map(|offset| (i128::from(start) + offset as i128) as i64)
            .collect();
        stamps.push(end);
        stamps
    }

    pub fn with_max_extrapolation_nanos(mut self, nanos: i64) -> Self {
        self.max_extrapolation_nanos = nanos.max(0);
        self
    }

    pub fn len(&self) -> usize {
        self.stamps_nanos.len()
    }

    pub fn is_empty(&self) -> bool {
        self.stamps_nanos.is_empty()
    }

    pub fn stamps_nanos(&self) -> &[i64] {
        &self.stamps_nanos
    }

    pub fn poses(&self) -> impl Iterator<Item = (i64, Rigid)> + '_ {
        self.stamps_nanos
            .iter()
            .copied()
            .zip(self.world_from_vehicle.iter().copied())
    }

    /// First and last stamp.
    pub fn time_range_nanos(&self) -> Option<(i64, i64)> {
        Some((*self.stamps_nanos.first()?, *self.stamps_nanos.last()?))
    }

    /// `world_from_vehicle` at `stamp_nanos`.
    pub fn world_from_vehicle(&self, stamp_nanos: i64) -> Result<Rigid, TrajectoryError> {
        let (start, end) = self.time_range_nanos().ok_or(TrajectoryError::Empty)?;
        let outside = if stamp_nanos < start {
            start - stamp_nanos
        } else if stamp_nanos > end {
            stamp_nanos - end
        } else {
            0
        };
        if outside > self.max_extrapolation_nanos {
            return Err(TrajectoryError::OutOfRange {
                stamp_nanos,
                start_nanos: start,
                end_nanos: end,
                outside_ms: outside as f64 * 1e-6,
                allowed_ms: self.max_extrapolation_nanos as f64 * 1e-6,
            });
        }
        let n = self.stamps_nanos.len();
        if n == 1 {
            return Ok(self.world_from_vehicle[0]);
        }
        // Index of the segment [i, i+1] containing (or nearest to) the stamp.
        let i = match self.stamps_nanos.binary_search(&stamp_nanos) {
            Ok(i) => return Ok(self.world_from_vehicle[i]),
            Err(i) => i.clamp(1, n - 1) - 1,
        };
        let (t0, t1) = (self.stamps_nanos[i], self.stamps_nanos[i + 1]);
        let s = (stamp_nanos - t0) as f64 / (t1 - t0) as f64;
        Ok(self.world_from_vehicle[i].interpolate(self.world_from_vehicle[i + 1], s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DQuat, DVec3};

    fn straight() -> Trajectory {
        Trajectory::new(vec![
            (
                2_000,
                Rigid::new(DQuat::from_rotation_z(0.2), DVec3::new(2.0, 0.0, 0.0)),
            ),
            (0, Rigid::IDENTITY),
            (
                1_000,
                Rigid::new(DQuat::from_rotation_z(0.1), DVec3::new(1.0, 0.0, 0.0)),
            ),
        ])
    }

    #[test]
    fn interpolates_between_poses() {
        let p = straight().world_from_vehicle(1_500).unwrap();
        assert!((p.translation.x - 1.5).abs() < 1e-12);
        let (angle, _) = Rigid::IDENTITY.difference(p);
        assert!((angle - 0.15).abs() < 1e-12);
    }

    #[test]
    fn two_poses_at_one_stamp_that_disagree_are_a_conflict_and_the_last_is_kept() {
        let moved = Rigid::new(DQuat::IDENTITY, DVec3::new(0.0, 3.0, 0.0));
        let poses = vec![
            (5, Rigid::IDENTITY),
            (1, Rigid::IDENTITY),
            (5, moved),
            (1, Rigid::IDENTITY),
            (9, Rigid::IDENTITY),
        ];
        let conflicts = conflicting_stamps(&poses);
        assert_eq!(conflicts.len(), 1, "{conflicts:?}");
        assert_eq!(conflicts[0].stamp_nanos, 5);
        assert!((conflicts[0].translation_m - 3.0).abs() < 1e-12);
        assert!(conflicts[0].rotation_rad < 1e-12);
        let kept = Trajectory::new(poses).world_from_vehicle(5).unwrap();
        assert!(
            (kept.translation.y - 3.0).abs() < 1e-12,
            "the last pose given"
        );
        // A turn alone conflicts too; the same pose twice does not.
        let turned = Rigid::new(DQuat::from_rotation_z(0.01), DVec3::ZERO);
        let conflicts = conflicting_stamps(&[(0, Rigid::IDENTITY), (0, turned)]);
        assert!((conflicts[0].rotation_rad - 0.01).abs() < 1e-9);
        assert!(conflicting_stamps(&[(0, moved), (0, moved)]).is_empty());
    }

    #[test]
    fn a_pose_stamped_in_another_epoch_is_removed_and_a_paused_recording_kept() {
        let day = 86_400_000_000_000i64;
        let mut poses: Vec<(i64, Rigid)> = (0..50)
            .map(|k| (day * 20_000 + k * 100_000_000, Rigid::IDENTITY))
            .collect();
        // A 90-minute pause in the middle is a drive, not an outlier.
        poses.extend((0..50).map(|k| {
            (
                day * 20_000 + 5_400_000_000_000 + k * 100_000_000,
                Rigid::IDENTITY,
            )
        }));
        poses.push((0, Rigid::IDENTITY));
        poses.push((100_000_000, Rigid::IDENTITY));
        poses.push((i64::MAX / 2, Rigid::IDENTITY));
        let mut t = Trajectory::new(poses);
        // Two bad poses together at the start go as well as one.
        assert_eq!(t.remove_time_outliers(), vec![0, 100_000_000, i64::MAX / 2]);
        assert_eq!(t.len(), 100);
        assert!(t.remove_time_outliers().is_empty());
        // Stamps from i64::MIN to i64::MAX do not overflow.
        let mut wide = Trajectory::new(vec![
            (i64::MIN, Rigid::IDENTITY),
            (0, Rigid::IDENTITY),
            (1, Rigid::IDENTITY),
            (i64::MAX, Rigid::IDENTITY),
        ]);
        let _ = wide.remove_time_outliers();
    }

    #[test]
    fn samples_are_every_step_or_at_most_so_many() {
        assert_eq!(
            Trajectory::sample_stamps(0, 250, 100, 1000),
            vec![0, 100, 200, 250]
        );
        assert_eq!(
            Trajectory::sample_stamps(0, 200, 100, 1000),
            vec![0, 100, 200]
        );
        let many = Trajectory::sample_stamps(0, i64::MAX, 100, 1000);
        assert!(many.len() <= 1001 && many.len() >= 999, "{}", many.len());
        assert_eq!(many.last(), Some(&i64::MAX));
        assert!(many.windows(2).all(|w| w[1] > w[0]));
        assert!(Trajectory::sample_stamps(5, 4, 1, 10).is_empty());
        let whole = Trajectory::sample_stamps(i64::MIN, i64::MAX, 1, 100);
        assert_eq!(
            (whole.first(), whole.last()),
            (Some(&i64::MIN), Some(&i64::MAX))
        );
    }

    #[test]
    fn exact_stamps_return_the_pose() {
        let p = straight().world_from_vehicle(2_000).unwrap();
        assert!((p.translation.x - 2.0).abs() < 1e-15);
    }

    #[test]
    fn outside_range_is_an_error_unless_allowed() {
        let t = straight();
        assert!(matches!(
            t.world_from_vehicle(-1),
            Err(TrajectoryError::OutOfRange { .. })
        ));
        let t = t.with_max_extrapolation_nanos(500);
        let p = t.world_from_vehicle(-500).unwrap();
        assert!((p.translation.x + 0.5).abs() < 1e-12);
        assert!(t.world_from_vehicle(2_501).is_err());
        assert_eq!(
            Trajectory::default().world_from_vehicle(0),
            Err(TrajectoryError::Empty)
        );
    }

    #[test]
    fn a_pose_far_from_most_of_its_neighbours_is_removed_and_fast_driving_is_not() {
        let drive = |speed_mps: f64| -> Vec<(i64, Rigid)> {
            (0..10)
                .map(|k| {
                    let t = k as f64 * 0.1;
                    (
                        k * 100_000_000,
                        Rigid::new(DQuat::IDENTITY, DVec3::new(speed_mps * t, 0.0, 0.0)),
                    )
                })
                .collect()
        };
        // 50 m/s throughout: nothing is a jump.
        let mut fast = Trajectory::new(drive(50.0));
        assert!(fast.remove_jumps(100.0).is_empty());
        assert_eq!(fast.len(), 10);
        // Poses 0 and 2 off (pose 1 between them is good): both go, pose 1 stays.
        let mut poses = drive(5.0);
        poses[0].1.translation.y += 1e6;
        poses[2].1.translation.y += 1e6;
        let mut t = Trajectory::new(poses);
        assert_eq!(t.remove_jumps(100.0).len(), 2);
        assert_eq!(t.len(), 8);
        // Two in a row off by the same: both go.
        let mut poses = drive(5.0);
        poses[5].1.translation.y += 1e6;
        poses[6].1.translation.y += 1e6;
        let mut t = Trajectory::new(poses);
        assert_eq!(t.remove_jumps(100.0).len(), 2);
        // The whole trajectory jumping once (a relocalisation) loses nothing.
        let mut poses = drive(5.0);
        for p in &mut poses[5..] {
            p.1.translation.y += 1e6;
        }
        let mut t = Trajectory::new(poses);
        assert!(t.remove_jumps(100.0).is_empty());
        // One pose 1000 km off, inside and at either end.
        for k in [4usize, 0, 9] {
            let mut poses = drive(5.0);
            poses[k].1.translation.y += 1e6;
            let mut t = Trajectory::new(poses);
            let removed = t.remove_jumps(100.0);
            assert_eq!(removed.len(), 1, "pose {k}");
            assert_eq!(removed[0].0, k as i64 * 100_000_000);
            assert!((removed[0].1 - 1e6).abs() < 1.0, "{removed:?}");
            assert_eq!(t.len(), 9);
        }
    }
}
