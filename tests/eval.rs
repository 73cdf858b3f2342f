#![allow(clippy::unwrap_used, clippy::expect_used)]
//! `rigcal eval` from known answers: a calibration equal to the reference reports zero, a known
//! perturbation reports exactly that perturbation (whichever side is the reference, and with
//! the whole rig moved by a common transform), the PandaSet ground truth JSON is accepted, and
//! on the real drive the LiDAR–LiDAR metric grows when a LiDAR is misaligned.

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::DVec3;
use rigcal::calib::dataset_json::load_reference;
use rigcal::calib::{CalibrationFile, Rig};
use rigcal::cli::eval::{EvalArgs, EvalReport, evaluate};
use rigcal::geometry::Rigid;
use rigcal::geometry::so3;
use rigcal::sim::rigs::{RigPreset, SimRig};
use tempfile::TempDir;

fn pandaset_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/pandaset-002")
}

/// A scratch folder, removed when dropped.
fn temp_dir(name: &str) -> TempDir {
    tempfile::Builder::new()
        .prefix(&format!("rigcal-eval-{name}-"))
        .tempdir()
        .unwrap()
}

fn save(rig: &Rig, path: &Path) {
    CalibrationFile::from_rig(rig).save(path).unwrap();
}

fn run(reference: &Path, calibration: &Path) -> EvalReport {
    let args = EvalArgs {
        ground_truth: reference.to_path_buf(),
        calibration: calibration.to_path_buf(),
        frames: 1,
        ..Default::default()
    };
    evaluate(&args, &mut |_, _| {}).unwrap()
}

fn sim_rig() -> Rig {
    SimRig::preset(RigPreset::Pandaset).to_rig()
}

#[test]
fn equal_calibrations_have_zero_error() {
    let tmp = temp_dir("zero");
    let dir = tmp.path();
    let gt = dir.join("gt.yaml");
    save(&sim_rig(), &gt);
    let report = run(&gt, &gt);
    assert_eq!(report.poses.len(), sim_rig().sensors.len());
    assert_eq!(report.root, sim_rig().lidars().next().unwrap().name);
    for e in &report.poses {
        assert!(e.rotation_deg < 1e-6 && e.translation_m < 1e-9, "{e:?}");
    }
    assert!(report.missing.is_empty());
}

#[test]
fn a_known_perturbation_is_reported_exactly_both_ways_and_under_a_common_offset() {
    let tmp = temp_dir("known");
    let dir = tmp.path();
    let reference = sim_rig();
    let root = reference.lidars().next().unwrap().name.clone();
    let camera = reference.cameras().nth(1).unwrap().name.clone();
    let lidar = reference.lidars().nth(1).unwrap().name.clone();
    // Perturb one camera by 1.5° and 7 cm, one LiDAR by 0.3° and 2 cm (in their own frames),
    // then move the whole rig by G: root alignment must take G out.
    let g = Rigid::new(
        so3::exp(DVec3::new(0.02, -0.01, 0.3)),
        DVec3::new(0.4, -1.0, 0.2),
    );
    let mut estimate = reference.clone();
    let axis = DVec3::new(1.0, 2.0, -2.0) / 3.0;
    for (name, deg, shift) in [
        (&camera, 1.5f64, DVec3::new(0.07, 0.0, 0.0)),
        (&lidar, 0.3, DVec3::new(0.0, 0.0, 0.02)),
    ] {
        let s = estimate.sensor_mut(name).unwrap();
        s.vehicle_from_sensor = s
            .vehicle_from_sensor
            .perturbed_right(axis * deg.to_radians(), shift);
    }
    for s in &mut estimate.sensors {
        s.vehicle_from_sensor = g * s.vehicle_from_sensor;
    }
    let (gt_path, est_path) = (dir.join("gt.yaml"), dir.join("est.yaml"));
    save(&reference, &gt_path);
    save(&estimate, &est_path);
    for (a, b) in [(&gt_path, &est_path), (&est_path, &gt_path)] {
        let report = run(a, b);
        assert_eq!(report.root, root);
        for e in &report.poses {
            let (deg, cm) = if e.sensor == camera {
                (1.5, 7.0)
            } else if e.sensor == lidar {
                (0.3, 2.0)
            } else {
                (0.0, 0.0)
            };
            assert!(
                (e.rotation_deg - deg).abs() < 1e-6 && (e.translation_m * 100.0 - cm).abs() < 1e-6,
                "{e:?}"
            );
        }
        let md = report.to_markdown();
        assert!(
            md.contains(&format!("| {camera} | 1.5000 | 7.00 |")),
            "{md}"
        );
    }
    // A root that is not in both files is refused by name.
    let args = EvalArgs {
        ground_truth: gt_path.clone(),
        calibration: est_path.clone(),
        root: Some("nope".into()),
        ..Default::default()
    };
    let e = evaluate(&args, &mut |_, _| {}).unwrap_err();
    assert!(e.to_string().contains("nope"), "{e}");
    // Frames per pair outside 1–1000 are refused before any work (not allocated for).
    for frames in [0, 1001, usize::MAX] {
        let args = EvalArgs {
            ground_truth: gt_path.clone(),
            calibration: est_path.clone(),
            frames,
            ..Default::default()
        };
        let e = evaluate(&args, &mut |_, _| {}).unwrap_err();
        assert!(e.to_string().contains("--frames must be 1–1000"), "{e}");
    }
}

