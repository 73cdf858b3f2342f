//! LiDAR simulation: per-beam elevation tables, rotating (or rastering) azimuth with a firing time
//! per point, range noise, dropouts on dark and grazing surfaces, a maximum range, and intensity
//! from reflectivity and incidence angle.
//!
//! A spinning LiDAR turns clockwise seen from above; its sweep stamp is the moment it faces
//! the vehicle's forward direction, so a point at azimuth a (rad, CCW from forward) fires at −a / 2π · period relative to
//! the stamp: the back fires half a period early, as on PandaSet. Points are returned in the
//! LiDAR frame at their own firing time (raw, not deskewed).

use glam::DVec3;
use rayon::prelude::*;

use super::noise::hash3;
use super::rigs::SimLidar;
use super::world::World;
use crate::geometry::{Rigid, Trajectory, TrajectoryError};
use crate::log::LidarSweep;

/// Firing-time offset (s) of azimuth `az_rad` for a spinning LiDAR of the given period.
/// `az_rad` is measured from the LiDAR's forward direction and wrapped to [−π, π).
pub fn spin_time_offset_secs(az_rad: f64, period_secs: f64) -> f64 {
    let wrapped =
        (az_rad + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    -wrapped / std::f64::consts::TAU * period_secs
}

fn gaussian(a: i32, b: i32, seed: u64) -> f32 {
    let u1 = hash3(a, b, 7, seed).max(1e-7);
    let u2 = hash3(a, b, 8, seed);
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

/// Simulate one sweep stamped `stamp_nanos`.
pub fn simulate_sweep(
    world: &World,
    lidar: &SimLidar,
    trajectory: &Trajectory,
    stamp_nanos: i64,
    seed: u64,
) -> Result<LidarSweep, TrajectoryError> {
    let period = 1.0 / lidar.rotation_hz.max(1e-3);
    let (az0, az1) = (
        lidar.azimuth_range_deg.0.to_radians(),
        lidar.azimuth_range_deg.1.to_radians(),
    );
    let steps = (((az1 - az0).abs() / lidar.azimuth_resolution_deg.to_radians().max(1e-5)).round()
        as usize)
        .max(1);
    // Azimuth columns and their firing times. Like real sensors, the firing azimuths drift from
    // one revolution to the next: a per-sweep phase within one azimuth step.
    let phase = hash3((stamp_nanos / 1_000_000) as i32, 0, 5, seed) as f64 - 0.5;
    let forward = lidar.forward_azimuth_deg().to_radians();
    let columns: Vec<(f64, f64)> = (0..steps)
        .map(|k| {
            let az = az0 + (az1 - az0) * (k as f64 + 0.5 + phase) / steps as f64;
            let t = if lidar.spinning {
                spin_time_offset_secs(az - forward, period)
            } else {
                ((k as f64 + 0.5) / steps as f64 - 0.5) * period
            };
            (az, t)
        })
        .collect();
    let poses: Vec<Rigid> = columns
        .iter()
        .map(|(_, t)| {
            Ok(
                trajectory.world_from_vehicle(stamp_nanos + (t * 1e9) as i64)?
                    * lidar.vehicle_from_lidar,
            )
        })
        .collect::<Result<_, TrajectoryError>>()?;
    let stamp_seed = seed ^ (stamp_nanos as u64).wrapping_mul(0x9E37_79B9);
    let elevations: Vec<f64> = lidar
        .beam_elevations_deg
        .iter()
        .map(|e| e.to_radians())
        .collect();
    let per_column: Vec<Vec<([f32; 3], f32, f32)>> = columns
        .par_iter()
        .zip(poses.par_iter())
        .enumerate()
        .map(|(k, ((az, t), world_from_lidar))| {
            let origin = world_from_lidar.translation.as_vec3();
            let rot = world_from_lidar.rotation.as_quat();
            let mut out = Vec::with_capacity(elevations.len());
            for (b, el) in elevations.iter().enumerate() {
                let d_lidar = DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
                let d_world = rot * d_lidar.as_vec3();
                let Some(hit) = world.trace(origin, d_world, lidar.max_range_m as f32) else {
                    continue;
                };
                let surf = world.surface(&hit, 0.02);
                let cos_inc = (-d_world.dot(hit.normal)).clamp(0.0, 1.0);
                // Dropouts: grazing incidence and dark surfaces return too little light.
                let u = hash3(k as i32, b as i32, 1, stamp_seed);
                let p_drop = 0.01
                    + if cos_inc < 0.12 { 0.7 } else { 0.0 }
                    + if surf.reflectivity < 0.06 { 0.5 } else { 0.0 };
                if u < p_drop as f32 {
                    continue;
                }
                let range =
                    hit.t + lidar.range_noise_m as f32 * gaussian(k as i32, b as i32, stamp_seed);
                if range <= 0.3 || range > lidar.max_range_m as f32 {
                    continue;
                }
                let p = d_lidar.as_vec3() * range;
                let falloff = 1.0 / (1.0 + (hit.t / 120.0).powi(2));
                let intensity = (255.0 * surf.reflectivity * (0.3 + 0.7 * cos_inc) * falloff)
                    .clamp(0.0, 255.0)
                    .round();
                out.push((p.to_array(), intensity, *t as f32));
            }
            out
        })
        .collect();
    let n: usize = per_column.iter().map(Vec::len).sum();
    let mut sweep = LidarSweep {
        stamp_nanos,
        frame_id: lidar.name.clone(),
        points_in_sensor: Vec::with_capacity(n),
        intensity: Vec::with_capacity(n),
        time_offset_secs: Some(Vec::with_capacity(n)),
    };
    for col in per_column {
        for (p, i, t) in col {
            sweep.points_in_sensor.push(p);
            sweep.intensity.push(i);
            if let Some(times) = sweep.time_offset_secs.as_mut() {
                times.push(t);
            }
        }
    }
    Ok(sweep)
}
