#![allow(clippy::unwrap_used, clippy::expect_used)]
//! UniCal's LiDAR stage as a runner `Calibrator` on the real PandaSet drive: it prepares from
//! the drive, steps with finite losses, moves only LiDAR extrinsics, ends at its step budget,
//! and a segment without sweeps is a clear error; on the real KITTI-360 sample, its scene
//! holds a sweep near every training image.

use std::path::PathBuf;

use rigcal::log::Drive;
use rigcal::optim::runner::Calibrator;
use rigcal::unical::calibrator::UnicalLidarStage;
use rigcal::unical::depth_calib::DepthCalibConfig;

fn pandaset() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/pandaset-002/pandaset-002.mcap")
}

#[test]
fn the_lidar_stage_runs_as_a_calibrator_on_the_real_drive_with_a_frozen_root() {
    let drive = Drive::open(&pandaset()).unwrap();
    let root = drive.rig.lidars().next().unwrap().name.clone();
    let config = DepthCalibConfig {
        rays_per_sensor: 256,
        iterations: 3,
        pose_warmup: 0,
        pose_ramp: 0,
        geometry_init_steps: 0,
        frozen_sensor: Some(root.clone()),
        ..DepthCalibConfig::default()
    };
    // Two rounds of three iterations: done only at the end of the second.
    let mut stage = UnicalLidarStage::from_drive(&drive, &drive.rig, 2, &[], config)
        .unwrap()
        .in_rounds(2);
    assert_eq!(stage.max_steps(), 6);
    let mut last = None;
    for k in 0..6 {
        let r = stage.step();
        assert!(r.losses.iter().all(|(_, v)| v.is_finite()), "{r:?}");
        assert_eq!(r.done, k == 5);
        assert_eq!(stage.calibration().iteration, k % 3 + 1);
        last = Some(r);
    }
    let names: Vec<String> = last.unwrap().losses.into_iter().map(|(n, _)| n).collect();
    for term in ["depth loss", "intensity loss", "regulariser"] {
        assert!(names.iter().any(|n| n == term), "{term} missing: {names:?}");
    }
    let now = stage.current();
    let mut lidar_moved = false;
    for s in &drive.rig.sensors {
        let t = now.sensor(&s.name).unwrap().vehicle_from_sensor;
        let (rot, trans) = s.vehicle_from_sensor.difference(t);
        if s.camera.is_some() || s.name == root {
            assert!(rot + trans < 1e-12, "{} moved", s.name);
        } else {
            lidar_moved |= rot + trans > 1e-9;
        }
    }
    assert!(lidar_moved, "no LiDAR extrinsic changed");
    let (_, t1) = drive.trajectory.time_range_nanos().unwrap();
    let e = UnicalLidarStage::from_drive(
        &drive,
        &drive.rig,
        2,
        &[(t1 + 1_000_000_000, t1 + 2_000_000_000)],
        DepthCalibConfig::default(),
    )
    .err()
    .unwrap();
    assert!(e.to_string().contains("segments"), "{e}");
}

/// The result is every pose averaged over the run's latest iterates: here the last two of four
/// (a half of the run), so each LiDAR's reported translation is the mean of the last two
/// iterates' and its rotation their midpoint; with averaging off it is the last iterate.
#[test]
fn the_result_averages_the_latest_iterates() {
    let drive = Drive::open(&pandaset()).unwrap();
    let root = drive.rig.lidars().next().unwrap().name.clone();
    let config = DepthCalibConfig {
        rays_per_sensor: 256,
        iterations: 4,
        pose_warmup: 0,
        pose_ramp: 0,
        geometry_init_steps: 0,
        frozen_sensor: Some(root.clone()),
        pose_average_fraction: 0.5,
        ..DepthCalibConfig::default()
    };
    let mut stage =
        UnicalLidarStage::from_drive(&drive, &drive.rig, 2, &[], config.clone()).unwrap();
    let mut iterates = Vec::new();
    for _ in 0..4 {
        stage.step();
        iterates.push(stage.current());
    }
    let best = stage.best();
    let moving = drive
        .rig
        .lidars()
        .find(|l| l.name != root)
        .unwrap()
        .name
        .clone();
    let pose = |rig: &rigcal::calib::Rig| rig.sensor(&moving).unwrap().vehicle_from_sensor;
    let (a, b, m) = (pose(&iterates[2]), pose(&iterates[3]), pose(&best));
    let (step_rad, step_m) = a.difference(b);
    assert!(step_rad > 1e-7 && step_m > 1e-7, "the LiDAR did not move");
    assert!((m.translation - (a.translation + b.translation) / 2.0).length() < 1e-12);
    let (to_a, _) = m.difference(a);
    let (to_b, _) = m.difference(b);
    assert!((to_a - step_rad / 2.0).abs() < 1e-9 && (to_b - step_rad / 2.0).abs() < 1e-9);
    // The live pose is the last iterate, untouched by the averaging.
    assert!(pose(&stage.current()).difference(b).0 < 1e-15);

    let off = DepthCalibConfig {
        pose_average_fraction: 0.0,
        ..config
    };
    let mut stage = UnicalLidarStage::from_drive(&drive, &drive.rig, 2, &[], off).unwrap();
    for _ in 0..4 {
        stage.step();
    }
    let (rot, trans) = pose(&stage.best()).difference(pose(&stage.current()));
    assert!(rot + trans < 1e-15);
}

