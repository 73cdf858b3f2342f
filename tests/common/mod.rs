//! Helpers shared by the integration tests that read the real PandaSet drive.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::PathBuf;

use rigcal::calib::Rig;
use rigcal::calib::dataset_json::load_reference;
use rigcal::log::Drive;

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
