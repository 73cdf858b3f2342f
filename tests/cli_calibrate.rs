#![allow(clippy::unwrap_used, clippy::expect_used)]
//! `rigcal calibrate` end to end on the real PandaSet drive: a camera rotated in the initial
//! guess comes back (edge method), the other sensors keep their extrinsics, the output is a
//! native calibration file with provenance; bad arguments fail with a one-line reason.

use std::path::PathBuf;
use std::process::Command;

use glam::DVec3;
use rigcal::calib::CalibrationFile;
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
    let status = Command::new(env!("CARGO_BIN_EXE_rigcal"))
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
        .status()
        .unwrap();
    assert!(status.success());
    let doc = CalibrationFile::load(&out).unwrap();
    assert!(doc.provenance.contains_key("method") && doc.provenance.contains_key("input"));
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
    let (ok, err) = run(&["--method", "edge", "--sensors", "nope"]);
    assert!(!ok && err.contains("'nope'"), "{err}");
    let (ok, err) = run(&["--method", "unical", "--root", "roof"]);
    assert!(!ok && err.contains("--root: 'roof'"), "{err}");
    // A valid run with an unwritable output fails before calibrating, naming the path.
    let (ok, err) = run(&["--method", "edge", "--iterations", "1"]);
    assert!(!ok && err.contains("/nonexistent-dir/out.yaml"), "{err}");
    let (ok, err) = run(&["--method", "edge", "--segment", "5..1"]);
    assert!(!ok && err.contains("--segment"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}