/// With cameras: every camera's images are loaded (downscaled), the colour loss is reported and
/// finite, and camera extrinsics now move too; a bad scale is a clear error.
#[test]
fn cameras_join_the_stage_through_the_colour_term() {
    let drive = Drive::open(&pandaset()).unwrap();
    let config = DepthCalibConfig {
        rays_per_sensor: 128,
        rays_per_camera: 64,
        iterations: 2,
        pose_warmup: 0,
        pose_ramp: 0,
        geometry_init_steps: 0,
        ..DepthCalibConfig::default()
    };
    let mut stage = UnicalLidarStage::from_drive(&drive, &drive.rig, 1, &[], config.clone())
        .unwrap()
        .with_cameras(&drive, 1, &[], 0.0625)
        .unwrap();
    assert!(stage.name().contains("camera"), "{}", stage.name());
    for _ in 0..2 {
        let r = stage.step();
        assert!(r.losses.iter().all(|(_, v)| v.is_finite()), "{r:?}");
        let colour = r.losses.iter().find(|(n, _)| n == "colour loss").unwrap().1;
        assert!(colour > 0.0 && colour < 3.0, "{colour}");
    }
    let now = stage.current();
    let cameras_moved = drive
        .rig
        .sensors
        .iter()
        .filter(|s| s.camera.is_some())
        .filter(|s| {
            let (rot, trans) = s
                .vehicle_from_sensor
                .difference(now.sensor(&s.name).unwrap().vehicle_from_sensor);
            rot + trans > 1e-9
        })
        .count();
    assert_eq!(cameras_moved, 6);
    // Which sensors move in two steps of a stage with `config`.
    let moved = |config: DepthCalibConfig| {
        let mut stage = UnicalLidarStage::from_drive(&drive, &drive.rig, 1, &[], config)
            .unwrap()
            .with_cameras(&drive, 1, &[], 0.0625)
            .unwrap();
        for _ in 0..2 {
            stage.step();
        }
        let now = stage.current();
        drive
            .rig
            .sensors
            .iter()
            .map(|s| {
                let (rot, trans) = s
                    .vehicle_from_sensor
                    .difference(now.sensor(&s.name).unwrap().vehicle_from_sensor);
                (s.name.clone(), s.camera.is_some(), rot + trans > 1e-9)
            })
            .collect::<Vec<_>>()
    };
    // Held sensors (those a user did not ask to calibrate) stay while the others move.
    let held = ["front_camera".to_string(), "pandar_gt".to_string()];
    for (name, _, moved) in moved(DepthCalibConfig {
        held_sensors: held.to_vec(),
        ..config.clone()
    }) {
        assert_eq!(moved, !held.contains(&name), "{name}");
    }
    // The camera pose rate is the cameras' own: at 0 they stay while the LiDARs move.
    for (name, camera, moved) in moved(DepthCalibConfig {
        lr_camera_pose: 0.0,
        ..config.clone()
    }) {
        assert_eq!(moved, !camera, "{name}");
    }
    let e = UnicalLidarStage::from_drive(&drive, &drive.rig, 1, &[], config)
        .unwrap()
        .with_cameras(&drive, 1, &[], 1.5)
        .err()
        .unwrap();
    assert!(e.to_string().contains("scale"), "{e}");
}

/// The real KITTI-360 sample: twenty frames 20–220 m apart, where four sweeps spread over the
/// drive leave most of the cameras' training images looking at places no sweep saw.
#[test]
fn the_scene_holds_a_sweep_near_every_image_the_cameras_train_on() {
    use rigcal::unical::calibrator::training_stamps;
    let log = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/kitti360-sample/kitti360-20-frames.mcap");
    let drive = Drive::open(&log).unwrap();
    let stamps = training_stamps(&drive, &drive.rig, 16, &[]);
    assert_eq!(stamps.len(), 32, "16 images of each of the two cameras");
    let config = DepthCalibConfig {
        geometry_init_steps: 0,
        ..DepthCalibConfig::default()
    };
    let stage =
        UnicalLidarStage::from_drive_covering(&drive, &drive.rig, 4, &[], &stamps, config.clone())
            .unwrap();
    let lidar = &stage.calibration().lidars[0];
    let stream = drive.stream(&lidar.name).unwrap();
    let nearest = |t: i64| {
        stream
            .frames
            .iter()
            .map(|f| f.stamp_nanos)
            .min_by_key(|s| (s - t).abs())
            .unwrap()
    };
    let scene: Vec<i64> = lidar.sweeps.iter().map(|s| s.stamp_nanos).collect();
    let at = |t: i64| drive.trajectory.world_from_vehicle(t).unwrap().translation;
    for &t in &stamps {
        let within = scene
            .iter()
            .any(|&s| at(s).distance(at(t)) <= rigcal::unical::scene_sweeps::COVER_M);
        assert!(
            within || scene.contains(&nearest(t)),
            "no sweep near the image at {t}: {scene:?}"
        );
    }
    // Without the images, the four of the spread.
    let spread = UnicalLidarStage::from_drive(&drive, &drive.rig, 4, &[], config).unwrap();
    assert_eq!(spread.calibration().lidars[0].sweeps.len(), 4);
    assert!(scene.len() > 4);
}
