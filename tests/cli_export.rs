#![allow(clippy::unwrap_used, clippy::expect_used)]
//! `rigcal export` end to end: every format from the fixture rig, directories for the
//! per-camera formats, an export that cannot be made leaves an existing file untouched, bad
//! arguments fail with a one-line reason naming what is wrong. (tests/exports/check_exports.py
//! reads the same files with other tools' parsers; `.ci/run` runs it.)

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use rigcal::interop::ExportFormat;

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/exports/rig.yaml")
}

fn rigcal(args: &[&str], out: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .arg("export")
        .arg(fixture())
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rigcal-cli-export-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn every_format_is_written() {
    let dir = scratch("all");
    for format in ExportFormat::ALL {
        let out = dir.join(format.default_file_name());
        // Kalibr has no rational_polynomial model and KITTI no distortion: subsets.
        let mut args = vec!["--format", format.name()];
        match format {
            ExportFormat::Kalibr => args.extend([
                "--sensors",
                "front_camera,left_camera,back_camera,front_right_camera",
            ]),
            ExportFormat::Kitti => {
                args.extend(["--sensors", "front_camera,front_right_camera,lidar_top"])
            }
            _ => {}
        }
        let o = rigcal(&args, &out);
        assert!(
            o.status.success(),
            "{}: {}",
            format.name(),
            String::from_utf8_lossy(&o.stderr)
        );
        if format.is_directory() {
            let n = std::fs::read_dir(&out).unwrap().count();
            assert_eq!(n, 5, "{}: one file per camera", format.name());
        } else {
            let text = std::fs::read(&out).unwrap();
            assert!(text.len() > 100, "{}", format.name());
            // Every text format names a direction.
            if format != ExportFormat::Mcap {
                let text = String::from_utf8(text).unwrap();
                let named = [
                    "_from_",
                    "p_parent",
                    "Tr_velo_to_cam",
                    "vehicle_from_sensor",
                    "p_root",
                ];
                assert!(
                    named.iter().any(|n| text.contains(n)),
                    "{}: no direction named\n{text}",
                    format.name()
                );
            }
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_failed_export_leaves_the_existing_file_whole_and_errors_are_one_line() {
    let dir = scratch("errors");
    let out = dir.join("camchain.yaml");
    std::fs::write(&out, "previous contents\n").unwrap();
    // The whole rig cannot go to Kalibr (a rational_polynomial camera): refused, file untouched.
    let o = rigcal(&["--format", "kalibr"], &out);
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!o.status.success());
    assert!(
        err.contains("right_camera") && err.contains("rational_polynomial"),
        "{err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        "previous contents\n"
    );
    // No temporary file is left behind.
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);

    let cases: [(&[&str], PathBuf, &str); 5] = [
        (
            &["--format", "bogus"],
            dir.join("x"),
            "unknown export format 'bogus'",
        ),
        (
            &["--format", "urdf"],
            dir.join("missing/sub/rig.urdf"),
            "missing/sub/rig.urdf",
        ),
        (
            &["--format", "urdf", "--sensors", "nobody"],
            dir.join("r.urdf"),
            "'nobody' is not a sensor",
        ),
        (
            &["--format", "opencv", "--lidar", "front_camera"],
            dir.join("cv"),
            "not a lidar",
        ),
        (&["--format", "opencv"], out.clone(), "is a file"),
    ];
    for (args, path, expected) in cases {
        let o = rigcal(args, &path);
        let err = String::from_utf8(o.stderr).unwrap();
        assert!(!o.status.success(), "{args:?}");
        assert!(err.contains(expected), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    }
    let o = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .args([
            "export",
            "/nonexistent/calib.yaml",
            "--format",
            "urdf",
            "--out",
        ])
        .arg(dir.join("y.urdf"))
        .output()
        .unwrap();
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(
        !o.status.success() && err.contains("/nonexistent/calib.yaml"),
        "{err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_export_is_an_initial_guess_for_calibrate() {
    // The exported URDF of a rig, given to `rigcal calibrate --init`, is what the run starts
    // from: with 0 steps of the edge method the output is the URDF's rig.
    let pandaset = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/pandaset-002/pandaset-002.mcap");
    let drive = rigcal::log::Drive::open(&pandaset).unwrap();
    let mut rig = drive.rig.clone();
    let gt = rig.sensor_mut("pandar_gt").unwrap();
    gt.vehicle_from_sensor.translation.x += 0.3;
    let moved = gt.vehicle_from_sensor;
    let dir = scratch("init");
    let urdf = dir.join("rig.urdf");
    let doc = rigcal::calib::CalibrationFile::from_rig(&rig);
    let e = rigcal::interop::export(&doc, ExportFormat::Urdf, &Default::default()).unwrap();
    rigcal::interop::write(&e, &urdf).unwrap();
    let out = dir.join("out.yaml");
    let o = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .arg("calibrate")
        .arg(&pandaset)
        .args([
            "--method",
            "edge",
            "--sensors",
            "front_camera",
            "--iterations",
            "0",
        ])
        .arg("--init")
        .arg(&urdf)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got = rigcal::calib::CalibrationFile::load_rig(&out).unwrap();
    let (r, t) = got
        .sensor("pandar_gt")
        .unwrap()
        .vehicle_from_sensor
        .difference(moved);
    assert!(r < 1e-9 && t < 1e-9, "{r} {t}");
    std::fs::remove_dir_all(&dir).unwrap();
}
