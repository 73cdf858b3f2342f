#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Simulator acceptance: the output reads back as asked (trajectory, perturbed extrinsics,
//! ground truth); LiDAR silhouettes land on image edges with the true extrinsics (≤ 1 px in the
//! stationary scene) and clearly worse with a 1° error; urban images are textured enough for
//! corner detectors.

use rigcal::calib::CalibrationFile;
use rigcal::eval::fast;
use rigcal::geometry::{Trajectory, so3};
use rigcal::log::Drive;
use rigcal::sim::camera_sim::{self, Exposure, RayTable};
use rigcal::sim::rigs::{RigPreset, SimRig};
use rigcal::sim::silhouettes::SilhouetteCheck;
use rigcal::sim::synth::{EPOCH_NANOS, SynthConfig, synthesize};
use rigcal::sim::trajectories::{self, TrajectoryConfig, TrajectoryKind};
use rigcal::sim::world::{SceneKind, World};

#[test]
fn output_reads_back_as_asked() {
    let mut cfg = SynthConfig::new(
        SceneKind::Urban,
        SimRig::preset(RigPreset::Pandaset),
        TrajectoryKind::Figure8,
        0.6,
        11,
    );
    cfg.perturb_deg = 2.0;
    cfg.perturb_cm = 20.0;
    cfg.scale = 0.1;
    let tmp = tempfile::Builder::new()
        .prefix("rigcal-sim-")
        .tempdir()
        .unwrap();
    let (mcap, gt) = (tmp.path().join("rt.mcap"), tmp.path().join("rt_gt.yaml"));
    let out = synthesize(&cfg, &mcap, &gt, &mut |_, _| {}).unwrap();
    let drive = Drive::open(&mcap).unwrap();
    assert!(drive.problems.is_empty(), "{:?}", drive.problems);
    // The trajectory is exactly the generated one.
    let samples = trajectories::generate(&TrajectoryConfig {
        kind: TrajectoryKind::Figure8,
        duration_secs: 1.0,
        rate_hz: 100.0,
        speed_mps: 8.0,
        seed: 11,
    });
    assert_eq!(drive.trajectory.len(), samples.len());
    for ((t, p), (t2, p2)) in samples.iter().zip(drive.trajectory.poses()) {
        assert_eq!(EPOCH_NANOS + t, t2);
        let (r, d) = p.difference(p2);
        assert!(r < 1e-12 && d < 1e-12);
    }
    // /tf_static carries the perturbed initial guess, exactly 2° and 20 cm from the truth.
    let truth = CalibrationFile::load_rig(&gt).unwrap();
    for (a, b) in truth.sensors.iter().zip(&out.ground_truth.sensors) {
        let (r, d) = a.vehicle_from_sensor.difference(b.vehicle_from_sensor);
        assert!(
            a.name == b.name && a.camera == b.camera && r < 1e-12 && d < 1e-12,
            "{}",
            a.name
        );
    }
    for s in &truth.sensors {
        let read = drive.rig.sensor(&s.name).unwrap();
        let asked = out.initial.sensor(&s.name).unwrap();
        let (r, d) = read
            .vehicle_from_sensor
            .difference(asked.vehicle_from_sensor);
        assert!(r < 1e-12 && d < 1e-12, "{}", s.name);
        let rot = so3::angle_rad(
            s.vehicle_from_sensor.rotation.conjugate() * read.vehicle_from_sensor.rotation,
        );
        let trans =
            (s.vehicle_from_sensor.translation - read.vehicle_from_sensor.translation).length();
        assert!(
            (rot.to_degrees() - 2.0).abs() < 1e-9 && (trans - 0.2).abs() < 1e-9,
            "{}: {rot} {trans}",
            s.name
        );
        assert_eq!(read.camera, s.camera, "{}", s.name);
    }
    assert_eq!(drive.rig.lidars().count(), 2);
    assert_eq!(drive.rig.cameras().count(), 6);
}

/// Mean distance (px) of LiDAR silhouettes to image edges in the stationary checkerboard scene,
/// with the camera extrinsic rotated by `error_deg` ([`SilhouetteCheck`]).
fn stationary_edge_distances(errors_deg: &[f64]) -> Vec<f64> {
    let check = SilhouetteCheck::stationary(3).unwrap();
    errors_deg
        .iter()
        .map(|e| {
            let px = check.pixels(*e).unwrap();
            assert!(px.len() > 200, "{} silhouette points in view", px.len());
            check.mean_distance(&px).unwrap()
        })
        .collect()
}

#[test]
fn lidar_silhouettes_lie_on_image_edges() {
    let d = stationary_edge_distances(&[0.0, 1.0]);
    eprintln!(
        "mean distance to edges: true {:.3} px, 1° off {:.3} px",
        d[0], d[1]
    );
    assert!(d[0] <= 1.0, "true extrinsics: {} px", d[0]);
    assert!(
        d[1] > 2.0 * d[0] && d[1] > 2.0,
        "1° error: {} px vs {} px",
        d[1],
        d[0]
    );
}

#[test]
fn urban_images_have_enough_corners() {
    let rig = SimRig::preset(RigPreset::Pandaset);
    let tcfg = TrajectoryConfig {
        kind: TrajectoryKind::Figure8,
        duration_secs: 2.0,
        rate_hz: 100.0,
        speed_mps: 8.0,
        seed: 7,
    };
    let traj = Trajectory::new(trajectories::generate(&tcfg));
    let world = World::build(
        SceneKind::Urban,
        &trajectories::path_polyline(&tcfg, 1.0),
        7,
    );
    for name in ["front_camera", "left_camera"] {
        let cam = rig.cameras.iter().find(|c| c.name == name).unwrap();
        assert_eq!((cam.intrinsics.width, cam.intrinsics.height), (1920, 1080));
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
        let corners = fast::fast9(&rigcal::features::grey::grey_u8(&img), 1920, 1080, 20);
        eprintln!("{name}: {} FAST corners", corners.len());
        assert!(
            corners.len() >= 1000,
            "{name}: {} FAST corners",
            corners.len()
        );
    }
}