#[test]
fn the_pandaset_ground_truth_json_is_accepted_and_misalignment_shows_in_the_data() {
    let json = pandaset_dir().join("ground_truth.json");
    let reference = load_reference(&json).unwrap();
    assert_eq!(reference.sensors.len(), 8);
    assert_eq!(reference.lidars().count(), 2);
    let tmp = temp_dir("pandaset");
    let dir = tmp.path();
    let same = dir.join("same.yaml");
    save(&reference, &same);
    let report = run(&json, &same);
    assert_eq!(report.root, "pandar64");
    assert!(report.poses.iter().all(|e| e.rotation_deg < 1e-6));
    // Misalign the PandarGT by 0.5° and 10 cm: the pose error says so, and so does the
    // point-to-plane error on the drive (the reference's value is the data's own floor).
    let mut moved = reference.clone();
    let s = moved.sensor_mut("pandar_gt").unwrap();
    s.vehicle_from_sensor = s.vehicle_from_sensor.perturbed_right(
        DVec3::new(0.0, 0.0, 0.5f64.to_radians()),
        DVec3::new(0.1, 0.0, 0.0),
    );
    let moved_path = dir.join("moved.yaml");
    save(&moved, &moved_path);
    let args = EvalArgs {
        ground_truth: json.clone(),
        calibration: moved_path,
        log: Some(pandaset_dir().join("pandaset-002.mcap")),
        frames: 2,
        ..Default::default()
    };
    let report = evaluate(&args, &mut |_, _| {}).unwrap();
    let gt_err = report
        .poses
        .iter()
        .find(|e| e.sensor == "pandar_gt")
        .unwrap();
    assert!((gt_err.rotation_deg - 0.5).abs() < 1e-6);
    assert_eq!(report.registration_cm.len(), 1);
    let m = &report.registration_cm[0];
    let (calibrated, truth) = (m.calibration.unwrap(), m.reference.unwrap());
    eprintln!("point-to-plane: moved {calibrated:.2} cm, reference {truth:.2} cm");
    assert!(truth < 5.0, "{m:?}");
    assert!(calibrated > truth + 1.0, "{m:?}");
    assert_eq!(report.edge_px.len(), 12);
    assert!(report.photo_inconsistency.is_empty());
}

#[test]
fn a_turned_camera_agrees_less_with_the_lidar_map_photometrically() {
    // The front camera turned by 1° about its vertical axis: its images agree less over the
    // LiDAR map than at the reference; the other cameras are the reference on both sides.
    let json = pandaset_dir().join("ground_truth.json");
    let mut turned = load_reference(&json).unwrap();
    let s = turned.sensor_mut("front_camera").unwrap();
    s.vehicle_from_sensor = s
        .vehicle_from_sensor
        .perturbed_right(DVec3::new(0.0, 1f64.to_radians(), 0.0), DVec3::ZERO);
    let tmp = temp_dir("photo");
    let dir = tmp.path();
    let path = dir.join("turned.yaml");
    save(&turned, &path);
    let args = EvalArgs {
        ground_truth: json,
        calibration: path,
        log: Some(pandaset_dir().join("pandaset-002.mcap")),
        frames: 1,
        photometric: true,
        ..Default::default()
    };
    let report = evaluate(&args, &mut |_, _| {}).unwrap();
    assert_eq!(report.photo_inconsistency.len(), 6);
    assert_eq!(report.photo_delay_ms.len(), 6);
    for m in &report.photo_inconsistency {
        let (c, r) = (m.calibration.unwrap(), m.reference.unwrap());
        if m.a == "front_camera" {
            assert!(c > r * 1.1, "{m:?}");
        } else {
            assert!((c - r).abs() < 1e-9 * r.max(1.0), "{m:?}");
        }
    }
    for m in &report.photo_delay_ms {
        let d = m.reference.unwrap();
        assert!((-60.0..=60.0).contains(&d) && d % 10.0 == 0.0, "{m:?}");
    }
    assert_eq!(report.photo_focal_scale.len(), 6);
    for m in &report.photo_focal_scale {
        let s = m.reference.unwrap();
        assert!((0.98..=1.02).contains(&s), "{m:?}");
    }
    let text = report.to_markdown();
    assert!(text.contains("photometric inconsistency") && text.contains("focal-length scale"));
}

