//! Helpers shared by the integration tests: the real PandaSet drive, and the simulator's
//! checkerboard drive.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::PathBuf;

use rigcal::calib::Rig;
use rigcal::calib::dataset_json::load_reference;
use rigcal::log::Drive;
use tempfile::TempDir;

/// `../shared/data/pandaset-002`.
pub fn pandaset_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/pandaset-002")
}

/// The drive's rig with every extrinsic set to the dataset's reference (ground_truth.json).
pub fn reference_rig(drive: &Drive) -> Rig {
    let reference = load_reference(&pandaset_dir().join("ground_truth.json")).unwrap();
    let mut rig = drive.rig.clone();
    for s in &mut rig.sensors {
        if let Some(r) = reference.sensor(&s.name) {
            s.vehicle_from_sensor = r.vehicle_from_sensor;
        }
    }
    rig
}

/// A stationary 0.6 s drive of the pandaset rig in the checkerboard scene (cameras at 2 Hz),
/// every sensor perturbed by 2° / 20 cm with `seed`: (its folder, removed when dropped, the log,
/// the ground truth).
pub fn checkerboard_drive(tag: &str, seed: u64) -> (TempDir, PathBuf, PathBuf) {
    use rigcal::sim::rigs::{RigPreset, SimRig};
    use rigcal::sim::synth::{SynthConfig, synthesize};
    use rigcal::sim::trajectories::TrajectoryKind;
    use rigcal::sim::world::SceneKind;
    let tmp = tempfile::Builder::new()
        .prefix(&format!("rigcal-{tag}-{seed}-"))
        .tempdir()
        .unwrap();
    let dir = tmp.path();
    let mut cfg = SynthConfig::new(
        SceneKind::Checkerboard,
        SimRig::preset(RigPreset::Pandaset),
        TrajectoryKind::Stationary,
        0.6,
        seed,
    );
    cfg.perturb_deg = 2.0;
    cfg.perturb_cm = 20.0;
    cfg.camera_rate_hz = 2.0;
    let (log, gt) = (dir.join("boards.mcap"), dir.join("gt.yaml"));
    synthesize(&cfg, &log, &gt, &mut |_, _| {}).unwrap();
    (tmp, log, gt)
}

/// `(name, vehicle_from_sensor)` of every sensor, for `rig_errors`.
pub fn named(rig: &Rig) -> Vec<(String, rigcal::geometry::Rigid)> {
    rig.sensors
        .iter()
        .map(|s| (s.name.clone(), s.vehicle_from_sensor))
        .collect()
}
