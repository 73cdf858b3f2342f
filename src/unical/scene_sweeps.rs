//! Which sweeps of a LiDAR shape UniCal's scene: sweeps spread over the drive, and the sweep
//! nearest every image the cameras are fitted on. A camera ray is scored against the scene
//! where it lands; where no sweep saw that place the scene there is whatever the colour term
//! made of it, and the camera's pose follows that instead of the LiDAR. On the real KITTI-360
//! sample (20 frames 20–220 m apart) four sweeps spread over the drive left most of the
//! sixteen training images looking into places no sweep had seen.
//!
//! How it works. `count` sweeps are spread evenly over the usable part of the drive (as
//! before). Then, for each training image in time order, the sweep nearest it in time is added
//! unless a chosen sweep was taken within [`COVER_M`] of where the image was (a standing
//! vehicle's images are all covered by one sweep; on a sparse log every image gets its own).
//! At most [`MAX_SCENE_SWEEPS`] are taken per LiDAR (the added ones spread evenly when there
//! are more): the look-through test for moving traffic compares every sweep with every other.
//!
//! Why not a sweep for every image: sweeps taken a few metres apart see the same surfaces, and
//! each one adds occupied cells that every ray then samples. On PandaSet-002 (21 m in 8 s) a
//! sweep within 1 m of every image (10 per LiDAR instead of 4) made a step about 20 % slower,
//! the run stopped at step 818 of its 1000 within its budget, and the cameras ended 0.652°
//! off on average instead of 0.457° (seed 54, docs/experiments/real-camera-methods.md).
//! Positions come from the trajectory at the stamps; nothing is decoded.

use crate::log::{Drive, spread_evenly};
use glam::DVec3;

/// A sweep taken within this distance (m) of where an image was taken saw what the image
/// sees (a LiDAR's returns reach tens of metres): no other sweep is added for that image.
pub const COVER_M: f64 = 10.0;

/// The most sweeps of one LiDAR the scene is shaped by (or `count`, where more are asked for).
pub const MAX_SCENE_SWEEPS: usize = 32;

/// The sweeps of LiDAR `name` inside `segments_nanos` that shape the scene: `count` spread
/// evenly and the nearest one to each of `image_stamps_nanos`; indices of its stream in time
/// order.
pub fn pick(
    drive: &Drive,
    name: &str,
    count: usize,
    segments_nanos: &[(i64, i64)],
    image_stamps_nanos: &[i64],
) -> Vec<usize> {
    let Some(stream) = drive.stream(name) else {
        return Vec::new();
    };
    let usable: Vec<(usize, i64)> = drive
        .frames_within(name, segments_nanos)
        .into_iter()
        .filter_map(|i| Some((i, stream.frames.get(i)?.stamp_nanos)))
        .collect();
    pick_among(&usable, count, image_stamps_nanos, |t| {
        drive
            .trajectory
            .world_from_vehicle(t)
            .ok()
            .map(|p| p.translation)
    })
}

/// [`pick`] among the sweeps `usable` (index and stamp, in time order), with the vehicle's
/// position at a stamp.
pub fn pick_among(
    usable: &[(usize, i64)],
    count: usize,
    image_stamps_nanos: &[i64],
    position: impl Fn(i64) -> Option<DVec3>,
) -> Vec<usize> {
    if usable.is_empty() {
        return Vec::new();
    }
    let spread = spread_evenly(usable, count);
    let mut chosen: Vec<(usize, Option<DVec3>)> =
        spread.iter().map(|&(i, t)| (i, position(t))).collect();
    let mut added = Vec::new();
    let mut images = image_stamps_nanos.to_vec();
    images.sort_unstable();
    for t in images {
        let Some(&(nearest, stamp)) = usable.iter().min_by_key(|(_, s)| (s - t).abs()) else {
            continue;
        };
        if chosen.iter().any(|(i, _)| *i == nearest) {
            continue;
        }
        let here = position(t);
        let covered = here.is_some_and(|here| {
            chosen
                .iter()
                .any(|(_, p)| p.is_some_and(|p| p.distance(here) <= COVER_M))
        });
        if !covered {
            chosen.push((nearest, position(stamp)));
            added.push(nearest);
        }
    }
    let room = MAX_SCENE_SWEEPS.saturating_sub(spread.len());
    if added.len() > room {
        added.sort_unstable();
        added = if room == 0 {
            Vec::new()
        } else {
            spread_evenly(&added, room)
        };
    }
    let mut picked: Vec<usize> = spread.iter().map(|&(i, _)| i).chain(added).collect();
    picked.sort_unstable();
    picked.dedup();
    picked
}

