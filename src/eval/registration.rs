//! LiDAR–LiDAR registration error: the paper's point-to-plane metric (method.md §13).
//!
//! How it works. Both clouds are in one frame (the world, each point moved with the trajectory
//! at its firing time under the calibration being measured). The target cloud is hashed into
//! cells as large as the inlier distance (30 cm). For every source point the nearest target
//! point within that distance is its correspondence; the target's local plane there is the
//! least-squares plane of the target points within [`NORMAL_RADIUS_M`] (at least
//! [`MIN_NEIGHBOURS`], and flat: the variance across the plane at most [`MAX_FLATNESS`] of the
//! total), and the error is the source point's distance to that plane. The result is the mean
//! over those inliers, in centimetres. A miscalibrated LiDAR puts the same wall at two depths,
//! and this distance grows with the error; two views of a flat surface agree to the range noise.

use crate::error::RunError;
use std::collections::HashMap;

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use crate::geometry::so3;

/// The paper's inlier distance (m).
pub const MAX_CORRESPONDENCE_M: f64 = 0.3;
/// Radius of the target neighbourhood a normal is fitted to (m).
pub const NORMAL_RADIUS_M: f64 = 0.5;
pub const MIN_NEIGHBOURS: usize = 6;
/// Largest ratio of the smallest covariance eigenvalue to the trace for a neighbourhood to be
/// a plane.
pub const MAX_FLATNESS: f64 = 0.02;

/// Point-to-plane agreement of one LiDAR pair.
#[derive(Clone, Debug, PartialEq)]
pub struct RegistrationError {
    /// Mean point-to-plane distance over inliers (cm).
    pub mean_cm: f64,
    /// Source points with a planar target correspondence within the inlier distance.
    pub inliers: usize,
    /// Source points tried.
    pub source_points: usize,
}

/// Points hashed by cell, for radius queries (also ICP's neighbour search).
pub struct CellIndex<'a> {
    points: &'a [DVec3],
    cell_m: f64,
    cells: HashMap<[i32; 3], Vec<u32>>,
}

impl<'a> CellIndex<'a> {
    /// The nearest point within `radius_m` of `p`.
    pub fn nearest(&self, p: DVec3, radius_m: f64) -> Option<u32> {
        self.within(p, radius_m).min_by(|a, b| {
            let da = self.points[*a as usize].distance_squared(p);
            da.total_cmp(&self.points[*b as usize].distance_squared(p))
        })
    }

    pub fn new(points: &'a [DVec3], cell_m: f64) -> Self {
        let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
        for (i, p) in points.iter().enumerate() {
            cells
                .entry(Self::key(*p, cell_m))
                .or_default()
                .push(i as u32);
        }
        Self {
            points,
            cell_m,
            cells,
        }
    }

    fn key(p: DVec3, cell_m: f64) -> [i32; 3] {
        (p / cell_m).floor().as_ivec3().to_array()
    }

    /// Indices of the points within `radius_m` of `p`.
    pub fn within(&self, p: DVec3, radius_m: f64) -> impl Iterator<Item = u32> + '_ {
        let reach = (radius_m / self.cell_m).ceil() as i32;
        let [cx, cy, cz] = Self::key(p, self.cell_m);
        let r2 = radius_m * radius_m;
        (-reach..=reach)
            .flat_map(move |dx| {
                (-reach..=reach)
                    .flat_map(move |dy| (-reach..=reach).map(move |dz| [cx + dx, cy + dy, cz + dz]))
            })
            .filter_map(|k| self.cells.get(&k))
            .flatten()
            .copied()
            .filter(move |&i| self.points[i as usize].distance_squared(p) <= r2)
    }
}

/// Unit normal of the least-squares plane through `points`, if they are flat enough.
pub fn plane_normal(points: &[DVec3]) -> Option<DVec3> {
    let n = points.len();
    if n < MIN_NEIGHBOURS {
        return None;
    }
    let mean = points.iter().sum::<DVec3>() / n as f64;
    let mut cov = DMat3::ZERO;
    for p in points {
        let q = *p - mean;
        cov += so3::outer(q, q);
    }
    normal_of_covariance(cov, MAX_FLATNESS)
}

