//! The calibrations an example compares, read from its command line: the log's own rig first,
//! then each file given (a native calibration file or a dataset's ground_truth.json) laid over
//! a copy of it, sensor by sensor.

use rigcal::calib::Rig;
use rigcal::calib::dataset_json::load_reference;
use rigcal::log::Drive;

fn load(path: &str) -> Result<Rig, String> {
    let p = std::path::Path::new(path);
    if path.ends_with(".json") {
        load_reference(p).map_err(|e| e.to_string())
    } else {
        rigcal::calib::file::CalibrationFile::load_rig(p).map_err(|e| e.to_string())
    }
}

/// `("log", the log's rig)` and `(path, the log's rig with that file's extrinsics)` per path.
pub fn given_rigs(drive: &Drive, paths: &[String]) -> Result<Vec<(String, Rig)>, String> {
    let mut rigs: Vec<(String, Rig)> = vec![("log".into(), drive.rig.clone())];
    for path in paths {
        let loaded = load(path)?;
        let mut rig = drive.rig.clone();
        for s in &mut rig.sensors {
            if let Some(r) = loaded.sensor(&s.name) {
                s.vehicle_from_sensor = r.vehicle_from_sensor;
            }
        }
        rigs.push((path.clone(), rig));
    }
    Ok(rigs)
}
