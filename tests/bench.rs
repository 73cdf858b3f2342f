#![allow(clippy::unwrap_used, clippy::expect_used)]
//! `rigcal bench` end to end on a tiny suite (a 1 s simulated drive at 1/8 image size, a few
//! steps per method): every run is measured against the ground truth from its perturbed start,
//! the tables, CSV, JSON and both PNG plots are written, a run whose drive is missing is
//! reported without sinking the suite, an unwritable output folder fails before any run, and
//! the command line refuses an unknown suite.

use std::path::PathBuf;
use std::process::Command;

use rigcal::bench::case::CaseResult;
use rigcal::bench::suite::{Case, DriveSpec, Method, Protocol, Suite, UnicalSettings};
use rigcal::bench::{Stage, run_suite};
use rigcal::calib::CalibrationFile;
use rigcal::geometry::rig_errors;
use rigcal::sim::synth::perturb_rig;
use rigcal::sim::trajectories::TrajectoryKind;
use rigcal::sim::world::SceneKind;
use rigcal::unical::surface_align::AlignmentLoss;
use tempfile::TempDir;

/// A scratch folder, removed when dropped.
fn temp_dir(name: &str) -> TempDir {
    tempfile::Builder::new()
        .prefix(&format!("rigcal-bench-{name}-"))
        .tempdir()
        .unwrap()
}

fn tiny_suite() -> Suite {
    let drive = DriveSpec::Sim {
        scene: SceneKind::Urban,
        trajectory: TrajectoryKind::Figure8,
        seconds: 1.0,
        scale: 0.125,
        seed: 3,
    };
    let unical = Method::UniCal(UnicalSettings {
        iterations: 6,
        geometry_init_steps: 2,
        geometry_init_rays: 256,
        pose_warmup: 3,
        pose_ramp: 0,
        rays_per_sensor: 64,
        rays_per_camera: 8,
        sweeps_per_lidar: 1,
        camera_frames: 1,
        camera_scale: 0.25,
        newton_lidar_poses: false,
        lidar_supervision: true,
        alignment: AlignmentLoss::SurfaceAlignment,
    });
    let camera_only = match &unical {
        Method::UniCal(s) => Method::UniCal(UnicalSettings {
            lidar_supervision: false,
            ..s.clone()
        }),
        m => m.clone(),
    };
    let edge = Method::Edge {
        frames: 1,
        max_steps: 4,
    };
    let case = |protocol, row: &str, method: &Method, drive: &DriveSpec, deg, cm, seed| Case {
        protocol,
        row: row.into(),
        method: method.clone(),
        drive: drive.clone(),
        perturb_deg: deg,
        perturb_cm: cm,
        seed,
    };
    let missing = DriveSpec::Log {
        mcap: PathBuf::from("/nonexistent/drive.mcap"),
        ground_truth: PathBuf::from("/nonexistent/gt.yaml"),
    };
    Suite {
        name: "tiny".into(),
        cases: vec![
            case(
                Protocol::Perturbation,
                "Rotation 2°",
                &edge,
                &drive,
                2.0,
                0.0,
                1,
            ),
            case(
                Protocol::Perturbation,
                "Rotation 2°",
                &edge,
                &drive,
                2.0,
                0.0,
                2,
            ),
            case(
                Protocol::Perturbation,
                "Rotation 2°",
                &unical,
                &drive,
                2.0,
                0.0,
                1,
            ),
            case(
                Protocol::Perturbation,
                "Transl 20 cm",
                &unical,
                &drive,
                0.0,
                20.0,
                1,
            ),
            // The same run as the third case: shared, run once.
            case(Protocol::Sensors, "Full", &unical, &drive, 2.0, 0.0, 1),
            case(
                Protocol::Sensors,
                "Camera-only",
                &camera_only,
                &drive,
                2.0,
                0.0,
                1,
            ),
            case(Protocol::PandaSet, "missing", &edge, &missing, 1.0, 10.0, 1),
        ],
    }
}

