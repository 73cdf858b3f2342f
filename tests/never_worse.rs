#![allow(clippy::unwrap_used, clippy::expect_used)]
//! A camera method never ends worse than the initial guess without saying so: its result is
//! checked by edge alignment on frames it did not fit (`pipeline::report::Report::for_cameras`,
//! which `rigcal calibrate --method edge|mi|target` runs), and a camera whose edges align worse
//! than at the start goes back to the start with the verdict "failed". Built to fail: the
//! initial guess is the truth and the "result" is it turned by 2°, as a method that ran off
//! would leave it; and built to pass: the start 2° off and the result the truth. The same
//! for a LiDAR that UniCal moved with the scene (`--method unical`, no registration first),
//! checked by its point-to-plane residual against the reference LiDAR.

use glam::DVec3;
use rigcal::calib::Rig;
use rigcal::log::{Drive, spread_evenly};
use rigcal::optim::edge_align::{held_out_pairs, images_nearest};
use rigcal::pipeline::mi_check::MiCheck;
use rigcal::pipeline::report::{MethodFit, Report, Verdict};
use rigcal::sim::rigs::{RigPreset, SimRig};
use rigcal::sim::synth::{SynthConfig, synthesize};
use rigcal::sim::trajectories::TrajectoryKind;
use rigcal::sim::world::SceneKind;

fn turned(rig: &Rig, camera: &str, deg: f64) -> Rig {
    let mut out = rig.clone();
    let s = out.sensor_mut(camera).unwrap();
    s.vehicle_from_sensor = s.vehicle_from_sensor.perturbed_right(
        DVec3::new(0.3, 1.0, 0.2).normalize_or_zero() * deg.to_radians(),
        DVec3::ZERO,
    );
    out
}

/// A small figure-8 drive of the PandaSet rig with its front camera only, `(seconds, camera
/// rate in Hz)`, and its truth.
fn front_camera_drive(
    dir: &std::path::Path,
    seed: u64,
    (secs, rate_hz): (f64, f64),
) -> (Drive, Rig) {
    let mut rig = SimRig::preset(RigPreset::Pandaset);
    rig.cameras.retain(|c| c.name == "front_camera");
    let mut cfg = SynthConfig::new(SceneKind::Urban, rig, TrajectoryKind::Figure8, secs, seed);
    cfg.scale = 0.25;
    cfg.camera_rate_hz = rate_hz;
    let (log, gt) = (dir.join("d.mcap"), dir.join("gt.yaml"));
    synthesize(&cfg, &log, &gt, &mut |_, _| {}).unwrap();
    let truth = rigcal::calib::CalibrationFile::load(&gt)
        .unwrap()
        .to_rig(&gt)
        .unwrap();
    (Drive::open(&log).unwrap(), truth)
}

#[test]
fn a_camera_result_worse_than_the_start_is_put_back_and_failed_and_a_better_one_kept() {
    let tmp = tempfile::tempdir().unwrap();
    let (drive, truth) = front_camera_drive(tmp.path(), 83, (4.0, 2.0));
    let cameras = vec!["front_camera".to_string()];
    let pose = |rig: &Rig| rig.sensor("front_camera").unwrap().vehicle_from_sensor;
    let fit = MethodFit {
        reference: "pandar64",
        cameras: &cameras,
        fitted_sweeps: 4,
        ..MethodFit::default()
    };

    // A method that ran off: the start is right, the result 2° away.
    let worse = turned(&truth, "front_camera", 2.0);
    let (report, written) = Report::for_cameras(&drive, &truth, &worse, &fit, &[]);
    let camera = &report.sensors[0];
    assert_eq!(camera.verdict, Verdict::Failed, "{}", report.to_text());
    assert!(
        camera.why.contains("initial guess is kept"),
        "{}",
        camera.why
    );
    assert_eq!(pose(&written), pose(&truth));
    let check = &camera.checks[0];
    assert!(check.after <= check.before, "{check:?}");
    assert!(check.what.contains("none of them fitted"), "{}", check.what);

    // A method that did its job: the start 2° off, the result the truth.
    let start = turned(&truth, "front_camera", 2.0);
    let (report, written) = Report::for_cameras(&drive, &start, &truth, &fit, &[]);
    assert_ne!(
        report.sensors[0].verdict,
        Verdict::Failed,
        "{}",
        report.to_text()
    );
    assert_eq!(pose(&written), pose(&truth));

    // A result the method itself rejects (mutual information on its bound) is failed and
    // put back, however its edges align.
    let failures = vec![("front_camera".to_string(), "ran to its bounds".to_string())];
    let rejected = MethodFit {
        failures: &failures,
        ..fit.clone()
    };
    let (report, written) = Report::for_cameras(&drive, &start, &truth, &rejected, &[]);
    assert_eq!(report.sensors[0].verdict, Verdict::Failed);
    assert!(report.sensors[0].why.starts_with("ran to its bounds"));
    assert_eq!(pose(&written), pose(&start));
}

