#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The edge-alignment refinement on the real PandaSet drive: a camera rotated by about 1° from
//! the dataset's reference comes back to within a few tenths of a degree; the pair score
//! separates a rotated camera from the reference; selected segments limit the frames used.

use std::path::PathBuf;

use glam::DVec3;
use rigcal::log::Drive;
use rigcal::optim::edge_refine::EdgeRefiner;
use rigcal::optim::runner::Calibrator;

fn pandaset() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/pandaset-002/pandaset-002.mcap")
}

#[test]
fn refines_a_rotated_camera_on_the_real_drive() {
    let drive = Drive::open(&pandaset()).unwrap();
    let truth = drive.rig.clone();
    for (camera, omega_deg) in [
        ("front_camera", DVec3::new(0.6, -0.5, 0.5)),
        ("left_camera", DVec3::new(-0.5, 0.6, -0.5)),
    ] {
        let mut rig = truth.clone();
        let gt = truth.sensor(camera).unwrap().vehicle_from_sensor;
        rig.sensor_mut(camera).unwrap().vehicle_from_sensor =
            gt.perturbed_right(omega_deg * 1f64.to_radians(), DVec3::ZERO);
        let mut refiner = EdgeRefiner::new(
            &drive,
            &rig,
            ("pandar64", &[camera.to_string()]),
            4,
            &[],
            drive.camera_readout,
        )
        .unwrap();
        let mut losses = Vec::new();
        for _ in 0..refiner.max_steps() {
            let r = refiner.step();
            losses.push(r.losses[0].1);
            if r.done {
                break;
            }
        }
        let (before, _) = gt.difference(rig.sensor(camera).unwrap().vehicle_from_sensor);
        let (after, _) = gt.difference(refiner.best().sensor(camera).unwrap().vehicle_from_sensor);
        let (before, after) = (before.to_degrees(), after.to_degrees());
        eprintln!(
            "{camera}: {before:.2}° -> {after:.3}°, cost {:.2} -> {:.2} px in {} steps",
            losses[0],
            losses[losses.len() - 1],
            losses.len()
        );
        assert!(after < 0.5, "{camera}: {after}° after refinement");
    }
}

#[test]
fn the_pair_score_is_worse_for_a_rotated_camera_in_both_directions() {
    use rigcal::optim::edge_align::EdgeAlignment;
    let drive = Drive::open(&pandaset()).unwrap();
    let truth = drive.rig.clone();
    let camera = "front_camera";
    let (good, distances) = EdgeAlignment::score_rig(
        &drive,
        &truth,
        (camera, "pandar64"),
        3,
        &[],
        drive.camera_readout,
    )
    .unwrap();
    assert!(!distances.is_empty() && distances.iter().all(|d| (0.0..=20.0).contains(d)));
    for sign in [-1.0, 1.0] {
        let mut rig = truth.clone();
        let gt = truth.sensor(camera).unwrap().vehicle_from_sensor;
        rig.sensor_mut(camera).unwrap().vehicle_from_sensor =
            gt.perturbed_right(DVec3::new(0.0, sign * 1f64.to_radians(), 0.0), DVec3::ZERO);
        let (bad, _) = EdgeAlignment::score_rig(
            &drive,
            &rig,
            (camera, "pandar64"),
            3,
            &[],
            drive.camera_readout,
        )
        .unwrap();
        eprintln!("{camera}: {good:.2} px at the reference, {bad:.2} px at {sign}° yaw");
        assert!(bad > good + 0.3, "{bad} vs {good}");
    }
}

#[test]
fn selected_segments_limit_the_frames_used() {
    use rigcal::optim::edge_align::EdgeAlignment;
    let drive = Drive::open(&pandaset()).unwrap();
    let (t0, t1) = drive.trajectory.time_range_nanos().unwrap();
    let third = (t1 - t0) / 3;
    let segments = [(t0, t0 + third), (t1 - third / 2, t1)];
    let p = EdgeAlignment::from_drive(
        &drive,
        &drive.rig,
        ("front_camera", "pandar64"),
        6,
        &segments,
        drive.camera_readout,
    )
    .unwrap();
    assert!(p.frames.len() >= 2);
    for f in &p.frames {
        assert!(
            segments
                .iter()
                .any(|&(a, b)| f.sweep_stamp_nanos >= a && f.sweep_stamp_nanos <= b),
            "frame at {} outside the segments",
            f.sweep_stamp_nanos
        );
    }
    // Both segments contribute.
    assert!(p.frames.iter().any(|f| f.sweep_stamp_nanos <= t0 + third));
    assert!(
        p.frames
            .iter()
            .any(|f| f.sweep_stamp_nanos >= t1 - third / 2)
    );
    // A segment with no sweep is an error that says so.
    let e = EdgeAlignment::from_drive(
        &drive,
        &drive.rig,
        ("front_camera", "pandar64"),
        3,
        &[(t1 + 1_000_000_000, t1 + 2_000_000_000)],
        drive.camera_readout,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("selected segments"), "{e}");
}
