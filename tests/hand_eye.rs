#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Hand-eye initialisation of cameras from their own motion, end to end on a simulated drive
//! that turns: from 10° and half a metre off, the front and back cameras's rotation comes back and its height
//! (which a level drive cannot observe) stays where it started, until the LiDAR map measures
//! it; on the real PandaSet drive,
//! which runs straight, the CLI keeps every camera and says why.

use std::path::PathBuf;
use std::process::Command;

use glam::DVec3;
use rigcal::calib::CalibrationFile;
use rigcal::classical::camera_motion::{fit_camera, fit_rig_cameras, lidar_map};
use rigcal::geometry::{Rigid, so3};
use rigcal::log::Drive;
use rigcal::sim::rigs::{RigPreset, SimRig};
use rigcal::sim::synth::{SynthConfig, synthesize};
use rigcal::sim::trajectories::TrajectoryKind;
use rigcal::sim::world::SceneKind;
use tempfile::TempDir;

/// The drive's folder (removed when dropped), the log and the ground truth.
fn drive() -> (TempDir, PathBuf, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix("rigcal-hand-eye-")
        .tempdir()
        .unwrap();
    let dir = tmp.path();
    let mut rig = SimRig::preset(RigPreset::Pandaset);
    rig.lidars.truncate(1);
    rig.cameras
        .retain(|c| c.name == "front_camera" || c.name == "back_camera");
    let mut cfg = SynthConfig::new(SceneKind::Urban, rig, TrajectoryKind::Figure8, 6.0, 5);
    cfg.scale = 0.5;
    cfg.camera_rate_hz = 4.0;
    let (log, gt) = (dir.join("turning.mcap"), dir.join("gt.yaml"));
    synthesize(&cfg, &log, &gt, &mut |_, _| {}).unwrap();
    (tmp, log, gt)
}

#[test]
fn cameras_ten_degrees_off_come_back_to_their_motion_and_keep_their_height() {
    let (_tmp, log, gt) = drive();
    let drive = Drive::open(&log).unwrap();
    let truth = CalibrationFile::load_rig(&gt).unwrap();
    for (k, name) in ["front_camera", "back_camera"].into_iter().enumerate() {
        for (axis, shift) in [
            (DVec3::new(1.0, -2.0, 0.5), DVec3::new(0.3, -0.2, 0.4)),
            (DVec3::new(-0.5, 0.4, 1.0), DVec3::new(-0.4, 0.3, -0.3)),
        ] {
            let t = truth.sensor(name).unwrap().vehicle_from_sensor;
            let start = Rigid::new(
                so3::exp(axis.normalize_or_zero() * 10f64.to_radians()) * t.rotation,
                t.translation + shift,
            );
            let mut rig = truth.clone();
            rig.sensor_mut(name).unwrap().vehicle_from_sensor = start;
            let fit = fit_camera(&drive, &rig, name, 24, &[], &|_, _, _| {}).unwrap();
            let found = fit.vehicle_from_camera;
            let (rot, _) = t.difference(found);
            eprintln!(
                "{name}: {:.3}° {:?} cm, {} of {} pairs, unobserved {:?}",
                rot.to_degrees(),
                (found.translation - t.translation) * 100.0,
                fit.pairs_used,
                fit.pairs_given,
                fit.unobserved
            );
            assert!(
                rot.to_degrees() < 0.5,
                "{name} (case {k}): {:.3}°",
                rot.to_degrees()
            );
            // Along the vehicle's x axis the turns observe it (to a few centimetres here).
            assert!((found.translation.x - t.translation.x).abs() < 0.1);
            assert!(fit.unobserved.contains(&"z"), "{:?}", fit.unobserved);
            assert!((found.translation.z - start.translation.z).abs() < 1e-3);
        }
    }

    // The whole rig at once (what the CLI and the studio run): both cameras moved, an unknown
    // name kept with its reason, every other sensor untouched.
    let mut start = truth.clone();
    for name in ["front_camera", "back_camera"] {
        let s = start.sensor_mut(name).unwrap();
        s.vehicle_from_sensor = Rigid::new(
            so3::exp(DVec3::new(0.3, 1.0, -0.2).normalize_or_zero() * 8f64.to_radians())
                * s.vehicle_from_sensor.rotation,
            s.vehicle_from_sensor.translation + DVec3::new(0.2, 0.1, -0.1),
        );
    }
    let names = ["front_camera", "back_camera", "no_such_camera"].map(String::from);
    let (fitted, outcomes) = fit_rig_cameras(&drive, &start, &names, 24, &[], None, &|_, _, _| {});
    assert_eq!(outcomes.len(), 3);
    for o in &outcomes[..2] {
        let fit = o.fit.as_ref().unwrap();
        let t = truth.sensor(&o.name).unwrap().vehicle_from_sensor;
        let got = fitted.sensor(&o.name).unwrap().vehicle_from_sensor;
        assert_eq!(got, fit.vehicle_from_camera);
        assert!(t.difference(got).0.to_degrees() < 0.5, "{}", o.summary());
        let s0 = start.sensor(&o.name).unwrap().vehicle_from_sensor;
        assert!((o.moved.0 - s0.difference(got).0).abs() < 1e-12);
        assert!(o.summary().contains("moved"), "{}", o.summary());
    }
    assert!(outcomes[2].fit.is_err());
    assert!(outcomes[2].summary().contains("no_such_camera kept"));
    // With the LiDAR map the translation comes back too, the height the drive cannot observe
    // included (the start is 20 cm forward, 10 cm left and 10 cm low).
    let map = lidar_map(&drive, &truth).unwrap();
    let (fitted, outcomes) = fit_rig_cameras(
        &drive,
        &start,
        &names[..2],
        24,
        &[],
        Some(&map),
        &|_, _, _| {},
    );
    for o in &outcomes {
        let t = truth.sensor(&o.name).unwrap().vehicle_from_sensor;
        let got = fitted.sensor(&o.name).unwrap().vehicle_from_sensor;
        let error = got.translation - t.translation;
        assert!(error.length() < 0.08, "{error} {}", o.summary());
        assert!(
            o.summary().contains("translation against the LiDAR map:"),
            "{}",
            o.summary()
        );
    }
    for s in &start.sensors {
        if !names.contains(&s.name) {
            assert_eq!(fitted.sensor(&s.name).unwrap(), s);
        }
    }
}

#[test]
fn on_a_straight_drive_the_cli_keeps_the_cameras_and_says_why() {
    let pandaset = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/pandaset-002/pandaset-002.mcap");
    let tmp = tempfile::Builder::new()
        .prefix("rigcal-hand-eye-cli-")
        .tempdir()
        .unwrap();
    let dir = tmp.path();
    let out = dir.join("out.yaml");
    let config = dir.join("rigcal.yaml");
    std::fs::write(&config, "cameras:\n  hand_eye: always\n").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .args(["calibrate"])
        .arg(&pandaset)
        .args(["--config"])
        .arg(&config)
        .args([
            "--quality",
            "fast",
            "--sensors",
            "front_camera",
            "--iterations",
            "1",
            "--segment",
            "0..4",
        ])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("plan: cameras: no hand-eye start: the drive turns")
            && err.contains("too little for the cameras' own motion to place them"),
        "{err}"
    );
    let before = Drive::open(&pandaset).unwrap().rig;
    let after = CalibrationFile::load(&out).unwrap().to_rig(&out).unwrap();
    let (r, t) = before
        .sensor("front_camera")
        .unwrap()
        .vehicle_from_sensor
        .difference(after.sensor("front_camera").unwrap().vehicle_from_sensor);
    assert!(r < 1e-12 && t < 1e-12);
}
