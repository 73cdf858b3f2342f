//! The scene box drawn around the drive instead of around every LiDAR return (method.md §2:
//! "distant regions" belong to the background model).
//!
//! How it works. A LiDAR reaches 100–200 m, so a box around all of its returns is hundreds of
//! metres across while the cameras and the vehicle stay within a few tens of metres of the
//! trajectory. The hash grid maps that box to its unit cube, so most of its finest levels'
//! entries go to far returns that no camera sees at a useful resolution, and they share table
//! entries with the near surfaces that hold the cameras. [`keep_near_drive`] drops every return
//! farther than `radius_m` (horizontally) from the axis-aligned box around the trajectory's
//! positions, before the occupancy grid and the scene box are formed; camera rays leave the
//! smaller box into the background model as before.

use glam::DVec3;

use super::depth_calib::LidarData;
use crate::geometry::Trajectory;
use crate::geometry::projection::world_points;

/// Returns kept and dropped by [`keep_near_drive`], over every LiDAR.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Kept {
    pub kept: usize,
    pub dropped: usize,
}

/// The horizontal extent `[min, max]` (x, y) of the trajectory's positions grown by `radius_m`.
pub fn drive_footprint(trajectory: &Trajectory, radius_m: f64) -> Option<([f64; 2], [f64; 2])> {
    let mut positions = trajectory.poses().map(|(_, p)| p.translation);
    let first = positions.next()?;
    let (lo, hi) = positions.fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p)));
    let r = DVec3::new(radius_m, radius_m, 0.0);
    let (lo, hi) = (lo - r, hi + r);
    Some(([lo.x, lo.y], [hi.x, hi.y]))
}

/// Drop every LiDAR return (under the LiDARs' initial extrinsics, at its firing time) whose
/// world position lies horizontally outside the drive's footprint grown by `radius_m`. A sweep
/// whose points cannot be placed (outside the trajectory) is left as it is.
pub fn keep_near_drive(lidars: &mut [LidarData], trajectory: &Trajectory, radius_m: f64) -> Kept {
    let mut tally = Kept::default();
    let Some((lo, hi)) = drive_footprint(trajectory, radius_m) else {
        return tally;
    };
    for lidar in lidars.iter_mut() {
        for sweep in &mut lidar.sweeps {
            let Ok(points) = world_points(&sweep.view(), trajectory, lidar.initial, 1) else {
                tally.kept += sweep.len();
                continue;
            };
            let keep: Vec<bool> = points
                .iter()
                .map(|p| p.x >= lo[0] && p.x <= hi[0] && p.y >= lo[1] && p.y <= hi[1])
                .collect();
            let dropped = keep.iter().filter(|k| !**k).count();
            sweep.retain(&keep);
            tally.dropped += dropped;
            tally.kept += sweep.len();
        }
    }
    tally
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Rigid;
    use crate::log::LidarSweep;
    use glam::DQuat;

    fn straight_drive() -> Trajectory {
        // Ten metres along x in one second, then nothing.
        Trajectory::new(
            (0..=10)
                .map(|k| {
                    let t = k as i64 * 100_000_000;
                    (
                        t,
                        Rigid::new(DQuat::IDENTITY, DVec3::new(k as f64, 0.0, 0.0)),
                    )
                })
                .collect(),
        )
    }

    #[test]
    fn the_footprint_is_the_drive_grown_by_the_radius() {
        let (lo, hi) = drive_footprint(&straight_drive(), 5.0).expect("a footprint");
        assert_eq!(lo, [-5.0, -5.0]);
        assert_eq!(hi, [15.0, 5.0]);
        assert!(drive_footprint(&Trajectory::new(Vec::new()), 5.0).is_none());
    }

    #[test]
    fn only_returns_beyond_the_radius_go_with_their_intensity_and_time() {
        // A LiDAR 2 m up and 1 m right of the vehicle origin; the sweep at t = 0.5 s (x = 5).
        let vehicle_from_lidar = Rigid::new(DQuat::IDENTITY, DVec3::new(0.0, -1.0, 2.0));
        let sweep = LidarSweep {
            stamp_nanos: 500_000_000,
            frame_id: "lidar".into(),
            points_in_sensor: vec![
                [3.0, 0.0, 0.0],   // x 8, y −1: near
                [0.0, 30.0, 0.0],  // y 29: beyond 20 m sideways
                [-11.0, 0.0, 0.0], // x −6: 6 m behind the start, within 20 m
                [0.0, -20.5, 0.0], // y −21.5: beyond
                [40.0, 0.0, -1.0], // x 45: 35 m beyond the end
            ],
            intensity: vec![1.0, 2.0, 3.0, 4.0, 5.0],
            time_offset_secs: Some(vec![0.0, 0.01, 0.02, 0.03, 0.04]),
        };
        let mut lidars = vec![LidarData {
            name: "lidar".into(),
            initial: vehicle_from_lidar,
            sweeps: vec![sweep],
        }];
        let tally = keep_near_drive(&mut lidars, &straight_drive(), 20.0);
        assert_eq!(
            tally,
            Kept {
                kept: 2,
                dropped: 3
            }
        );
        let s = &lidars[0].sweeps[0];
        assert_eq!(s.points_in_sensor, vec![[3.0, 0.0, 0.0], [-11.0, 0.0, 0.0]]);
        assert_eq!(s.intensity, vec![1.0, 3.0]);
        assert_eq!(s.time_offset_secs, Some(vec![0.0, 0.02]));
    }
}