/// [`plane_normal`] from the moments of the points taken relative to any nearby origin `o`:
/// their count, `Σ (p − o)` and `Σ (p − o)(p − o)ᵀ` (one pass, no list of neighbours), flat
/// when the variance across the plane is at most `max_flatness` of the total.
pub fn plane_normal_from_moments(
    n: usize,
    sum: DVec3,
    outer: DMat3,
    max_flatness: f64,
) -> Option<DVec3> {
    if n < MIN_NEIGHBOURS {
        return None;
    }
    let mean = sum / n as f64;
    let cov = outer - so3::outer(mean, sum);
    normal_of_covariance(cov, max_flatness)
}

fn normal_of_covariance(cov: DMat3, max_flatness: f64) -> Option<DVec3> {
    let normal = smallest_eigenvector(cov)?;
    let trace = cov.x_axis.x + cov.y_axis.y + cov.z_axis.z;
    let across = normal.dot(cov * normal);
    (trace > 0.0 && across <= max_flatness * trace).then_some(normal)
}

/// Eigenvector of the smallest eigenvalue of a symmetric positive semi-definite matrix: inverse
/// iteration on `cov + ε·I` from the best of the three cross products of its rows.
fn smallest_eigenvector(cov: DMat3) -> Option<DVec3> {
    let trace = cov.x_axis.x + cov.y_axis.y + cov.z_axis.z;
    if !trace.is_finite() || trace <= 0.0 {
        return None;
    }
    let rows = [cov.row(0), cov.row(1), cov.row(2)];
    let mut v = [
        rows[0].cross(rows[1]),
        rows[0].cross(rows[2]),
        rows[1].cross(rows[2]),
    ]
    .into_iter()
    .max_by(|a, b| a.length_squared().total_cmp(&b.length_squared()))?
    .try_normalize()
    .unwrap_or(DVec3::Z);
    let shifted = cov + DMat3::from_diagonal(DVec3::splat(1e-9 * trace));
    if shifted.determinant().abs() < 1e-300 {
        return Some(v);
    }
    let inverse = shifted.inverse();
    for _ in 0..8 {
        v = (inverse * v).try_normalize()?;
    }
    Some(v)
}

/// Point-to-plane error of `source` against `target` (both in one frame).
pub fn point_to_plane_error(source: &[DVec3], target: &[DVec3]) -> Option<RegistrationError> {
    let index = CellIndex::new(target, MAX_CORRESPONDENCE_M);
    let distances: Vec<f64> = source
        .par_iter()
        .filter_map(|p| {
            let nearest = index
                .nearest(*p, MAX_CORRESPONDENCE_M)
                .map(|i| target[i as usize])?;
            let neighbours: Vec<DVec3> = index
                .within(nearest, NORMAL_RADIUS_M)
                .map(|i| target[i as usize])
                .collect();
            let normal = plane_normal(&neighbours)?;
            Some(normal.dot(*p - nearest).abs())
        })
        .collect();
    (!distances.is_empty()).then(|| RegistrationError {
        mean_cm: distances.iter().sum::<f64>() / distances.len() as f64 * 100.0,
        inliers: distances.len(),
        source_points: source.len(),
    })
}

