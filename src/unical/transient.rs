//! Returns of moving things (transient returns), found by the other sweeps looking through them.
//!
//! The scene is static (method.md §2), but a real drive has traffic: a car that passes leaves
//! returns in each sweep at another place, and a scene fitted to all of them grows a trail of
//! surfaces that the cameras then paint. A return is *transient* when other sweeps saw through
//! the place where it was: placed in the world by the trajectory and its LiDAR's extrinsic, it
//! is taken into another sweep's frame (at the firing time of its azimuth when the sweep has
//! per-point times), and if every return that sweep has around that direction (the
//! direction's bin and its eight neighbours, in a range image of [`TransientSettings::azimuth_bin_deg`]
//! by [`TransientSettings::elevation_bin_deg`]) lies more than [`TransientSettings::margin_m`]
//! beyond it, that sweep's beams passed through empty space there. Taking the *nearest* return
//! around the direction keeps static surfaces: the ground seen at a grazing angle, a thin pole,
//! an edge. A direction with no return in its neighbourhood (sky, outside a field of view) says
//! nothing. A return seen through by [`TransientSettings::min_votes`] sweeps or more is dropped
//! from its sweep before the occupancy grid and the depth term see it.

use glam::DVec3;
use rayon::prelude::*;

use super::depth_calib::LidarData;
use crate::geometry::projection::world_points;
use crate::geometry::{Rigid, Trajectory};
use crate::log::pointcloud::LidarSweep;

/// How the look-through test is made.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TransientSettings {
    /// Range-image bin across azimuth (degrees).
    pub azimuth_bin_deg: f64,
    /// Range-image bin across elevation (degrees); about a spinning LiDAR's widest beam spacing,
    /// so that a direction between two beams still finds a return.
    pub elevation_bin_deg: f64,
    /// How far beyond a return another sweep's returns must all lie (m).
    pub margin_m: f64,
    /// Sweeps that must see through a return for it to count as transient.
    pub min_votes: usize,
}

impl Default for TransientSettings {
    fn default() -> Self {
        Self {
            azimuth_bin_deg: 0.5,
            elevation_bin_deg: 1.0,
            margin_m: 1.0,
            min_votes: 2,
        }
    }
}

/// What [`remove_transient`] dropped.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TransientStats {
    /// Per LiDAR: (returns dropped, returns examined).
    pub per_lidar: Vec<(String, usize, usize)>,
}

impl TransientStats {
    pub fn dropped(&self) -> usize {
        self.per_lidar.iter().map(|(_, d, _)| d).sum()
    }

    pub fn examined(&self) -> usize {
        self.per_lidar.iter().map(|(_, _, n)| n).sum()
    }
}

/// One sweep as a range image: the nearest return per bin, and the mean firing time per
/// azimuth column (0 for a deskewed sweep).
struct RangeImage {
    lidar_from_world: Rigid,
    /// Per column, `lidar_from_world` at that column's firing time (None: the sweep's own).
    column_pose: Vec<Option<Rigid>>,
    nearest_m: Vec<f32>,
    cols: usize,
    rows: usize,
    settings: TransientSettings,
}

impl RangeImage {
    fn bin(&self, p_lidar: DVec3) -> Option<(usize, usize, f64)> {
        let range = p_lidar.length();
        if range < 1e-3 {
            return None;
        }
        let az = p_lidar.y.atan2(p_lidar.x).to_degrees() + 180.0;
        let el = (p_lidar.z / range).clamp(-1.0, 1.0).asin().to_degrees() + 90.0;
        let c = ((az / self.settings.azimuth_bin_deg) as usize).min(self.cols - 1);
        let r = ((el / self.settings.elevation_bin_deg) as usize).min(self.rows - 1);
        Some((c, r, range))
    }