#[test]
fn the_command_prints_tables_and_fails_with_the_file_named() {
    let tmp = temp_dir("cli");
    let dir = tmp.path();
    let gt = dir.join("gt.yaml");
    save(&sim_rig(), &gt);
    let json = dir.join("report.json");
    let out = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .args(["eval", "--ground-truth"])
        .arg(&gt)
        .arg("--calibration")
        .arg(&gt)
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("| sensor | rotation (°) | translation (cm) |"),
        "{text}"
    );
    let parsed: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert!(parsed["poses"].as_array().unwrap().len() > 2);
    // A log that holds none of the calibration's sensors is refused, not measured as empty.
    let other_log = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/mcap/ros2.mcap");
    let out = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .args(["eval", "--ground-truth"])
        .arg(&gt)
        .arg("--calibration")
        .arg(&gt)
        .arg(&other_log)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("has none of the sensors of"),
        "{err}"
    );
    let bad = dir.join("bad.yaml");
    std::fs::write(&bad, "rigcal_calibration: 1\nsensors: 7\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .args(["eval", "--ground-truth"])
        .arg(&gt)
        .arg("--calibration")
        .arg(&bad)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.yaml") && err.lines().count() == 1,
        "{err}"
    );
}

/// `--camera-readout-ms` reaches the photometric and edge-alignment metrics: with a rolling
/// shutter the images' rows are placed at their own times, so both change; without a log, or
/// malformed, it is refused by name.
#[test]
fn a_rolling_shutter_readout_reaches_the_photometric_and_edge_metrics() {
    let json = pandaset_dir().join("ground_truth.json");
    let mut rig = load_reference(&json).unwrap();
    // One camera and one LiDAR: one map and one camera to measure per readout.
    rig.sensors
        .retain(|s| s.name == "front_camera" || s.name == "pandar64");
    let tmp = temp_dir("readout");
    let path = tmp.path().join("front.yaml");
    save(&rig, &path);
    let args = |readout: Option<&str>, photometric: bool| EvalArgs {
        ground_truth: json.clone(),
        calibration: path.clone(),
        log: Some(pandaset_dir().join("pandaset-002.mcap")),
        frames: 1,
        photometric,
        camera_readout_ms: readout.map(String::from),
        ..Default::default()
    };
    let inconsistency = |readout| {
        let report = evaluate(&args(readout, true), &mut |_, _| {}).unwrap();
        assert_eq!(report.photo_inconsistency.len(), 1);
        report.photo_inconsistency[0].calibration.unwrap()
    };
    // Against the same middle time without rows (−10 ms for the whole image), so only the
    // rows' own times make the difference.
    let (global, rolling) = (
        inconsistency(Some("-10..-10")),
        inconsistency(Some("-30..10")),
    );
    assert!(
        (global - rolling).abs() > 1e-6 * global,
        "{global} {rolling}"
    );
    // The edge-alignment metric takes it too (without --photometric).
    let edge = |readout| {
        let report = evaluate(&args(readout, false), &mut |_, _| {}).unwrap();
        assert!(report.photo_inconsistency.is_empty());
        assert_eq!(report.edge_px.len(), 1);
        report.edge_px[0].calibration.unwrap()
    };
    let (global, rolling) = (edge(Some("-10..-10")), edge(Some("-30..10")));
    assert!(
        (global - rolling).abs() > 1e-6 * global,
        "{global} {rolling}"
    );
    let no_log = EvalArgs {
        log: None,
        ..args(Some("-30..10"), true)
    };
    let e = evaluate(&no_log, &mut |_, _| {}).unwrap_err();
    assert!(
        e.to_string()
            .contains("--camera-readout-ms applies to the metrics measured on a log: give one"),
        "{e}"
    );
    let e = evaluate(&args(Some("-30"), true), &mut |_, _| {}).unwrap_err();
    assert!(
        e.to_string()
            .contains("--camera-readout-ms '-30': expected FIRST..LAST"),
        "{e}"
    );
}
