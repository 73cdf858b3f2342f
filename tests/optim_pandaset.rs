#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The edge-alignment refinement on the real PandaSet drive: a camera rotated by about 1° from
//! the dataset's reference comes back to within a few tenths of a degree.

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
        let mut refiner =
            EdgeRefiner::new(&drive, &rig, "pandar64", &[camera.to_string()], 4, &[]).unwrap();
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
