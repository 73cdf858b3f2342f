#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The checkerboard corner error on the simulator's stationary checkerboard scene: boards found
//! in the LiDAR sweep where the simulator put them, corners found in the image, a small error
//! with the true extrinsics and a large one with the camera rotated by 1° either way.

use glam::{DVec3, Vec3};
use rigcal::eval::checkerboard::{BoardSpec, boards_in_points, corner_error};
use rigcal::geometry::projection::{SweepView, world_points};
use rigcal::geometry::{Rigid, Trajectory, so3};
use rigcal::sim::camera_sim::{self, Exposure, RayTable};
use rigcal::sim::lidar_sim;
use rigcal::sim::rigs::{RigPreset, SimRig};
use rigcal::sim::trajectories::{self, TrajectoryConfig, TrajectoryKind};
use rigcal::sim::world::{SceneKind, World};

#[test]
fn corner_error_separates_true_and_rotated_extrinsics() {
    let rig = SimRig::preset(RigPreset::Pandaset);
    let tcfg = TrajectoryConfig {
        kind: TrajectoryKind::Stationary,
        duration_secs: 2.0,
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
    let spec = BoardSpec::default();
    let t = 1_000_000_000;
    let world_from_vehicle = traj.world_from_vehicle(t).unwrap();
    // Boards in the spinning LiDAR's sweep, in the world frame.
    let lidar = &rig.lidars[0];
    let sweep = lidar_sim::simulate_sweep(&world, lidar, &traj, t, 5).unwrap();
    let view = SweepView {
        points_in_lidar: &sweep.points_in_sensor,
        intensity: &sweep.intensity,
        time_offset_secs: sweep.time_offset_secs.as_deref(),
        stamp_nanos: sweep.stamp_nanos,
    };
    let points = world_points(&view, &traj, lidar.vehicle_from_lidar, 1).unwrap();
    let boards = boards_in_points(&points, &spec);
    assert!(
        boards.len() >= 4,
        "only {} boards in the sweep",
        boards.len()
    );
    for b in &boards {
        eprintln!(
            "board at {:.2?} n {:.2?} inliers {}",
            b.center, b.normal, b.inliers
        );
    }
    for b in &boards {
        // The simulator's board centres (pattern centred on the board).
        let nearest = world
            .boards
            .iter()
            .map(|w| {
                let c: Vec3 = w.origin
                    + w.u_axis * (w.squares_u as f32 * w.square_m * 0.5)
                    + w.v_axis * (w.squares_v as f32 * w.square_m * 0.5);
                b.center.distance(c.as_dvec3())
            })
            .fold(f64::MAX, f64::min);
        assert!(nearest < 0.04, "a board {nearest:.3} m from any true board");
    }
    // Corner error in the front camera, true and rotated ±1° about its vertical axis.
    let cam = rig
        .cameras
        .iter()
        .find(|c| c.name == "front_camera")
        .unwrap();
    let image = camera_sim::render(
        &world,
        &RayTable::new(&cam.intrinsics),
        &cam.intrinsics,
        world_from_vehicle * cam.vehicle_from_camera,
        Exposure {
            gain: 1.0,
            tint: [1.0; 3],
            noise_sigma: 2.0,
            seed: 1,
        },
    );
    let error = |deg: f64| {
        let vehicle_from_camera = cam.vehicle_from_camera
            * Rigid::new(so3::exp(DVec3::Y * deg.to_radians()), DVec3::ZERO);
        let camera_from_world = (world_from_vehicle * vehicle_from_camera).inverse();
        corner_error(&image, &cam.intrinsics, camera_from_world, &boards, &spec)
    };
    let truth = error(0.0).expect("no board found in the front camera");
    eprintln!("true extrinsics: {truth:?}");
    assert!(truth.corners >= 30, "{truth:?}");
    assert!(truth.mean_px < 4.0, "{truth:?}");
    for deg in [-1.0, 1.0] {
        let wrong = error(deg).expect("boards lost at 1°");
        eprintln!("{deg}°: {wrong:?}");
        assert!(
            wrong.mean_px > 3.0 * truth.mean_px && wrong.mean_px > 15.0,
            "{deg}°: {} px vs {} px",
            wrong.mean_px,
            truth.mean_px
        );
    }
}

#[test]
fn pair_corner_error_on_a_written_drive() {
    use rigcal::eval::checkerboard::pair_corner_error;
    use rigcal::log::Drive;
    use rigcal::sim::synth::{SynthConfig, synthesize};
    let mut rig = SimRig::preset(RigPreset::Pandaset);
    rig.cameras.retain(|c| c.name == "front_camera");
    let mut cfg = SynthConfig::new(
        SceneKind::Checkerboard,
        rig,
        TrajectoryKind::Stationary,
        0.25,
        3,
    );
    cfg.camera_rate_hz = 5.0;
    let dir = std::env::temp_dir().join(format!("rigcal-board-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (log, gt) = (dir.join("boards.mcap"), dir.join("gt.yaml"));
    synthesize(&cfg, &log, &gt, &mut |_, _| {}).unwrap();
    let drive = Drive::open(&log).unwrap();
    let spec = BoardSpec::default();
    let good = pair_corner_error(&drive, &drive.rig, "front_camera", "pandar64", 1, &spec)
        .unwrap()
        .expect("no board found through the drive");
    let mut wrong = drive.rig.clone();
    let s = wrong.sensor_mut("front_camera").unwrap();
    s.vehicle_from_sensor = s
        .vehicle_from_sensor
        .perturbed_right(DVec3::new(0.0, 1f64.to_radians(), 0.0), DVec3::ZERO);
    let bad = pair_corner_error(&drive, &wrong, "front_camera", "pandar64", 1, &spec)
        .unwrap()
        .expect("boards lost at 1°");
    eprintln!("drive: {good:?} / {bad:?}");
    assert!(
        good.mean_px < 4.0 && bad.mean_px > 15.0,
        "{good:?} / {bad:?}"
    );
    let _ = std::fs::remove_dir_all(dir);
}
