#![allow(clippy::unwrap_used, clippy::expect_used)]
//! A camera method never ends worse than the initial guess without saying so: its result is
//! checked by edge alignment on frames it did not fit (`pipeline::report::Report::for_cameras`,
//! which `rigcal calibrate --method edge|mi|target` runs), and a camera whose edges align worse
//! than at the start goes back to the start with the verdict "failed". Built to fail: the
//! initial guess is the truth and the "result" is it turned by 2°, as a method that ran off
//! would leave it; and built to pass: the start 2° off and the result the truth.

use glam::DVec3;
use rigcal::calib::Rig;
use rigcal::pipeline::report::{Report, Verdict};
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

#[test]
fn a_camera_result_worse_than_the_start_is_put_back_and_failed_and_a_better_one_kept() {
    let tmp = tempfile::tempdir().unwrap();
    let mut rig = SimRig::preset(RigPreset::Pandaset);
    rig.cameras.retain(|c| c.name == "front_camera");
    let mut cfg = SynthConfig::new(SceneKind::Urban, rig, TrajectoryKind::Figure8, 4.0, 83);
    cfg.scale = 0.25;
    cfg.camera_rate_hz = 2.0;
    let (log, gt) = (tmp.path().join("d.mcap"), tmp.path().join("gt.yaml"));
    synthesize(&cfg, &log, &gt, &mut |_, _| {}).unwrap();
    let drive = rigcal::log::Drive::open(&log).unwrap();
    let truth = rigcal::calib::CalibrationFile::load(&gt)
        .unwrap()
        .to_rig(&gt)
        .unwrap();
    let cameras = vec!["front_camera".to_string()];
    let pose = |rig: &Rig| rig.sensor("front_camera").unwrap().vehicle_from_sensor;

    // A method that ran off: the start is right, the result 2° away.
    let worse = turned(&truth, "front_camera", 2.0);
    let (report, written) = Report::for_cameras(&drive, &truth, &worse, "pandar64", &cameras, &[]);
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

    // A method that did its job: the start 2° off, the result the truth.
    let start = turned(&truth, "front_camera", 2.0);
    let (report, written) = Report::for_cameras(&drive, &start, &truth, "pandar64", &cameras, &[]);
    assert_ne!(
        report.sensors[0].verdict,
        Verdict::Failed,
        "{}",
        report.to_text()
    );
    assert_eq!(pose(&written), pose(&truth));
}
