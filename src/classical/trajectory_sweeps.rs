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
//! sweeps yield fewer than [`MIN_PAIRS`] such pairs (a sparse sample, or a vehicle that barely
//! moves between close sweeps) is not fitted at all.
//! Positions come from the trajectory at the sweeps' stamps; nothing is decoded.

use crate::log::{Drive, spread_evenly};
use glam::DVec3;

/// The farthest apart (m between the vehicle's positions) two sweeps of a LiDAR may be and still share
/// enough surfaces for the fit.
pub const OVERLAP_M: f64 = 25.0;

/// The travel (m) between the two sweeps of a pair on a long drive: enough for the vehicle to
/// turn between them on a bend, well inside [`OVERLAP_M`].
pub const PAIR_TRAVEL_M: f64 = 10.0;

/// The fewest pairs of sweeps [`PAIR_TRAVEL_M`]–[`OVERLAP_M`] apart a fit needs (fewer where
/// fewer sweeps are asked for): one pair is one look at one place.
pub const MIN_PAIRS: usize = 3;

/// The sweeps [`pick`] chose.
#[derive(Clone, Debug, PartialEq)]
pub enum Picked {
    /// Sweep indices of the LiDAR's stream, in time order.
    Sweeps(Vec<usize>),
    /// Fewer than [`MIN_PAIRS`] pairs of sweeps [`PAIR_TRAVEL_M`]–[`OVERLAP_M`] apart were
    /// found (`pairs` were).
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
    // Pairs in time order, [a, b, a, b, …]: the fit splits the sweeps by parity, so each
    // pair's two sweeps fall in different sets (an anchor before the last partner is passed).
    let mut picked: Vec<usize> = Vec::new();
    for anchor in spread_evenly(usable, (frames / 2).max(1)) {
        if picked.last().is_some_and(|&last| anchor <= last) {
            continue;
        }
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
    let pairs = picked.len() / 2;
    if pairs < MIN_PAIRS.min((frames / 2).max(1)) {
        return Picked::TooSparse { pairs };
    }
    Picked::Sweeps(picked)
}

#[cfg(test)]
mod tests;