#[test]
fn the_second_check_scores_the_truth_above_a_turned_camera_by_reflectivity_against_grey() {
    // Known answer: on the simulator the truth is where the LiDAR's reflectivity and the
    // image's grey agree best, so a camera turned by 1° scores lower, and the check says so
    // both ways round (each time on the points the result keeps in view). The report carries
    // it beside the edge check.
    let tmp = tempfile::tempdir().unwrap();
    let (drive, truth) = front_camera_drive(tmp.path(), 87, (4.0, 2.0));
    let pose = |rig: &Rig| rig.sensor("front_camera").unwrap().vehicle_from_sensor;
    let turned_pose = pose(&turned(&truth, "front_camera", 1.0));
    let check = |start, end| {
        MiCheck::new(
            &drive,
            &truth,
            ("front_camera", "pandar64"),
            (8, &[], &[]),
            (start, end),
        )
        .unwrap()
    };
    let ran_off = check(pose(&truth), turned_pose);
    assert!(ran_off.worse(), "{ran_off:?}");
    assert!(ran_off.frames >= 4, "{ran_off:?}");
    let found = check(turned_pose, pose(&truth));
    assert!(!found.worse(), "{found:?}");

    let cameras = vec!["front_camera".to_string()];
    let fit = MethodFit {
        reference: "pandar64",
        cameras: &cameras,
        fitted_sweeps: 4,
        ..MethodFit::default()
    };
    let start = turned(&truth, "front_camera", 1.0);
    let edges = MethodFit {
        fitted_edges: true,
        ..fit.clone()
    };
    let (report, _) = Report::for_cameras(&drive, &start, &truth, &edges, &[]);
    assert_ne!(report.sensors[0].verdict, Verdict::Failed);
    let mi = report.sensors[0]
        .checks
        .iter()
        .find(|c| c.unit == "nats")
        .expect("an edge fit's report has the mutual-information check");
    assert!(mi.after > mi.before, "{mi:?}");
    // Another method's result the edges judge alone.
    let (report, _) = Report::for_cameras(&drive, &start, &truth, &fit, &[]);
    assert!(report.sensors[0].checks.iter().all(|c| c.unit != "nats"));
}

#[test]
fn the_check_keeps_off_the_frames_a_method_fitted_unless_the_log_has_no_others() {
    let tmp = tempfile::tempdir().unwrap();
    let (drive, _) = front_camera_drive(tmp.path(), 84, (3.0, 4.0));
    let pair = ("front_camera", "pandar64");
    let sweeps = drive.frames_within("pandar64", &[]);
    assert!(sweeps.len() >= 8, "{} sweeps", sweeps.len());

    // A method that fitted four sweeps spread evenly: none of the check's images is theirs.
    let fitted = images_nearest(&drive, pair.0, pair.1, &spread_evenly(&sweeps, 4));
    assert_eq!(fitted.len(), 4);
    let (pairs, held_out) = held_out_pairs(&drive, pair, 4, &[], &fitted).unwrap();
    assert!(held_out);
    assert_eq!(pairs.len(), 4);
    // Nor is one a neighbour of a fitted image (within a quarter of their spacing).
    let stamp = |j: usize| drive.stream(pair.0).unwrap().frames[j].stamp_nanos;
    let spacing = (stamp(fitted[3]) - stamp(fitted[0])) / 3;
    for p in &pairs {
        for &f in &fitted {
            let apart = (p.image_stamp_nanos - stamp(f)).abs();
            assert!(apart > spacing / 4, "{} is next to {f}", p.image_index);
        }
        assert!(
            !fitted.contains(&p.image_index),
            "{} was fitted",
            p.image_index
        );
    }
    // Without the exclusion the same spread lands on the fitted images themselves.
    let (same, _) = held_out_pairs(&drive, pair, 4, &[], &[]).unwrap();
    let same: Vec<usize> = same.iter().map(|p| p.image_index).collect();
    assert_eq!(same, fitted);

    // Every image fitted: the check falls back to them and says so.
    let every: Vec<usize> = (0..drive.stream(pair.0).unwrap().frames.len()).collect();
    let (pairs, held_out) = held_out_pairs(&drive, pair, 4, &[], &every).unwrap();
    assert!(!held_out);
    assert_eq!(pairs.len(), 4);
}

