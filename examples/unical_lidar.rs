#![allow(clippy::unwrap_used, clippy::expect_used)]
//! UniCal's LiDAR stage on a simulated drive: perturb every LiDAR, learn the scene and the
//! extrinsics from depth, print the error against the ground truth as it goes.
//! `cargo run --release --example unical_lidar -- [ITERATIONS] [SECONDS] [PERTURBATION_SCALE]`

use glam::DVec3;
use rigcal::geometry::Trajectory;
use rigcal::sim::lidar_sim;
use rigcal::sim::rigs::{RigPreset, SimRig};
use rigcal::sim::trajectories::{self, TrajectoryConfig, TrajectoryKind};
use rigcal::sim::world::{SceneKind, World};
use rigcal::unical::depth_calib::{DepthCalibConfig, DepthCalibration, LidarData};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let iterations: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(300);
    let seconds: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(3.0);
    // Scale of the initial perturbation (0: start at the ground truth, to see the scene's own
    // rendering error).
    let perturbation: f64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(1.0);
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
    let t0 = std::time::Instant::now();
    let lidars: Vec<LidarData> = rig
        .lidars
        .iter()
        .enumerate()
        .map(|(k, l)| {
            let sweeps = (1..(seconds * 10.0) as i64)
                .map(|i| lidar_sim::simulate_sweep(&world, l, &traj, i * 100_000_000, 5).unwrap())
                .collect();
            let sign = if k == 0 { perturbation } else { -perturbation };
            LidarData {
                name: l.name.clone(),
                initial: l.vehicle_from_lidar.perturbed_right(
                    DVec3::new(0.6, -0.5, 0.6) * sign * 1f64.to_radians(),
                    DVec3::new(0.06, -0.05, 0.05) * sign,
                ),
                sweeps,
            }
        })
        .collect();
    eprintln!(
        "simulated {} LiDARs in {:.1} s",
        lidars.len(),
        t0.elapsed().as_secs_f64()
    );
    let truth: Vec<_> = rig.lidars.iter().map(|l| l.vehicle_from_lidar).collect();
    let config = DepthCalibConfig {
        iterations,
        ..DepthCalibConfig::default()
    };
    let mut calib = DepthCalibration::new(config, traj, lidars);
    eprintln!(
        "occupancy {:.1} % of {:?} voxels",
        calib.occupancy.occupied_fraction() * 100.0,
        calib.occupancy.dims
    );
    let t0 = std::time::Instant::now();
    for it in 0..iterations {
        let r = calib.step();
        if let Some(loss) = r.geometry_init_loss {
            if it % 25 == 0 {
                eprintln!(
                    "it {it:4} geometry init loss {loss:.4} · {:.2} s/it",
                    t0.elapsed().as_secs_f64() / (it + 1) as f64
                );
            }
            continue;
        }
        if it % 25 == 0 || it + 1 == iterations {
            let errs: Vec<String> = calib
                .extrinsics()
                .iter()
                .zip(&truth)
                .map(|((n, e), t)| {
                    let (r, d) = t.difference(*e);
                    format!("{n} {:.3}° {:.1} cm", r.to_degrees(), d * 100.0)
                })
                .collect();
            eprintln!(
                "it {it:4} depth loss {:.4} |err| {:.3} m int {:.4} reg {:.3} β {:.1} · {} · {:.2} s/it",
                r.loss,
                r.mean_abs_error_m,
                r.intensity_loss,
                r.regulariser_loss,
                r.beta,
                errs.join(" · "),
                t0.elapsed().as_secs_f64() / (it + 1) as f64
            );
        }
    }
}
