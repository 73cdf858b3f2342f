#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The simulator's silhouette acceptance measure, in detail: the stationary checkerboard scene's
//! front camera, LiDAR depth discontinuities of 16 accumulated sweeps projected with the true
//! extrinsics, and the distribution of their distances to the nearest image edge (the mean is
//! what `tests/sim_acceptance.rs` bounds). Writes the edge map with the silhouette points drawn
//! over it (green within 1 px of an edge, red beyond).
//! `cargo run --release --example silhouette_check -- [OUT.png] [SCENE_SEED]`

use glam::DVec3;
use rigcal::eval::edges;
use rigcal::geometry::projection::{SweepView, project_sweep};
use rigcal::geometry::{Rigid, Trajectory, so3};
use rigcal::sim::camera_sim::{self, Exposure, RayTable};
use rigcal::sim::lidar_sim;
use rigcal::sim::rigs::{RigPreset, SimRig};
use rigcal::sim::trajectories::{self, TrajectoryConfig, TrajectoryKind};
use rigcal::sim::world::{SceneKind, World};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let out = args
        .get(1)
        .cloned()
        .unwrap_or_else(|| "silhouettes.png".into());
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(3);
    let rig = SimRig::preset(RigPreset::Pandaset);
    let tcfg = TrajectoryConfig {
        kind: TrajectoryKind::Stationary,
        duration_secs: 3.0,
        rate_hz: 100.0,
        speed_mps: 0.0,
        seed,
    };
    let traj = Trajectory::new(trajectories::generate(&tcfg));
    let world = World::build(
        SceneKind::Checkerboard,
        &trajectories::path_polyline(&tcfg, 1.0),
        seed,
    );
    let lidar = &rig.lidars[0];
    let cam = rig
        .cameras
        .iter()
        .find(|c| c.name == "front_camera")
        .unwrap();
    let img = camera_sim::render(
        &world,
        &RayTable::new(&cam.intrinsics),
        &cam.intrinsics,
        traj.world_from_vehicle(1_000_000_000).unwrap() * cam.vehicle_from_camera,
        Exposure {
            gain: 1.0,
            tint: [1.0; 3],
            noise_sigma: 2.0,
            seed: 1,
        },
    );
    let (w, h) = (img.width() as usize, img.height() as usize);
    let edge_map = edges::image_edges(&img);
    let dt = edges::distance_transform(&edge_map, w, h);
    let mut accumulated: Vec<[f32; 3]> = Vec::new();
    for k in 0..16 {
        let sweep =
            lidar_sim::simulate_sweep(&world, lidar, &traj, 500_000_000 + k * 100_000_000, 5)
                .unwrap();
        accumulated.extend_from_slice(&sweep.points_in_sensor);
    }
    let silhouettes: Vec<[f32; 3]> = edges::depth_discontinuities(&accumulated, 0.05)
        .into_iter()
        .map(|i| accumulated[i])
        .collect();
    let intensity = vec![0.0; silhouettes.len()];
    for error_deg in [0.0, 1.0] {
        let wrong = cam.vehicle_from_camera
            * Rigid::new(
                so3::exp(DVec3::new(0.0, 1.0, 0.0) * f64::to_radians(error_deg)),
                DVec3::ZERO,
            );
        let view = SweepView {
            points_in_lidar: &silhouettes,
            intensity: &intensity,
            time_offset_secs: None,
            stamp_nanos: 1_000_000_000,
        };
        let px: Vec<[f32; 2]> = project_sweep(
            &view,
            &traj,
            lidar.vehicle_from_lidar,
            wrong,
            &cam.intrinsics,
            1_000_000_000,
            1,
        )
        .unwrap()
        .iter()
        .map(|p| p.pixel)
        .collect();
        let mut d: Vec<f32> = px
            .iter()
            .filter_map(|p| {
                let (x, y) = (p[0].round(), p[1].round());
                (x >= 0.0 && y >= 0.0 && x < w as f32 && y < h as f32)
                    .then(|| dt[y as usize * w + x as usize])
            })
            .collect();
        d.sort_by(f32::total_cmp);
        let hist: Vec<usize> = [0.0f32, 1.0, 1.5, 2.0, 3.0, 1e9]
            .windows(2)
            .map(|b| d.iter().filter(|&&x| x >= b[0] && x < b[1]).count())
            .collect();
        println!("histogram [0,1) [1,1.5) [1.5,2) [2,3) [3,inf): {hist:?}");
        let n = d.len();
        let mean = d.iter().sum::<f32>() / n as f32;
        let q = |f: f64| d[((n as f64 * f) as usize).min(n - 1)];
        let tail: f32 = d.iter().filter(|&&x| x > 3.0).sum::<f32>() / n as f32;
        println!(
            "{error_deg}°: {n} points, mean {mean:.3} px; median {:.2}, p75 {:.2}, p90 {:.2}, p99 {:.2}, max {:.1}; \
             share > 1 px {:.1} %, > 3 px {:.1} % (contributing {tail:.3} px of the mean)",
            q(0.5),
            q(0.75),
            q(0.9),
            q(0.99),
            d[n - 1],
            100.0 * d.iter().filter(|&&x| x > 1.0).count() as f32 / n as f32,
            100.0 * d.iter().filter(|&&x| x > 3.0).count() as f32 / n as f32,
        );
        if error_deg == 0.0 {
            let mut overlay = image::RgbImage::new(w as u32, h as u32);
            for (k, e) in edge_map.iter().enumerate() {
                let g = img.as_raw()[3 * k] / 3;
                let v = if *e { [255, 255, 255] } else { [g, g, g] };
                overlay.put_pixel((k % w) as u32, (k / w) as u32, image::Rgb(v));
            }
            for p in &px {
                let (x, y) = (p[0].round(), p[1].round());
                if x >= 0.0 && y >= 0.0 && x < w as f32 && y < h as f32 {
                    let dist = dt[y as usize * w + x as usize];
                    let c = if dist <= 1.0 {
                        [0, 255, 0]
                    } else {
                        [255, 0, 0]
                    };
                    overlay.put_pixel(x as u32, y as u32, image::Rgb(c));
                }
            }
            overlay.save(&out).unwrap();
            img.save(out.replace(".png", "-image.png")).unwrap();
        }
    }
}
