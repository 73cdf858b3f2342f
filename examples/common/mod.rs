//! The simulated drive the UniCal examples learn from: the urban scene, the pandaset rig,
//! a figure-8 at 8 m/s (seed 3), sweeps of every LiDAR at 10 Hz.

use rigcal::geometry::Trajectory;
use rigcal::sim::lidar_sim;
use rigcal::sim::rigs::{RigPreset, SimLidar, SimRig};
use rigcal::sim::trajectories::{self, TrajectoryConfig, TrajectoryKind};
use rigcal::sim::world::{SceneKind, World};
use rigcal::unical::depth_calib::LidarData;

/// The rig, its trajectory (`seconds` + 0.5 s long) and the world around it.
pub fn drive(seconds: f64) -> (SimRig, Trajectory, World) {
    let rig = SimRig::preset(RigPreset::Pandaset);
    let tcfg = TrajectoryConfig {
        kind: TrajectoryKind::Figure8,
        duration_secs: seconds + 0.5,
        rate_hz: 100.0,
        speed_mps: 8.0,
        seed: 3,
    };
    let traj = Trajectory::new(trajectories::generate(&tcfg));
    let world = World::build(
        SceneKind::Urban,
        &trajectories::path_polyline(&tcfg, 1.0),
        3,
    );
    (rig, traj, world)
}

/// `lidar`'s sweeps over the first `seconds`, starting from `initial`.
pub fn lidar_data(
    world: &World,
    lidar: &SimLidar,
    traj: &Trajectory,
    seconds: f64,
    initial: rigcal::geometry::Rigid,
) -> LidarData {
    LidarData {
        name: lidar.name.clone(),
        initial,
        sweeps: (1..(seconds * 10.0) as i64)
            .map(|i| {
                lidar_sim::simulate_sweep(world, lidar, traj, i * 100_000_000, 5)
                    .expect("a sweep inside the trajectory")
            })
            .collect(),
    }
}

/// Every LiDAR's sweeps over the first `seconds`, starting from its true pose.
#[allow(dead_code)] // unical_lidar starts from perturbed poses instead
pub fn lidars_at_truth(
    world: &World,
    rig: &SimRig,
    traj: &Trajectory,
    seconds: f64,
) -> Vec<LidarData> {
    rig.lidars
        .iter()
        .map(|l| lidar_data(world, l, traj, seconds, l.vehicle_from_lidar))
        .collect()
}

/// `RIGCAL_OPACITY=interval|per-sample` overrides the opacity model (`default` otherwise).
#[allow(dead_code)] // not every example reads it
pub fn opacity_from_env(
    default: rigcal::unical::composite::OpacityModel,
) -> rigcal::unical::composite::OpacityModel {
    use rigcal::unical::composite::OpacityModel;
    match std::env::var("RIGCAL_OPACITY").as_deref() {
        Ok("interval") => OpacityModel::Interval,
        Ok("per-sample") => OpacityModel::PerSample,
        _ => default,
    }
}