/// The registration error of one LiDAR pair of a drive under each of `rigs` (e.g. a
/// calibration and its reference): up to `frames` sweeps of `source` spread over the drive,
/// each against the sweep of `target` nearest in time, both moved into the world frame with the
/// trajectory (every `stride`-th source point). Each sweep is read once for all rigs.
pub fn pair_registration_errors(
    drive: &crate::log::Drive,
    rigs: &[&crate::calib::Rig],
    source: &str,
    target: &str,
    frames: usize,
    stride: usize,
) -> Result<Vec<Option<RegistrationError>>, RunError> {
    use crate::geometry::projection::world_points;
    let extrinsics = |name: &str| {
        rigs.iter()
            .map(|rig| {
                rig.sensor(name)
                    .map(|s| s.vehicle_from_sensor)
                    .ok_or_else(|| RunError::no_sensor("sensor", name))
            })
            .collect::<Result<Vec<_>, _>>()
    };
    let (vehicle_from_source, vehicle_from_target) = (extrinsics(source)?, extrinsics(target)?);
    let stream = |name: &str| {
        drive.stream(name).map(|s| &s.frames).ok_or_else(|| {
            RunError::NotEnoughData(format!(
                "no sweeps of '{name}' in {}",
                drive.path().display()
            ))
        })
    };
    let (sources, targets) = (stream(source)?, stream(target)?);
    // Per rig: Σ mean·inliers, inliers, points tried.
    let mut sums = vec![(0.0, 0, 0); rigs.len()];
    let all: Vec<usize> = (0..sources.len()).collect();
    for i in crate::log::spread_evenly(&all, frames) {
        let stamp = sources[i].stamp_nanos;
        let Some(j) = (0..targets.len()).min_by_key(|&j| (targets[j].stamp_nanos - stamp).abs())
        else {
            continue;
        };
        let (Some(src_sweep), Some(tgt_sweep)) = (
            drive.sweep_or_skip(source, i),
            drive.sweep_or_skip(target, j),
        ) else {
            continue;
        };
        for (r, sum) in sums.iter_mut().enumerate() {
            let world = |sweep: &crate::log::LidarSweep, extrinsic, stride, name: &str| {
                world_points(&sweep.view(), &drive.trajectory, extrinsic, stride)
                    .map_err(|e| RunError::from(e).within(name))
            };
            let src = world(&src_sweep, vehicle_from_source[r], stride, source)?;
            let tgt = world(&tgt_sweep, vehicle_from_target[r], 1, target)?;
            if let Some(e) = point_to_plane_error(&src, &tgt) {
                sum.0 += e.mean_cm * e.inliers as f64;
                sum.1 += e.inliers;
                sum.2 += e.source_points;
            }
        }
    }
    Ok(sums
        .into_iter()
        .map(|(sum_cm, inliers, tried)| {
            (inliers > 0).then(|| RegistrationError {
                mean_cm: sum_cm / inliers as f64,
                inliers,
                source_points: tried,
            })
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A floor (z = 0) and two walls (x = 5, y = 4), sampled on a grid with a phase.
    fn room(phase: f64) -> Vec<DVec3> {
        let mut pts = Vec::new();
        for i in 0..60 {
            for j in 0..60 {
                let (a, b) = (i as f64 * 0.08 + phase, j as f64 * 0.08 + phase);
                pts.push(DVec3::new(a, b - 1.0, 0.0));
                pts.push(DVec3::new(5.0, a - 1.0, b * 0.5));
                pts.push(DVec3::new(a, 4.0, b * 0.5));
            }
        }
        pts
    }

    #[test]
    fn normals_of_planes_and_none_for_a_blob() {
        let floor: Vec<DVec3> = (0..50)
            .map(|k| DVec3::new((k % 7) as f64 * 0.1, (k / 7) as f64 * 0.1, 0.0))
            .collect();
        let n = plane_normal(&floor).unwrap();
        assert!((n.z.abs() - 1.0).abs() < 1e-9, "{n}");
        let tilted: Vec<DVec3> = floor
            .iter()
            .map(|p| DVec3::new(p.x, p.y, 0.5 * p.x))
            .collect();
        let n = plane_normal(&tilted).unwrap();
        let expected = DVec3::new(-0.5, 0.0, 1.0).normalize_or_zero();
        assert!((n.dot(expected).abs() - 1.0).abs() < 1e-9, "{n}");
        let blob: Vec<DVec3> = (0..64)
            .map(|k| DVec3::new((k % 4) as f64, ((k / 4) % 4) as f64, (k / 16) as f64) * 0.1)
            .collect();
        assert!(plane_normal(&blob).is_none());
        assert!(plane_normal(&floor[..3]).is_none());
    }

    #[test]
    fn aligned_clouds_agree_and_an_offset_is_measured() {
        let target = room(0.0);
        // Another sampling of the same surfaces: zero error.
        let source = room(0.037);
        let e = point_to_plane_error(&source, &target).unwrap();
        // (Up to a trace from neighbourhoods that straddle two walls at the corners.)
        assert!(e.mean_cm < 0.05, "{e:?}");
        assert!(e.inliers > source.len() / 2);
        // Shift the source 5 cm along (1, 1, 1)/√3: each plane sees 5/√3 cm.
        let shift = DVec3::ONE.normalize_or_zero() * 0.05;
        let moved: Vec<DVec3> = source.iter().map(|p| *p + shift).collect();
        let e = point_to_plane_error(&moved, &target).unwrap();
        let expected = 5.0 / 3f64.sqrt();
        assert!((e.mean_cm - expected).abs() < 0.1, "{e:?}");
        // Beyond the inlier distance nothing corresponds.
        let far: Vec<DVec3> = source.iter().map(|p| *p + DVec3::splat(2.0)).collect();
        let e = point_to_plane_error(&far, &target);
        assert!(
            e.as_ref().is_none_or(|e| e.inliers < source.len() / 10),
            "{e:?}"
        );
    }
}