#[test]
fn a_tiny_suite_measures_every_run_and_writes_tables_and_plots() {
    let tmp = temp_dir("tiny");
    let out = tmp.path();
    let suite = tiny_suite();
    assert_eq!(suite.runs().len(), 6);
    let mut simulated = false;
    let mut runs_seen = Vec::new();
    let report = run_suite(&suite, out, &mut |stage, _, _| match stage {
        Stage::Simulating(_) => simulated = true,
        Stage::Running { index, runs, .. } => {
            assert_eq!(*runs, 6);
            if !runs_seen.contains(index) {
                runs_seen.push(*index);
            }
        }
    })
    .unwrap();
    assert!(simulated, "the drive was simulated");
    assert_eq!(report.results.len(), 6);

    // Known answers: each run's initial errors are the ground truth against its own seeded
    // perturbation, after aligning the root LiDAR.
    let gt_path = out.join("drives/urban-figure8-1s-x0.125-seed3-ground-truth.yaml");
    let gt = CalibrationFile::load_rig(&gt_path).unwrap();
    let root = gt.lidars().next().unwrap().name.clone();
    let by_case = |c: &Case| -> &CaseResult { report.result(c).unwrap() };
    for case in suite
        .cases
        .iter()
        .filter(|c| c.protocol != Protocol::PandaSet)
    {
        let r = by_case(case);
        assert!(r.error.is_none(), "{:?}", r.error);
        let camera_only = case.row == "Camera-only";
        let root = if camera_only {
            gt.cameras().next().unwrap().name.clone()
        } else {
            root.clone()
        };
        assert_eq!(r.root, root);
        let start = perturb_rig(&gt, case.perturb_deg, case.perturb_cm, case.seed);
        let want = rig_errors(&gt.extrinsics(), &start.extrinsics(), &root).unwrap();
        for s in &r.sensors {
            let w = want.iter().find(|w| w.sensor == s.sensor).unwrap();
            assert!(
                (s.initial_rotation_deg - w.rotation_deg).abs() < 1e-9,
                "{s:?}"
            );
            assert!((s.initial_translation_cm - w.translation_m * 100.0).abs() < 1e-9);
        }
        assert!(
            r.sensors
                .iter()
                .any(|s| s.initial_rotation_deg > 0.5 || s.initial_translation_cm > 5.0),
            "the start is perturbed"
        );
        assert_eq!(
            r.curve.len(),
            r.steps + 1,
            "one curve point per step and the start"
        );
        assert_eq!(r.curve[0].errors, r.initial);
        assert_eq!(r.curve.last().unwrap().step, r.steps);
    }
    // Edge alignment moves only cameras: LiDAR errors are not its to report.
    let edge = by_case(&suite.cases[0]);
    assert!(edge.result.lidar_rotation_deg.is_none() && edge.result.camera_rotation_deg.is_some());
    let unical = by_case(&suite.cases[2]);
    assert!(unical.result.lidar_rotation_deg.is_some());
    let p = unical
        .photometric
        .as_ref()
        .expect("UniCal with cameras renders a held-out frame");
    assert!(
        p.psnr_db.is_finite() && p.psnr_db > 0.0 && p.ssim.abs() <= 1.0,
        "{p:?}"
    );
    // Camera-only: errors against a camera root, the LiDARs left where they started.
    let camera_only = by_case(&suite.cases[5]);
    assert!(camera_only.result.lidar_rotation_deg.is_none());
    assert!(camera_only.result.camera_rotation_deg.is_some());
    assert!(
        camera_only
            .sensors
            .iter()
            .any(|s| s.kind == "camera" && s.moved_deg > 0.0),
        "the cameras moved"
    );
    for s in camera_only.sensors.iter().filter(|s| s.kind == "lidar") {
        assert!(!s.optimised);
        assert!(s.moved_deg < 1e-9 && s.moved_cm < 1e-9, "{s:?}");
    }
    // A run whose drive is missing is reported, naming the file.
    let missing = by_case(&suite.cases[6]);
    assert!(
        missing
            .error
            .as_deref()
            .unwrap_or("")
            .contains("/nonexistent/drive.mcap")
    );

    let md = std::fs::read_to_string(out.join("tables.md")).unwrap();
    for needle in [
        "Table A7 layout",
        "| Rotation 2° | edge alignment |",
        "| Transl 20 cm | UniCal |",
        "Table A10 layout",
        "| Camera-only | UniCal (camera only) |",
        "Run time (Table A1 layout)",
        "Photometric consistency",
        "## Failed runs",
    ] {
        assert!(md.contains(needle), "tables.md lacks {needle:?}:\n{md}");
    }
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    assert!(header.starts_with("protocol,row,method"));
    let columns = header.split(',').count();
    assert!(
        csv.lines().all(|l| l.split(',').count() >= columns),
        "{csv}"
    );
    let sensors = gt.sensors.len();
    assert_eq!(
        csv.lines().count(),
        1 + 6 * sensors + 1,
        "six cases × sensors + the failure"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert_eq!(json["results"].as_array().unwrap().len(), 6);
    for plot in ["convergence.png", "error-vs-perturbation.png"] {
        let img = image::open(out.join(plot)).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (1400, 900));
        let inked = img.pixels().filter(|p| p.0 != [255, 255, 255]).count();
        assert!(
            inked > 20_000,
            "{plot} is nearly blank ({inked} pixels drawn)"
        );
    }
}

#[test]
fn an_unwritable_output_folder_fails_before_any_run() {
    let suite = tiny_suite();
    let mut called = false;
    let e = run_suite(
        &suite,
        std::path::Path::new("/proc/rigcal-bench-out"),
        &mut |_, _, _| called = true,
    )
    .unwrap_err();
    assert!(e.to_string().contains("/proc/rigcal-bench-out"), "{e}");
    assert!(!called);
}

#[test]
fn the_command_line_refuses_an_unknown_suite() {
    let tmp = temp_dir("cli");
    let out = Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .args(["bench", "--suite", "nope", "--out"])
        .arg(tmp.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("unknown --suite 'nope'"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
}
