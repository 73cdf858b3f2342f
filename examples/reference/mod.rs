//! The reference a hand-eye example compares with.

/// `rig` with every sensor the reference file `gt` (a native calibration file or a dataset's
/// ground_truth.json) names moved to its reference pose.
pub fn at_reference(rig: &rigcal::calib::Rig, gt: &str) -> Result<rigcal::calib::Rig, String> {
    let reference = rigcal::calib::dataset_json::load_reference(std::path::Path::new(gt))
        .map_err(|e| e.to_string())?;
    let mut truth = rig.clone();
    for s in &mut truth.sensors {
        if let Some(r) = reference.sensor(&s.name) {
            s.vehicle_from_sensor = r.vehicle_from_sensor;
        }
    }
    Ok(truth)
}
