#![allow(clippy::unwrap_used, clippy::expect_used)]
//! `rigcal calibrate` end to end on the real PandaSet drive: a camera rotated in the initial
//! guess comes back (edge method), the other sensors keep their extrinsics, the output is a
//! native calibration file with provenance; bad arguments fail with a one-line reason; UniCal
//! with `--lidar-icp` registers the LiDARs first and holds them, and holds what `--sensors`
//! leaves out.

use std::path::PathBuf;
use std::process::Command;

use glam::DVec3;
use rigcal::calib::CalibrationFile;
use rigcal::geometry::{Rigid, so3};
use rigcal::log::Drive;

fn pandaset() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/pandaset-002/pandaset-002.mcap")
}

#[test]
fn calibrate_recovers_a_rotated_camera_and_writes_the_native_file() {
    let drive = Drive::open(&pandaset()).unwrap();
    let dir = std::env::temp_dir().join(format!("rigcal-cli-cal-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut init = drive.rig.clone();
    let gt = init.sensor("front_camera").unwrap().vehicle_from_sensor;
    init.sensor_mut("front_camera").unwrap().vehicle_from_sensor =
        gt.perturbed_right(DVec3::new(0.5, -0.6, 0.4) * 1f64.to_radians(), DVec3::ZERO);
    let init_path = dir.join("init.yaml");
    CalibrationFile::from_rig(&init).save(&init_path).unwrap();
    let out = dir.join("out.yaml");
    let o = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .args(["calibrate"])
        .arg(pandaset())
        .args([
            "--method",
            "edge",
            "--sensors",
            "front_camera",
            "--segment",
            "0..8",
        ])
        .arg("--init")
        .arg(&init_path)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    // The run says when the extrinsics first changed.
    assert!(err.contains("first extrinsic update: step "), "{err}");
    let doc = CalibrationFile::load(&out).unwrap();
    assert!(doc.provenance.contains_key("method") && doc.provenance.contains_key("input"));
    // The provenance says what was asked (to repeat the run) and when.
    let config = doc.provenance.get("config").and_then(|v| v.as_mapping());
    let get = |key: &str| config.and_then(|c| c.get(key)).and_then(|v| v.as_str());
    assert_eq!(get("method"), Some("edge"), "{config:?}");
    assert_eq!(get("sensors"), Some("front_camera"), "{config:?}");
    let date = doc.provenance.get("date").and_then(|v| v.as_str()).unwrap();
    assert!(
        date.len() == 20 && date.ends_with('Z') && date.starts_with("20"),
        "{date}"
    );
    let input = doc
        .provenance
        .get("input")
        .and_then(|v| v.as_str())
        .unwrap();
    assert!(std::path::Path::new(input).is_absolute(), "{input}");
    assert_eq!(
        doc.provenance.get("status").and_then(|v| v.as_str()),
        Some("complete")
    );
    let rig = doc.to_rig(&out).unwrap();
    let (before, _) = gt.difference(init.sensor("front_camera").unwrap().vehicle_from_sensor);
    let (after, _) = gt.difference(rig.sensor("front_camera").unwrap().vehicle_from_sensor);
    eprintln!(
        "front_camera: {:.2}° -> {:.2}°",
        before.to_degrees(),
        after.to_degrees()
    );
    assert!(after.to_degrees() < 0.5, "{}", after.to_degrees());
    for s in &init.sensors {
        if s.name != "front_camera" {
            let (r, t) = s
                .vehicle_from_sensor
                .difference(rig.sensor(&s.name).unwrap().vehicle_from_sensor);
            assert!(r < 1e-12 && t < 1e-12, "{} moved", s.name);
        }
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn bad_arguments_fail_with_one_line() {
    let run = |extra: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_rigcal"))
            .arg("calibrate")
            .arg(pandaset())
            .args(extra)
            .args(["--out", "/nonexistent-dir/out.yaml"])
            .output()
            .unwrap();
        (
            o.status.success(),
            String::from_utf8_lossy(&o.stderr).to_string(),
        )
    };
    let (ok, err) = run(&["--method", "nope"]);
    assert!(!ok && err.contains("unknown --method 'nope'"), "{err}");
    let (ok, err) = run(&["--method", "pose-graph", "--root", "front_camera"]);
    assert!(
        !ok && err.contains("'front_camera' is not a LiDAR"),
        "{err}"
    );
    let (ok, err) = run(&["--method", "icp", "--root", "front_camera"]);
    assert!(
        !ok && err.contains("--root: 'front_camera' is not a LiDAR"),
        "{err}"
    );
    let (ok, err) = run(&["--method", "edge", "--sensors", "nope"]);
    assert!(!ok && err.contains("'nope'"), "{err}");
    // Options another method would ignore, and sensors it does not calibrate.
    let (ok, err) = run(&["--method", "icp", "--quality", "fast", "--budget", "5m"]);
    assert!(
        !ok && err.contains("--quality, --budget apply to the pipeline and --method unical only"),
        "{err}"
    );
    let (ok, err) = run(&["--budget", "soon"]);
    assert!(
        !ok && err.contains("'soon' for '--budget <DURATION>'")
            && err.contains("expected a duration"),
        "{err}"
    );
    let (ok, err) = run(&["--quality", "best"]);
    assert!(
        !ok && err.contains("'--quality <QUALITY>': unknown quality 'best'"),
        "{err}"
    );
    // UniCal's settings are the configuration's: a bad one is named by its key.
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("rigcal.yaml");
    std::fs::write(&config, "unical:\n  lr_camera_pose: 0\n").unwrap();
    let (ok, err) = run(&["--config", config.to_str().unwrap()]);
    assert!(
        !ok && err.contains("unical.lr_camera_pose: expected a rate above 0"),
        "{err}"
    );
    // Options that left the command line for the configuration are unknown to it.
    let (ok, err) = run(&["--method", "unical", "--camera-frames", "8"]);
    assert!(
        !ok && err.contains("--camera-frames is no longer an option of calibrate: its setting is cameras.images_per_camera"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    let (ok, err) = run(&["--method", "UniCal"]);
    assert!(!ok && err.contains("unknown --method 'UniCal'"), "{err}");
    let (ok, err) = run(&["--method", "pose-graph", "--iterations", "5"]);
    assert!(!ok && err.contains("runs until it converges"), "{err}");
    let (ok, err) = run(&["--method", "icp", "--sensors", "front_camera"]);
    assert!(
        !ok && err.contains("calibrates LiDARs; 'front_camera'"),
        "{err}"
    );
    let (ok, err) = run(&["--method", "edge", "--sensors", "pandar_gt"]);
    assert!(
        !ok && err.contains("calibrates cameras; 'pandar_gt'"),
        "{err}"
    );
    let (ok, err) = run(&["--method", "unical", "--root", "roof"]);
    assert!(!ok && err.contains("--root: 'roof'"), "{err}");
    let (ok, err) = run(&["--method", "unical", "--iterations", "0"]);
    assert!(!ok && err.contains("--iterations 0"), "{err}");
    // A segment past the log's end names the log's span.
    let (ok, err) = run(&["--method", "edge", "--segment", "100..200"]);
    assert!(
        !ok && err.contains("lies outside") && err.contains("which spans 0.."),
        "{err}"
    );
    // A valid run with an unwritable output fails before calibrating, naming the path.
    let (ok, err) = run(&["--method", "edge", "--iterations", "1"]);
    assert!(!ok && err.contains("/nonexistent-dir/out.yaml"), "{err}");
    // Perturbations beyond a half turn or 10 m are refused, not allocated for.
    let (ok, err) = run(&["--method", "unical", "--perturb-cm", "1e6"]);
    assert!(
        !ok && err.contains("--perturb-cm") && err.contains("[0, 1000]"),
        "{err}"
    );
    let (ok, err) = run(&["--method", "unical", "--perturb-deg", "1e160"]);
    assert!(
        !ok && err.contains("--perturb-deg") && err.contains("[0, 180]"),
        "{err}"
    );
    // A device as the output is refused: the file is written at the start and replaced.
    let o = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .arg("calibrate")
        .arg(pandaset())
        .args([
            "--method",
            "edge",
            "--iterations",
            "1",
            "--out",
            "/dev/null",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("is not a regular file"),
        "{err}"
    );
    // An output that is the log itself (here through a link) is refused before anything is
    // written; a copy of a small fixture stands in for the log.
    let dir = std::env::temp_dir().join(format!("rigcal-cli-self-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("drive.mcap");
    let fixture =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/mcap/ros2.mcap");
    std::fs::copy(&fixture, &log).unwrap();
    let link = dir.join("link.mcap");
    std::os::unix::fs::symlink(&log, &link).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .arg("calibrate")
        .arg(&log)
        .args(["--method", "edge", "--iterations", "1", "--out"])
        .arg(&link)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("is the log itself"),
        "{err}"
    );
    assert_eq!(
        std::fs::read(&log).unwrap(),
        std::fs::read(&fixture).unwrap()
    );
    std::fs::remove_dir_all(&dir).unwrap();
    let (ok, err) = run(&["--method", "edge", "--segment", "5..1"]);
    assert!(!ok && err.contains("--segment"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}

#[test]
fn the_pipeline_registers_the_lidars_first_and_holds_them() {
    let drive = Drive::open(&pandaset()).unwrap();
    let dir = std::env::temp_dir().join(format!("rigcal-cli-icp-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let truth = drive.rig.clone();
    let mut init = truth.clone();
    let s = init.sensor_mut("pandar_gt").unwrap();
    let t = s.vehicle_from_sensor;
    s.vehicle_from_sensor = Rigid::new(
        so3::exp(DVec3::new(0.0, 0.6, 0.8) * 1f64.to_radians()) * t.rotation,
        t.translation + DVec3::new(0.06, -0.08, 0.0),
    );
    let init_path = dir.join("init.yaml");
    CalibrationFile::from_rig(&init).save(&init_path).unwrap();
    let out = dir.join("out.yaml");
    let o = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .args(["calibrate"])
        .arg(pandaset())
        .args([
            "--sensors",
            "pandar64,pandar_gt",
            "--iterations",
            "2",
            "--segment",
            "0..4",
        ])
        .arg("--init")
        .arg(&init_path)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("lidar icp: pandar_gt moved"), "{err}");
    // PandaSet's Pandar64 is its vehicle frame: it is not fitted to the trajectory, and the
    // plan says why.
    assert!(
        err.contains(
            "plan: lidars: pandar64 (the reference) stays: its frame is the vehicle frame"
        ),
        "{err}"
    );
    // The report rates the registered LiDAR with its check before and after.
    assert!(err.contains("point-to-plane against pandar64"), "{err}");
    let rig = CalibrationFile::load(&out).unwrap().to_rig(&out).unwrap();
    let pose = |rig: &rigcal::calib::Rig, name: &str| rig.sensor(name).unwrap().vehicle_from_sensor;
    // The other one registered to it (the reference is good to about 0.08° / 2.6 cm, the
    // data's README) ...
    let relative =
        |rig: &rigcal::calib::Rig| pose(rig, "pandar64").inverse() * pose(rig, "pandar_gt");
    let (rot, trans) = relative(&truth).difference(relative(&rig));
    assert!(
        rot.to_degrees() < 0.2 && trans < 0.04,
        "{:.3}° {:.1} cm",
        rot.to_degrees(),
        trans * 100.0
    );
    // ... and nothing else moved: the cameras were not asked for.
    for s in &init.sensors {
        if s.name != "pandar_gt" {
            let (r, t) = s
                .vehicle_from_sensor
                .difference(rig.sensor(&s.name).unwrap().vehicle_from_sensor);
            assert!(r < 1e-12 && t < 1e-12, "{} moved", s.name);
        }
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// `calibrate --help` is short and ends with example commands, every option of which the
/// command knows.
#[test]
fn calibrate_help_is_short_and_its_examples_use_real_options() {
    let o = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .args(["calibrate", "--help"])
        .output()
        .unwrap();
    assert!(o.status.success());
    let help = String::from_utf8_lossy(&o.stdout);
    let (options, examples) = help.split_once("Examples:").expect("an Examples section");
    let listed = options
        .lines()
        .filter(|l| l.trim_start().starts_with("--"))
        .count();
    assert!(listed <= 16, "{listed} options (with --help):\n{options}");
    let mut checked = 0;
    for line in examples
        .lines()
        .filter(|l| l.contains("rigcal calibrate") || l.trim_start().starts_with("--"))
    {
        for flag in line.split_whitespace().filter(|w| w.starts_with("--")) {
            assert!(
                options.contains(&format!("{flag} ")) || options.contains(&format!("{flag}\n")),
                "the example's {flag} is not an option of calibrate"
            );
            checked += 1;
        }
    }
    assert!(
        checked >= 8,
        "only {checked} options checked in:\n{examples}"
    );
}

/// An initial guess that gives only some of the log's sensors says which ones keep the log's
/// extrinsics instead of applying it silently.
#[test]
fn an_initial_guess_for_some_sensors_names_the_ones_it_leaves() {
    let drive = Drive::open(&pandaset()).unwrap();
    let dir = std::env::temp_dir().join(format!("rigcal-cli-partial-init-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut init = drive.rig.clone();
    init.sensors.retain(|s| s.name != "left_camera");
    let init_path = dir.join("init.yaml");
    CalibrationFile::from_rig(&init).save(&init_path).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .arg("calibrate")
        .arg(pandaset())
        .args(["--method", "edge", "--iterations", "0", "--init"])
        .arg(&init_path)
        .arg("--out")
        .arg(dir.join("out.yaml"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("gives 7 of 8 sensors; from the log's /tf_static: left_camera"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