#[cfg(test)]
mod tests {
    use super::*;

    const SECOND: i64 = 1_000_000_000;

    /// `n` sweeps at 10 Hz of a vehicle driving along x at `speed` m/s.
    fn drive(n: usize) -> Vec<(usize, i64)> {
        (0..n).map(|i| (i, i as i64 * SECOND / 10)).collect()
    }

    fn along(speed: f64) -> impl Fn(i64) -> Option<DVec3> {
        move |t| Some(DVec3::new(speed * t as f64 / SECOND as f64, 0.0, 0.0))
    }

    #[test]
    fn without_images_the_spread_is_kept() {
        let usable = drive(80);
        assert_eq!(
            pick_among(&usable, 4, &[], along(10.0)),
            vec![10, 30, 50, 70]
        );
    }

    #[test]
    fn each_image_far_from_the_spread_gets_its_nearest_sweep() {
        let usable = drive(80);
        // Images 2 ms after sweeps 0, 25 and 79, and one on the spread's sweep 30.
        let images = [
            2_000_000,
            25 * SECOND / 10 + 2_000_000,
            3 * SECOND,
            79 * SECOND / 10,
        ];
        // 40 m/s: the spread's sweeps are 80 m apart, each image 20 m or more from them.
        assert_eq!(
            pick_among(&usable, 4, &images, along(40.0)),
            vec![0, 10, 25, 30, 50, 70, 79]
        );
    }

    #[test]
    fn images_within_reach_of_the_spread_need_no_more_sweeps() {
        // 10 m/s: the spread's sweeps are 20 m apart, no image more than 10 m from one.
        let usable = drive(80);
        let images: Vec<i64> = (0..16).map(|k| k * SECOND / 2).collect();
        assert_eq!(
            pick_among(&usable, 4, &images, along(10.0)),
            vec![10, 30, 50, 70]
        );
        // 15 m/s: the spread's sweeps 30 m apart; the first image (15 m before the first of
        // them) and those half-way between two get their own; the last image (7.5 s: 112.5 m)
        // is 7.5 m past the last.
        assert_eq!(
            pick_among(&usable, 4, &images, along(15.0)),
            vec![0, 10, 20, 30, 40, 50, 60, 70]
        );
    }

    #[test]
    fn a_standing_vehicle_needs_no_more_sweeps() {
        let usable = drive(80);
        let images: Vec<i64> = (0..16).map(|k| k * SECOND / 2).collect();
        assert_eq!(
            pick_among(&usable, 4, &images, along(0.0)),
            vec![10, 30, 50, 70]
        );
    }

    #[test]
    fn a_sparse_sample_uses_every_sweep_an_image_is_near() {
        // Twenty frames 9 s apart (90 m at 10 m/s), an image at each but the first.
        let usable: Vec<(usize, i64)> = (0..20).map(|i| (i, i as i64 * 9 * SECOND)).collect();
        let images: Vec<i64> = (1..20).map(|i| i * 9 * SECOND + 1_000_000).collect();
        assert_eq!(
            pick_among(&usable, 4, &images, along(10.0)),
            (1..20).collect::<Vec<_>>()
        );
    }

    #[test]
    fn the_added_sweeps_are_capped_and_spread() {
        let usable = drive(400);
        let images: Vec<i64> = (0..400).map(|i| i * SECOND / 10).collect();
        // 200 m/s: every sweep 20 m from the next, no image covered by another's sweep.
        let picked = pick_among(&usable, 4, &images, along(200.0));
        assert_eq!(picked.len(), MAX_SCENE_SWEEPS);
        // The spread's four are among them, the rest reach both ends of the drive.
        for i in [50, 150, 250, 350] {
            assert!(picked.contains(&i), "{picked:?}");
        }
        assert!(
            picked[0] < 20 && picked[MAX_SCENE_SWEEPS - 1] > 380,
            "{picked:?}"
        );
    }

    #[test]
    fn no_sweeps_no_scene() {
        assert!(pick_among(&[], 4, &[5], along(1.0)).is_empty());
    }
}