#[test]
fn a_sensor_unical_left_worse_goes_back_to_its_start_relative_to_the_moved_reference() {
    use rigcal::pipeline::run::LidarEvidence;
    use rigcal::pipeline::{PipelineConfig, Plan, PlanRequest};
    let tmp = tempfile::tempdir().unwrap();
    let (drive, truth) = front_camera_drive(tmp.path(), 85, (4.0, 1.0));
    let mut config = PipelineConfig::default();
    config.lidars.register = false;
    config.cameras.hand_eye = rigcal::pipeline::config::HandEye::Never;
    let request = PlanRequest {
        sensors: vec!["pandar64".into(), "pandar_gt".into()],
        ..PlanRequest::default()
    };
    let plan = Plan::build(&drive, &truth, &request, &config).unwrap();
    let moved = |rig: &Rig, name: &str, deg: f64, cm: f64| {
        let mut out = rig.clone();
        let s = out.sensor_mut(name).unwrap();
        s.vehicle_from_sensor = s.vehicle_from_sensor.perturbed_right(
            DVec3::new(0.2, -0.4, 1.0).normalize_or_zero() * deg.to_radians(),
            DVec3::new(0.6, 0.8, 0.0) * cm / 100.0,
        );
        out
    };
    let pose = |rig: &Rig, name: &str| rig.sensor(name).unwrap().vehicle_from_sensor;
    let gt = |report: &Report| {
        report
            .sensors
            .iter()
            .find(|s| s.name == "pandar_gt")
            .unwrap()
            .clone()
    };

    // UniCal ran off: the start is right; the result turns the reference 0.5° and leaves the
    // PandarGT 1° / 20 cm away from it.
    let result = moved(&moved(&truth, "pandar64", 0.5, 0.0), "pandar_gt", 1.0, 20.0);
    let (report, written) =
        Report::build(&drive, &truth, &result, &plan, &LidarEvidence::default());
    let lidar = gt(&report);
    assert_eq!(lidar.verdict, Verdict::Failed, "{}", report.to_text());
    assert!(lidar.why.contains("registering worse"), "{}", lidar.why);
    let check = &lidar.checks[0];
    assert!(check.after > check.before, "{check:?}");
    // The reference keeps UniCal's pose; the PandarGT sits where the start put it against it.
    assert_eq!(pose(&written, "pandar64"), pose(&result, "pandar64"));
    let relative = |rig: &Rig| pose(rig, "pandar64").inverse() * pose(rig, "pandar_gt");
    let (deg, m) = relative(&truth).difference(relative(&written));
    assert!(deg < 1e-9 && m < 1e-9, "{deg} rad, {m} m");

    // UniCal did its job: the start 1° / 20 cm off, the result the truth.
    let start = moved(&truth, "pandar_gt", 1.0, 20.0);
    let (report, written) = Report::build(&drive, &start, &truth, &plan, &LidarEvidence::default());
    let lidar = gt(&report);
    assert_eq!(lidar.verdict, Verdict::CheckIt, "{}", report.to_text());
    assert!(lidar.why.contains("at least as well"), "{}", lidar.why);
    assert_eq!(pose(&written, "pandar_gt"), pose(&truth, "pandar_gt"));

    // A camera UniCal turned 2° off while it moved the reference 0.5°: it fails, and goes back
    // to its initial pose relative to the reference, as the PandarGT does; the check judges it
    // there (before: the whole initial guess's alignment).
    let request = PlanRequest {
        sensors: vec!["pandar64".into(), "front_camera".into()],
        ..PlanRequest::default()
    };
    let plan = Plan::build(&drive, &truth, &request, &config).unwrap();
    let result = moved(
        &moved(&truth, "pandar64", 0.5, 0.0),
        "front_camera",
        2.0,
        0.0,
    );
    let (report, written) =
        Report::build(&drive, &truth, &result, &plan, &LidarEvidence::default());
    let camera = report
        .sensors
        .iter()
        .find(|s| s.name == "front_camera")
        .unwrap();
    assert_eq!(camera.verdict, Verdict::Failed, "{}", report.to_text());
    assert!(
        camera
            .why
            .contains("its initial pose relative to pandar64 is kept"),
        "{}",
        camera.why
    );
    let relative = |rig: &Rig| pose(rig, "pandar64").inverse() * pose(rig, "front_camera");
    let (deg, m) = relative(&truth).difference(relative(&written));
    assert!(deg < 1e-9 && m < 1e-9, "{deg} rad, {m} m");
}
