#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Pairwise calibration unified by a pose graph (`--method pose-graph`) on the simulator's
//! checkerboard scene: ICP between the two LiDARs and checkerboards between every camera and
//! every LiDAR that sees its boards; from a seeded 2° / 20 cm start every sensor ends within
//! the pairwise methods' accuracy after aligning the reference LiDAR, the graph agrees with its
//! edges, and the CLI writes the native file.

mod common;

use std::path::PathBuf;
use std::process::Command;

use common::named;

use rigcal::calib::CalibrationFile;
use rigcal::classical::pose_graph_calibrator::{CameraPairs, PoseGraphCalibrator, PoseGraphConfig};
use rigcal::geometry::rig_errors;
use rigcal::log::Drive;
use rigcal::optim::runner::Calibrator;
use tempfile::TempDir;

fn drive(seed: u64) -> (TempDir, PathBuf, PathBuf) {
    common::checkerboard_drive("posegraph", seed)
}

#[test]
fn the_graph_unifies_icp_and_checkerboard_edges_into_one_rig() {
    let (_tmp, log, gt) = drive(3);
    let drive = Drive::open(&log).unwrap();
    let truth = CalibrationFile::load(&gt).unwrap().to_rig(&gt).unwrap();
    let start = drive.rig.clone();
    let config = PoseGraphConfig {
        camera_pairs: CameraPairs::Target,
        ..PoseGraphConfig::default()
    };
    let mut cal = PoseGraphCalibrator::from_drive(&drive, &start, "pandar64", &[], config).unwrap();
    for s in cal.skipped() {
        eprintln!("skipped {s}");
    }
    let mut steps = 0;
    while steps < cal.max_steps() {
        steps += 1;
        if cal.step().done {
            break;
        }
    }
    let result = cal.best();
    eprintln!(
        "steps {steps}/{} graph iterations {} converged {} cost {}",
        cal.max_steps(),
        cal.graph().iterations,
        cal.graph().converged,
        cal.graph().cost()
    );
    let edges = cal.edges();
    assert!(
        edges
            .iter()
            .any(|e| e.source == "icp" && e.child == "pandar_gt")
    );
    // Cameras seen from both LiDARs make loops.
    assert!(edges.iter().filter(|e| e.parent == "pandar_gt").count() >= 1);
    let before = rig_errors(&named(&truth), &named(&start), "pandar64").unwrap();
    let after = rig_errors(&named(&truth), &named(&result), "pandar64").unwrap();
    for (b, a) in before.iter().zip(&after) {
        eprintln!(
            "{}: {:.3}° {:.1} cm -> {:.3}° {:.1} cm",
            a.sensor,
            b.rotation_deg,
            100.0 * b.translation_m,
            a.rotation_deg,
            100.0 * a.translation_m
        );
    }
    for a in cal.agreement() {
        eprintln!(
            "edge {} {} -> {}: {:.3}° {:.2} cm, {:.2} σ",
            a.source,
            a.parent,
            a.child,
            a.rotation_deg,
            100.0 * a.translation_m,
            a.whitened
        );
    }
    assert!(cal.graph().converged);
    // The graph agrees with every edge within a few of the edge's own standard deviations.
    assert!(cal.agreement().iter().all(|a| a.whitened < 3.0));
    for (b, a) in before.iter().zip(&after) {
        if a.sensor == "pandar64" {
            continue;
        }
        let (max_deg, max_m) = if a.sensor == "pandar_gt" {
            (0.3, 0.02)
        } else {
            (1.5, 0.10)
        };
        assert!(
            a.rotation_deg < max_deg && a.translation_m < max_m,
            "{}: {:.3}° {:.3} m",
            a.sensor,
            a.rotation_deg,
            a.translation_m
        );
        if b.rotation_deg > 1.0 {
            assert!(a.rotation_deg < 0.6 * b.rotation_deg, "{}", a.sensor);
        }
        if b.translation_m > 0.15 {
            assert!(a.translation_m < 0.6 * b.translation_m, "{}", a.sensor);
        }
    }
    let cameras: Vec<_> = after
        .iter()
        .filter(|e| e.sensor.ends_with("camera"))
        .collect();
    let mean_deg = cameras.iter().map(|e| e.rotation_deg).sum::<f64>() / cameras.len() as f64;
    let mean_m = cameras.iter().map(|e| e.translation_m).sum::<f64>() / cameras.len() as f64;
    assert!(mean_deg < 0.8 && mean_m < 0.06, "{mean_deg}° {mean_m} m");
}

#[test]
fn the_cli_runs_the_pose_graph_and_names_skipped_pairs() {
    let (tmp, log, gt) = drive(5);
    let out = tmp.path().join("out.yaml");
    let o = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .args([
            "calibrate",
            log.to_str().unwrap(),
            "--method",
            "pose-graph",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    // The back camera sees no board with the forward LiDAR: the pair is named as skipped.
    assert!(
        err.lines()
            .any(|l| l.contains("pose-graph: skipped") && l.contains("back_camera × pandar_gt")),
        "{err}"
    );
    let truth = CalibrationFile::load(&gt).unwrap().to_rig(&gt).unwrap();
    let result = CalibrationFile::load(&out).unwrap().to_rig(&out).unwrap();
    let after = rig_errors(&named(&truth), &named(&result), "pandar64").unwrap();
    for a in &after {
        eprintln!(
            "{}: {:.3}° {:.1} cm",
            a.sensor,
            a.rotation_deg,
            100.0 * a.translation_m
        );
    }
    let gt_lidar = after.iter().find(|e| e.sensor == "pandar_gt").unwrap();
    assert!(gt_lidar.rotation_deg < 0.3 && gt_lidar.translation_m < 0.02);
    assert!(
        after
            .iter()
            .all(|e| e.rotation_deg < 2.0 && e.translation_m < 0.2)
    );
}
