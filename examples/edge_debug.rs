#![allow(clippy::unwrap_used, clippy::expect_used)]
use glam::DVec3;
use rigcal::eval::edges;
use rigcal::geometry::Trajectory;
use rigcal::geometry::projection::{SweepView, project_sweep};
use rigcal::sim::camera_sim::{self, Exposure, RayTable};
use rigcal::sim::lidar_sim;
use rigcal::sim::rigs::{RigPreset, SimRig};
use rigcal::sim::trajectories::{self, TrajectoryConfig, TrajectoryKind};
use rigcal::sim::world::{SceneKind, World};
fn main() {
    let rig = SimRig::preset(RigPreset::Pandaset);
    let tcfg = TrajectoryConfig {
        kind: TrajectoryKind::Stationary,
        duration_secs: 3.0,
        rate_hz: 100.0,
        speed_mps: 0.0,
        seed: 3,
    };
    let traj = Trajectory::new(trajectories::generate(&tcfg));
    let world = World::build(
        SceneKind::Checkerboard,
        &trajectories::path_polyline(&tcfg, 1.0),
        3,
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
    let e = edges::image_edges(&img);
    let dt = edges::distance_transform(&e, w, h);
    let mut sil = Vec::new();
    for k in 0..16 {
        let sweep =
            lidar_sim::simulate_sweep(&world, lidar, &traj, 500_000_000 + k * 100_000_000, 5)
                .unwrap();
        for i in edges::depth_discontinuities(&sweep.points_in_sensor, 0.05) {
            sil.push(sweep.points_in_sensor[i]);
        }
    }
    let inten = vec![0.0; sil.len()];
    let view = SweepView {
        points_in_lidar: &sil,
        intensity: &inten,
        time_offset_secs: None,
        stamp_nanos: 1_000_000_000,
    };
    let px = project_sweep(
        &view,
        &traj,
        lidar.vehicle_from_lidar,
        cam.vehicle_from_camera,
        &cam.intrinsics,
        1_000_000_000,
        1,
    )
    .unwrap();
    let mut out = image::RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let v = img.get_pixel(x, y)[1] / 3;
        if e[y as usize * w + x as usize] {
            image::Rgb([255, 255, 255])
        } else {
            image::Rgb([v, v, v])
        }
    });
    let mut ds: Vec<f32> = Vec::new();
    for p in &px {
        let (x, y) = (p.pixel[0].round() as i64, p.pixel[1].round() as i64);
        if x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h {
            ds.push(dt[y as usize * w + x as usize]);
            out.put_pixel(x as u32, y as u32, image::Rgb([255, 0, 0]));
        }
    }
    ds.sort_by(f32::total_cmp);
    let q = |f: f64| ds[((ds.len() as f64 - 1.0) * f) as usize];
    eprintln!(
        "n {} p10 {} p50 {} p75 {} p90 {} p99 {}",
        ds.len(),
        q(0.1),
        q(0.5),
        q(0.75),
        q(0.9),
        q(0.99)
    );
    out.save("/tmp/sim/edges.png").unwrap();
    // Analytic outline of the front board vs. where silhouettes and edges are.
    let b = &world.boards[0];
    let world_from_cam = traj.world_from_vehicle(1_000_000_000).unwrap() * cam.vehicle_from_camera;
    let cam_from_world = world_from_cam.inverse();
    let wdt = b.squares_u as f32 * b.square_m + 2.0 * b.margin_m;
    let c0 = b.origin - b.u_axis * b.margin_m - b.v_axis * b.margin_m;
    for (name, pnt) in [("top-left", c0), ("top-right", c0 + b.u_axis * wdt)] {
        let pc = cam_from_world.transform_point(pnt.as_dvec3());
        eprintln!("{name}: {:?}", cam.intrinsics.project(pc));
    }
    let row = 500usize;
    let xs: Vec<usize> = (700..900).filter(|&x| e[row * w + x]).collect();
    eprintln!("edges on row {row} in 700..900: {xs:?}");
    let reds: Vec<f32> = px
        .iter()
        .filter(|p| {
            (p.pixel[1] - row as f32).abs() < 15.0 && p.pixel[0] > 700.0 && p.pixel[0] < 900.0
        })
        .map(|p| p.pixel[0])
        .collect();
    eprintln!("silhouettes near row {row}: {reds:?}");
    let _ = DVec3::ZERO;
}
