#![allow(clippy::unwrap_used, clippy::expect_used)]
//! A calibration killed at any moment leaves a complete, valid output: the previous one or a
//! new one, never a partial file. `rigcal calibrate` writes its output before the first step,
//! every 30 s and at the end, each time to a temporary file renamed over the output; this test
//! SIGKILLs the child at moments spread over a whole run (before its first write, between its
//! writes, during its last) and reads the output back each time.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use rigcal::calib::CalibrationFile;
use rigcal::log::Drive;

fn pandaset() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/pandaset-002/pandaset-002.mcap")
}

/// A short ICP run of one LiDAR pair: seconds, with a write at its start and at its end.
fn calibrate(out: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rigcal"));
    c.arg("calibrate")
        .arg(pandaset())
        .args([
            "--method",
            "icp",
            "--sensors",
            "pandar_gt",
            "--segment",
            "0..3",
        ])
        .arg("--out")
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    c
}

/// The output's status, after checking it is a whole calibration of the drive's rig.
fn status_of(out: &Path, sensors: usize) -> String {
    let doc = CalibrationFile::load(out)
        .unwrap_or_else(|e| panic!("{}: not a valid calibration: {e}", out.display()));
    let rig = doc.to_rig(out).unwrap();
    assert_eq!(rig.sensors.len(), sensors, "a partial rig");
    doc.provenance
        .get("status")
        .and_then(|v| v.as_str())
        .unwrap_or("previous")
        .to_owned()
}

#[test]
fn a_killed_calibration_always_leaves_a_whole_output() {
    let drive = Drive::open(&pandaset()).unwrap();
    let sensors = drive.rig.sensors.len();
    let dir = std::env::temp_dir().join(format!("rigcal-kill-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("calib.yaml");

    // How long a whole run takes here.
    let started = Instant::now();
    assert!(calibrate(&out).status().unwrap().success());
    let whole = started.elapsed();
    assert_eq!(status_of(&out, sensors), "complete");

    const KILLS: u32 = 20;
    let mut seen = std::collections::BTreeMap::<String, u32>::new();
    for k in 0..KILLS {
        // The previous output: a calibration without a status, so a kill before the run's
        // first write is told apart.
        CalibrationFile::from_rig(&drive.rig).save(&out).unwrap();
        let mut child = calibrate(&out).spawn().unwrap();
        // Moments spread over the whole run, a little past its end too.
        std::thread::sleep(whole.mul_f64(1.1 * f64::from(k) / f64::from(KILLS)));
        child.kill().unwrap();
        child.wait().unwrap();
        let status = status_of(&out, sensors);
        let kind = status.split(':').next().unwrap_or_default().to_owned();
        assert!(
            ["previous", "running", "complete"].contains(&kind.as_str()),
            "kill {k}: status {status}"
        );
        *seen.entry(kind).or_default() += 1;
    }
    eprintln!("{KILLS} kills over {whole:?}: outputs seen {seen:?}");
    // The kills landed before and after the run's writes, not all on one side.
    assert!(seen.len() >= 2, "{seen:?}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_finished_run_leaves_no_temporary_file_beside_its_output() {
    let dir = std::env::temp_dir().join(format!("rigcal-kill-clean-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("calib.yaml");
    assert!(calibrate(&out).status().unwrap().success());
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name())
        .collect();
    assert_eq!(left.len(), 1, "{left:?}");
    let _ = std::fs::remove_dir_all(dir);
}
