//! How high the LiDARs look: the elevation of their highest returns in the vehicle frame, above
//! which camera rays see nothing the scene's geometry was given.
//!
//! How it works. The scene is sampled only in voxels the LiDARs occupied (`super::occupancy`),
//! so a façade above the highest beam (a Pandar64 looks up to 15°, a side camera with a 60°
//! vertical field of view up to 30°) has no surface to be painted on: its colour can only go
//! to the sky, a function of the view direction alone, which has no parallax. Rays there pull
//! the cameras' rotations to suit that sky (on the real PandaSet drive every camera ends
//! pitched up against the reference, docs/experiments/robustness-protocol.md). [`lidar_top_elevation_rad`] is the
//! 99.9th percentile of the returns' elevations (`asin` of the vehicle-frame direction's z,
//! the vehicle frame z up as in ROS's REP 103), the highest over the LiDARs, measured from each
//! LiDAR's own centre: a camera mounted at or below the LiDARs that draws rays only up to that
//! elevation sees only what some beam could have reached.

use glam::DVec3;

use super::depth_calib::LidarData;
use crate::geometry::Rigid;

/// The share of returns above the elevation [`lidar_top_elevation_rad`] reports: a few stray
/// returns (rain, a bird) must not open the sky.
pub const TOP_QUANTILE: f64 = 0.999;

/// Returns nearer than this (m) are not counted: the vehicle's own body.
const MIN_RANGE_M: f64 = 1.0;

/// Every this many returns of a sweep is counted (elevations repeat beam by beam).
const STRIDE: usize = 7;

/// The elevation (rad) of the LiDARs' highest returns in the vehicle frame, each at its
/// `initial` extrinsic (module docs); `None` without returns.
pub fn lidar_top_elevation_rad(lidars: &[LidarData]) -> Option<f64> {
    lidars
        .iter()
        .filter_map(|l| {
            let mut elevations: Vec<f64> = l
                .sweeps
                .iter()
                .flat_map(|s| s.points_in_sensor.iter().step_by(STRIDE))
                .filter_map(|p| {
                    let v = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                    (v.length() >= MIN_RANGE_M).then(|| elevation_rad(l.initial.rotation * v))
                })
                .collect();
            if elevations.is_empty() {
                return None;
            }
            let k = ((elevations.len() - 1) as f64 * TOP_QUANTILE).round() as usize;
            Some(*elevations.select_nth_unstable_by(k, f64::total_cmp).1)
        })
        .max_by(f64::total_cmp)
}

/// The elevation (rad) of the world-frame ray direction `d` in the vehicle frame of
/// `world_from_vehicle`.
pub fn ray_elevation_rad(world_from_vehicle: Rigid, d: DVec3) -> f64 {
    elevation_rad(world_from_vehicle.rotation.inverse() * d)
}

fn elevation_rad(v: DVec3) -> f64 {
    (v.z / v.length()).clamp(-1.0, 1.0).asin()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::log::LidarSweep;
    use glam::DQuat;

    /// A spinning LiDAR's sweep: `beams_deg` at 360 azimuths, 10 m away.
    fn sweep(beams_deg: &[f64]) -> LidarSweep {
        let mut points = Vec::new();
        for a in 0..360 {
            let az = (a as f64).to_radians();
            for e in beams_deg {
                let e = e.to_radians();
                let v = DVec3::new(e.cos() * az.cos(), e.cos() * az.sin(), e.sin()) * 10.0;
                points.push([v.x as f32, v.y as f32, v.z as f32]);
            }
        }
        LidarSweep {
            stamp_nanos: 0,
            frame_id: "lidar".into(),
            intensity: vec![1.0; points.len()],
            points_in_sensor: points,
            time_offset_secs: None,
        }
    }

    fn lidar(initial: Rigid, beams_deg: &[f64]) -> LidarData {
        LidarData {
            name: "lidar".into(),
            initial,
            sweeps: vec![sweep(beams_deg)],
        }
    }

    #[test]
    fn the_top_is_the_highest_beam_of_the_highest_lidar() {
        let beams: Vec<f64> = (0..32).map(|k| 15.0 - k as f64).collect();
        let level = lidar(Rigid::IDENTITY, &beams);
        let top = lidar_top_elevation_rad(std::slice::from_ref(&level)).unwrap();
        assert!(
            (top.to_degrees() - 15.0).abs() < 1e-4,
            "{}",
            top.to_degrees()
        );
        // A second LiDAR looking no higher than 5° does not lower it; one up to 20° raises it.
        let low = lidar(Rigid::IDENTITY, &[5.0, 0.0, -5.0]);
        let high = lidar(Rigid::IDENTITY, &[20.0, 10.0]);
        let both = lidar_top_elevation_rad(&[level.clone(), low]).unwrap();
        assert!((both.to_degrees() - 15.0).abs() < 1e-4);
        let three = lidar_top_elevation_rad(&[level, high]).unwrap();
        assert!((three.to_degrees() - 20.0).abs() < 1e-4);
        assert_eq!(lidar_top_elevation_rad(&[]), None);
    }

    #[test]
    fn a_tilted_mount_raises_the_top_and_stray_returns_do_not() {
        // Mounted pitched 5° nose-up (about the vehicle's y axis, negative angle lifts +x):
        // the beam at 15° reaches 20° in front of the vehicle.
        let tilt = Rigid::new(DQuat::from_rotation_y(-5f64.to_radians()), DVec3::ZERO);
        let beams: Vec<f64> = (0..32).map(|k| 15.0 - k as f64).collect();
        let tilted = lidar(tilt, &beams);
        let top = lidar_top_elevation_rad(&[tilted]).unwrap().to_degrees();
        assert!((top - 20.0).abs() < 0.05, "{top}");
        // Three returns at 60° among 11 520 are strays: the top stays at the beams'.
        let mut l = lidar(Rigid::IDENTITY, &beams);
        for _ in 0..3 {
            l.sweeps[0].points_in_sensor.push([5.0, 0.0, 8.66]);
        }
        let top = lidar_top_elevation_rad(&[l]).unwrap().to_degrees();
        assert!((top - 15.0).abs() < 1e-4, "{top}");
    }

    #[test]
    fn a_rays_elevation_is_measured_in_the_vehicle_frame() {
        // A vehicle heading 90° left: a world ray north and 10° up is 10° up.
        let v = Rigid::new(
            DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2),
            DVec3::new(3.0, 4.0, 0.0),
        );
        let e = 10f64.to_radians();
        let d = DVec3::new(0.0, e.cos(), e.sin());
        assert!((ray_elevation_rad(v, d) - e).abs() < 1e-12);
        // Pitched 10° nose-up, a level world ray is 10° below the vehicle's horizon.
        let pitched = Rigid::new(DQuat::from_rotation_y(-e), DVec3::ZERO);
        assert!((ray_elevation_rad(pitched, DVec3::X) + e).abs() < 1e-12);
    }
}