    fn build(
        lidar: &LidarData,
        sweep: usize,
        trajectory: &Trajectory,
        settings: TransientSettings,
    ) -> Option<Self> {
        let s = &lidar.sweeps[sweep];
        let world_from_lidar = trajectory.world_from_vehicle(s.stamp_nanos).ok()? * lidar.initial;
        let cols = (360.0 / settings.azimuth_bin_deg).ceil() as usize;
        let rows = (180.0 / settings.elevation_bin_deg).ceil() as usize;
        let mut image = Self {
            lidar_from_world: world_from_lidar.inverse(),
            column_pose: vec![None; cols],
            nearest_m: vec![f32::INFINITY; cols * rows],
            cols,
            rows,
            settings,
        };
        let mut time_sum = vec![(0.0f64, 0usize); cols];
        for (k, p) in s.points_in_sensor.iter().enumerate() {
            let p = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let Some((c, r, range)) = image.bin(p) else {
                continue;
            };
            let cell = &mut image.nearest_m[r * cols + c];
            *cell = cell.min(range as f32);
            if let Some(t) = s.time_offset_secs.as_ref().and_then(|t| t.get(k)) {
                time_sum[c].0 += *t as f64;
                time_sum[c].1 += 1;
            }
        }
        for (c, (sum, n)) in time_sum.into_iter().enumerate() {
            if n > 0 {
                let stamp = s.stamp_nanos + (sum / n as f64 * 1e9) as i64;
                image.column_pose[c] = trajectory
                    .world_from_vehicle(stamp)
                    .ok()
                    .map(|wv| (wv * lidar.initial).inverse());
            }
        }
        Some(image)
    }

    /// Whether this sweep saw through `p_world`.
    fn sees_through(&self, p_world: DVec3) -> bool {
        let mut p = self.lidar_from_world.transform_point(p_world);
        let Some((c, _, _)) = self.bin(p) else {
            return false;
        };
        // Where the sweep has firing times, look again from where it was at that column.
        if let Some(lidar_from_world) = self.column_pose[c] {
            p = lidar_from_world.transform_point(p_world);
        }
        let Some((c, r, range)) = self.bin(p) else {
            return false;
        };
        let mut nearest = f32::INFINITY;
        for dr in [-1isize, 0, 1] {
            let rr = r as isize + dr;
            if rr < 0 || rr as usize >= self.rows {
                continue;
            }
            for dc in [-1isize, 0, 1] {
                let cc = (c as isize + dc).rem_euclid(self.cols as isize) as usize;
                nearest = nearest.min(self.nearest_m[rr as usize * self.cols + cc]);
            }
        }
        nearest.is_finite() && nearest as f64 > range + self.settings.margin_m
    }
}

/// The training sweeps as range images: what they saw, for asking whether a place was empty.
pub struct Witnesses {
    /// Keyed like the sweeps: (LiDAR, sweep, stamp).
    images: Vec<((usize, usize, i64), Option<RangeImage>)>,
    settings: TransientSettings,
}

impl Witnesses {
    /// Every sweep of `lidars`, placed by `trajectory` and each LiDAR's `initial` extrinsic.
    pub fn new(lidars: &[LidarData], trajectory: &Trajectory, settings: TransientSettings) -> Self {
        let keys: Vec<(usize, usize, i64)> = lidars
            .iter()
            .enumerate()
            .flat_map(|(k, l)| {
                l.sweeps
                    .iter()
                    .enumerate()
                    .map(move |(s, sweep)| (k, s, sweep.stamp_nanos))
            })
            .collect();
        let images = keys
            .par_iter()
            .map(|&(k, s, stamp)| {
                (
                    (k, s, stamp),
                    RangeImage::build(&lidars[k], s, trajectory, settings),
                )
            })
            .collect();
        Self { images, settings }
    }

    /// Whether enough sweeps other than LiDAR `lidar`'s sweep stamped `stamp_nanos` (the one
    /// the return comes from, if it is a witness) saw through `p_world`.
    pub fn is_transient(&self, p_world: DVec3, lidar: usize, stamp_nanos: i64) -> bool {
        self.images
            .iter()
            .filter(|((k, _, stamp), image)| {
                !(*k == lidar && *stamp == stamp_nanos)
                    && image.as_ref().is_some_and(|im| im.sees_through(p_world))
            })
            .take(self.settings.min_votes)
            .count()
            >= self.settings.min_votes
    }

    /// The returns of `sweep` (of LiDAR `lidar`, with extrinsic `vehicle_from_lidar`) that are
    /// transient, in the world.
    pub fn transient_points(
        &self,
        sweep: &LidarSweep,
        lidar: usize,
        vehicle_from_lidar: Rigid,
        trajectory: &Trajectory,
    ) -> Vec<DVec3> {
        let flags = self.flags(sweep, lidar, vehicle_from_lidar, trajectory);
        flags
            .into_iter()
            .filter_map(|(q, transient)| transient.then_some(q))
            .collect()
    }

