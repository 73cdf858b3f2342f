//! Which sweeps a LiDAR is fitted to the trajectory on ([`super::trajectory_icp`]): sweeps
//! that share surfaces. The fit compares each sweep with its neighbours in time; sweeps taken
//! far apart see different streets, and what few returns match (the far ones, the sparsest
//! and noisiest) pull the LiDAR anywhere: on the real KITTI-360 sample (20 frames about 90 m
//! apart) the fit turned the Velodyne 3.6° from a start 1° off.
//!
//! How it works. Sweeps spread evenly over the usable part of the drive are kept as they are
//! when every neighbour in the spread is within [`OVERLAP_M`] of travel (a short drive: the
//! simulator's and PandaSet's eight seconds). On a longer drive they are taken in pairs
//! instead: half as many anchors spread evenly, each with the first later sweep at least
//! [`PAIR_TRAVEL_M`] from it (and within [`OVERLAP_M`]); the pairs see the drive's turns
//! wherever they are, and each pair's two sweeps share surfaces. A drive whose consecutive
//! sweeps are more than [`OVERLAP_M`] apart but for fewer than [`MIN_PAIRS`] (a sparse
//! sample) is not fitted at all.
//! Positions come from the trajectory at the sweeps' stamps; nothing is decoded.

use crate::log::{Drive, spread_evenly};
use glam::DVec3;

/// The farthest apart (m of vehicle travel) two sweeps of a LiDAR may be and still share
/// enough surfaces for the fit.
pub const OVERLAP_M: f64 = 25.0;

/// The travel (m) between the two sweeps of a pair on a long drive: enough for the vehicle to
/// turn between them on a bend, well inside [`OVERLAP_M`].
pub const PAIR_TRAVEL_M: f64 = 10.0;

/// The fewest pairs of consecutive sweeps within [`OVERLAP_M`] a fit needs: one pair is one
/// look at one place.
pub const MIN_PAIRS: usize = 3;

/// The sweeps [`pick`] chose.
#[derive(Clone, Debug, PartialEq)]
pub enum Picked {
    /// Sweep indices of the LiDAR's stream, in time order.
    Sweeps(Vec<usize>),
    /// Fewer than [`MIN_PAIRS`] consecutive sweeps are within [`OVERLAP_M`] of each other
    /// (`pairs` are).
    TooSparse { pairs: usize },
}

/// About `frames` sweeps of LiDAR `name` inside `segments_nanos` that share surfaces.
pub fn pick(drive: &Drive, name: &str, frames: usize, segments_nanos: &[(i64, i64)]) -> Picked {
    let usable = drive.frames_within(name, segments_nanos);
    let Some(stream) = drive.stream(name) else {
        return Picked::Sweeps(Vec::new());
    };
    pick_among(&usable, frames, |i| {
        let stamp = stream.frames.get(i)?.stamp_nanos;
        let pose = drive.trajectory.world_from_vehicle(stamp).ok()?;
        Some(pose.translation)
    })
}

/// [`pick`] among the sweeps `usable` (in time order), with the vehicle's position at each.
pub fn pick_among(
    usable: &[usize],
    frames: usize,
    position: impl Fn(usize) -> Option<DVec3>,
) -> Picked {
    let apart = |a: usize, b: usize| match (position(a), position(b)) {
        (Some(p), Some(q)) => p.distance(q),
        _ => f64::INFINITY,
    };
    let largest_gap = |picked: &[usize]| {
        picked
            .windows(2)
            .map(|w| apart(w[0], w[1]))
            .fold(0.0, f64::max)
    };
    let spread = spread_evenly(usable, frames);
    if spread.len() < 2 || largest_gap(&spread) <= OVERLAP_M {
        return Picked::Sweeps(spread);
    }
    let pairs = usable
        .windows(2)
        .filter(|w| apart(w[0], w[1]) <= OVERLAP_M)
        .count();
    if pairs < MIN_PAIRS {
        return Picked::TooSparse { pairs };
    }
    let mut picked = Vec::new();
    for anchor in spread_evenly(usable, (frames / 2).max(1)) {
        let partner = usable
            .iter()
            .copied()
            .filter(|&j| j > anchor)
            .take_while(|&j| apart(anchor, j) <= OVERLAP_M)
            .find(|&j| apart(anchor, j) >= PAIR_TRAVEL_M);
        if let Some(j) = partner {
            picked.extend([anchor, j]);
        }
    }
    picked.sort_unstable();
    picked.dedup();
    if picked.len() < 2 {
        // Sweeps close enough exist, but none a pair's travel apart: the vehicle barely
        // moves between them; the even spread is as good as any.
        return Picked::Sweeps(spread);
    }
    Picked::Sweeps(picked)
}

#[cfg(test)]
mod tests;
