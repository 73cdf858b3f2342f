#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Render one simulated camera image to PNG, for looking at the simulator's pictures.
//! `cargo run --release --example render_frame -- SCENE CAMERA OUT.png [TIME_S] [SCALE]`
//! With `RENDER_REPEAT=N` it first renders every camera of the rig at N times from TIME_S on
//! (0.5 s apart) and prints the mean time per image (a steadier figure for profiling); the
//! drive is then at least 8 s long, like the default drive.

use rigcal::geometry::Trajectory;
use rigcal::sim::camera_sim::{self, Exposure, RayTable};
use rigcal::sim::rigs::{RigPreset, SimRig};
use rigcal::sim::trajectories::{self, TrajectoryConfig, TrajectoryKind};
use rigcal::sim::world::SceneKind;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let scene: SceneKind = args
        .get(1)
        .map_or("urban", |s| s.as_str())
        .parse()
        .map_err(anyhow::Error::msg)?;
    let camera = args
        .get(2)
        .cloned()
        .unwrap_or_else(|| "front_camera".into());
    let out = args.get(3).cloned().unwrap_or_else(|| "frame.png".into());
    let time_s: f64 = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let repeat: usize = std::env::var("RENDER_REPEAT")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let scale: f64 = args.get(5).and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let kind = if scene == SceneKind::Checkerboard {
        TrajectoryKind::Stationary
    } else {
        TrajectoryKind::Figure8
    };
    let tcfg = TrajectoryConfig {
        kind,
        duration_secs: if repeat > 0 {
            (time_s + 1.0 + 0.5 * repeat as f64).max(8.0)
        } else {
            time_s + 1.0
        },
        rate_hz: 100.0,
        speed_mps: 8.0,
        seed: 7,
    };
    let traj = Trajectory::new(trajectories::generate(&tcfg));
    let world =
        rigcal::sim::world::World::build(scene, &trajectories::path_polyline(&tcfg, 1.0), 7);
    eprintln!("{world:?}");
    let rig = SimRig::preset(RigPreset::Pandaset).scaled(scale);
    let cam = rig
        .cameras
        .iter()
        .find(|c| c.name == camera)
        .ok_or_else(|| anyhow::anyhow!("no camera {camera}"))?;
    if repeat > 0 {
        let tables: Vec<RayTable> = rig
            .cameras
            .iter()
            .map(|c| RayTable::new(&c.intrinsics))
            .collect();
        let started = std::time::Instant::now();
        let mut images = 0;
        for i in 0..repeat {
            let t = time_s + 0.5 * i as f64;
            for (c, table) in rig.cameras.iter().zip(&tables) {
                let pose = traj.world_from_vehicle((t * 1e9) as i64)? * c.vehicle_from_camera;
                let exposure = Exposure {
                    gain: 1.0,
                    tint: [1.0; 3],
                    noise_sigma: 2.0,
                    seed: 1,
                };
                camera_sim::render(&world, table, &c.intrinsics, pose, exposure);
                images += 1;
            }
        }
        eprintln!(
            "{images} images, {:.3} s per image",
            started.elapsed().as_secs_f64() / images as f64
        );
    }
    let started = std::time::Instant::now();
    let pose = traj.world_from_vehicle((time_s * 1e9) as i64)? * cam.vehicle_from_camera;
    let table = RayTable::new(&cam.intrinsics);
    eprintln!("ray table in {:.2} s", started.elapsed().as_secs_f64());
    let started = std::time::Instant::now();
    let img = camera_sim::render(
        &world,
        &table,
        &cam.intrinsics,
        pose,
        Exposure {
            gain: 1.0,
            tint: [1.0; 3],
            noise_sigma: 2.0,
            seed: 1,
        },
    );
    eprintln!(
        "rendered {}x{} in {:.2} s",
        img.width(),
        img.height(),
        started.elapsed().as_secs_f64()
    );
    let corners = rigcal::eval::fast::fast9(
        &rigcal::features::grey::grey_u8(&img),
        img.width() as usize,
        img.height() as usize,
        20,
    );
    eprintln!("{} FAST corners", corners.len());
    img.save(&out)?;
    Ok(())
}