    /// Each return of `sweep` in the world, and whether it is transient (a sweep that reaches
    /// outside the trajectory is kept whole and not placed: `DVec3::NAN`).
    fn flags(
        &self,
        sweep: &LidarSweep,
        lidar: usize,
        vehicle_from_lidar: Rigid,
        trajectory: &Trajectory,
    ) -> Vec<(DVec3, bool)> {
        let Ok(points) = world_points(&sweep.view(), trajectory, vehicle_from_lidar, 1) else {
            return vec![(DVec3::NAN, false); sweep.len()];
        };
        points
            .into_par_iter()
            .map(|q| (q, self.is_transient(q, lidar, sweep.stamp_nanos)))
            .collect()
    }
}

/// Drop every return of `lidars` that at least `settings.min_votes` other sweeps (of any LiDAR)
/// saw through, placed by `trajectory` and each LiDAR's `initial` extrinsic; the witnesses are
/// the sweeps as they came, and are returned for masking camera images.
pub fn remove_transient(
    lidars: &mut [LidarData],
    trajectory: &Trajectory,
    settings: TransientSettings,
) -> (TransientStats, Witnesses) {
    let witnesses = Witnesses::new(lidars, trajectory, settings);
    let mut stats = TransientStats::default();
    for (k, lidar) in lidars.iter_mut().enumerate() {
        let (mut dropped, mut examined) = (0, 0);
        for sweep in &mut lidar.sweeps {
            let keep: Vec<bool> = witnesses
                .flags(sweep, k, lidar.initial, trajectory)
                .into_iter()
                .map(|(_, transient)| !transient)
                .collect();
            examined += sweep.len();
            sweep.retain(&keep);
            dropped += keep.iter().filter(|k| !**k).count();
        }
        stats
            .per_lidar
            .push((lidar.name.clone(), dropped, examined));
    }
    (stats, witnesses)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SECOND: i64 = 1_000_000_000;

    /// The nearest hit along `dir` from `origin` in a street: the ground (z = 0), a wall at
    /// y = 12 m and, if given, a car (an axis-aligned box) whose rear is at `car_x`.
    fn cast(origin: DVec3, dir: DVec3, car_x: Option<f64>) -> Option<DVec3> {
        let mut best = f64::INFINITY;
        if dir.z < -1e-9 {
            best = best.min(-origin.z / dir.z);
        }
        if dir.y > 1e-9 {
            best = best.min((12.0 - origin.y) / dir.y);
        }
        if let Some(x0) = car_x {
            let (lo, hi) = (DVec3::new(x0, 3.0, 0.0), DVec3::new(x0 + 4.5, 5.0, 1.5));
            let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
            for a in 0..3 {
                if dir[a].abs() < 1e-12 {
                    if origin[a] < lo[a] || origin[a] > hi[a] {
                        t0 = f64::INFINITY;
                    }
                    continue;
                }
                let (ta, tb) = ((lo[a] - origin[a]) / dir[a], (hi[a] - origin[a]) / dir[a]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
            if t0 <= t1 {
                best = best.min(t0);
            }
        }
        (best < 60.0).then(|| origin + dir * best)
    }

    /// A LiDAR 1.8 m up on a vehicle driving along x at 5 m/s, one sweep per second; a car
    /// overtakes at 12 m/s in the next lane when `traffic`.
    fn street(traffic: bool) -> (Trajectory, Vec<LidarData>) {
        let trajectory = Trajectory::new(
            (0..=6)
                .map(|s| {
                    (
                        s * SECOND,
                        Rigid::from_translation(DVec3::new(5.0 * s as f64, 0.0, 0.0)),
                    )
                })
                .collect(),
        );
        let vehicle_from_lidar = Rigid::from_translation(DVec3::new(0.0, 0.0, 1.8));
        let sweeps = (0..6)
            .map(|s| {
                let t = s as f64;
                let origin = DVec3::new(5.0 * t, 0.0, 1.8);
                let car = traffic.then_some(-5.0 + 12.0 * t);
                let mut points = Vec::new();
                for az in 0..720 {
                    for el in 0..32 {
                        let (a, e) = (
                            (az as f64 * 0.5).to_radians(),
                            (-25.0 + el as f64 * 1.25).to_radians(),
                        );
                        let dir = DVec3::new(a.cos() * e.cos(), a.sin() * e.cos(), e.sin());
                        if let Some(hit) = cast(origin, dir, car) {
                            let p = hit - origin;
                            points.push([p.x as f32, p.y as f32, p.z as f32]);
                        }
                    }
                }
                LidarSweep {
                    stamp_nanos: s * SECOND,
                    frame_id: "lidar".into(),
                    intensity: vec![1.0; points.len()],
                    points_in_sensor: points,
                    time_offset_secs: None,
                }
            })
            .collect();
        let lidar = LidarData {
            name: "lidar".into(),
            initial: vehicle_from_lidar,
            sweeps,
        };
        (trajectory, vec![lidar])
    }

    #[test]
    fn a_passing_car_is_dropped_and_the_street_is_kept() {
        let (trajectory, mut lidars) = street(true);
        let before: Vec<Vec<[f32; 3]>> = lidars[0]
            .sweeps
            .iter()
            .map(|s| s.points_in_sensor.clone())
            .collect();
        let (stats, _) = remove_transient(&mut lidars, &trajectory, TransientSettings::default());
        let (mut car_kept, mut car_total, mut static_dropped, mut static_total) = (0, 0, 0, 0);
        for (s, (sweep, all)) in lidars[0].sweeps.iter().zip(&before).enumerate() {
            let origin = DVec3::new(5.0 * s as f64, 0.0, 1.8);
            let car_x = -5.0 + 12.0 * s as f64;
            let on_car = |p: &[f32; 3]| {
                let q = origin + DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                q.x > car_x - 0.01 && q.x < car_x + 4.51 && q.y > 2.99 && q.y < 5.01 && q.z > 0.01
            };
            let kept: std::collections::HashSet<[u32; 3]> = sweep
                .points_in_sensor
                .iter()
                .map(|p| p.map(f32::to_bits))
                .collect();
            for p in all {
                let survived = kept.contains(&p.map(f32::to_bits));
                if on_car(p) {
                    car_total += 1;
                    car_kept += survived as usize;
                } else {
                    static_total += 1;
                    static_dropped += !survived as usize;
                }
            }
            assert_eq!(sweep.intensity.len(), sweep.points_in_sensor.len());
        }
        assert!(car_total > 300, "the car is seen: {car_total} returns");
        // Its lowest returns stay: a ray through them meets the road within the margin.
        assert!(
            (car_kept as f64) < 0.3 * car_total as f64,
            "{car_kept} of {car_total} car returns kept"
        );
        assert!(
            (static_dropped as f64) < 0.002 * static_total as f64,
            "{static_dropped} of {static_total} static returns dropped"
        );
        assert_eq!(stats.dropped(), car_total - car_kept + static_dropped);
        assert_eq!(stats.examined(), car_total + static_total);
    }

    #[test]
    fn a_sweeps_transient_points_are_the_cars_in_the_world() {
        let (trajectory, lidars) = street(true);
        let witnesses = Witnesses::new(&lidars, &trajectory, TransientSettings::default());
        let sweep = &lidars[0].sweeps[2];
        let points = witnesses.transient_points(sweep, 0, lidars[0].initial, &trajectory);
        // At 2 s the car's rear is at x = 19 m.
        assert!(points.len() > 50, "{} points", points.len());
        for q in &points {
            assert!(
                q.x > 18.99 && q.x < 23.51 && q.y > 2.99 && q.y < 5.01,
                "{q:?} is not on the car"
            );
        }
    }

    #[test]
    fn a_static_street_loses_nothing() {
        let (trajectory, mut lidars) = street(false);
        let total: usize = lidars[0].sweeps.iter().map(|s| s.len()).sum();
        let (stats, _) = remove_transient(&mut lidars, &trajectory, TransientSettings::default());
        assert_eq!(stats.examined(), total);
        assert_eq!(stats.dropped(), 0, "{stats:?}");
    }

    #[test]
    fn one_sweep_alone_says_nothing() {
        let (trajectory, mut lidars) = street(true);
        lidars[0].sweeps.truncate(1);
        let (stats, _) = remove_transient(&mut lidars, &trajectory, TransientSettings::default());
        assert_eq!(stats.dropped(), 0);
    }
}
