//! Reference calibrations in a dataset's JSON layout, as `--ground-truth` accepts them next to
//! the native file: `{"vehicle_frame": F, "sensors": {NAME: {"kind": "lidar"|"camera",
//! "vehicle_from_sensor": 4×4 row-major, "width", "height", "fx", "fy", "cx", "cy"}}}` (the
//! layout of ../shared/data/pandaset-002/ground_truth.json; cameras are pinhole in the OpenCV
//! optical frame). [`load_reference`] reads either format.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;

use super::file::{CalibFileError, CalibrationFile};
use super::rig::{Rig, Sensor, SensorKind};
use super::transform_text::rigid_from_matrix;
use crate::geometry::camera::CameraIntrinsics;

#[derive(Deserialize)]
struct DatasetFile {
    #[serde(default)]
    vehicle_frame: String,
    sensors: BTreeMap<String, DatasetSensor>,
}

#[derive(Deserialize)]
struct DatasetSensor {
    kind: SensorKind,
    vehicle_from_sensor: [[f64; 4]; 4],
    width: Option<u32>,
    height: Option<u32>,
    fx: Option<f64>,
    fy: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
}

/// Parse the dataset JSON layout; `path` only names the file in errors.
pub fn parse(text: &str, path: &Path) -> Result<Rig, CalibFileError> {
    let invalid = |what: String| CalibFileError::Invalid {
        path: path.to_path_buf(),
        what,
    };
    let file: DatasetFile = serde_json::from_str(text)
        .map_err(|e| invalid(format!("not a dataset calibration JSON: {e}")))?;
    let mut sensors = Vec::with_capacity(file.sensors.len());
    for (name, s) in file.sensors {
        let vehicle_from_sensor = rigid_from_matrix(s.vehicle_from_sensor.as_flattened())
            .map_err(|e| invalid(format!("sensor '{name}': vehicle_from_sensor: {e}")))?;
        let camera = match s.kind {
            SensorKind::Lidar => None,
            SensorKind::Camera => match (s.width, s.height, s.fx, s.fy, s.cx, s.cy) {
                (Some(w), Some(h), Some(fx), Some(fy), Some(cx), Some(cy))
                    if w > 0 && h > 0 && fx > 0.0 && fy > 0.0 =>
                {
                    Some(CameraIntrinsics::pinhole(w, h, fx, fy, cx, cy))
                }
                _ => {
                    return Err(invalid(format!(
                        "camera '{name}' needs positive width, height, fx, fy and cx, cy"
                    )));
                }
            },
        };
        sensors.push(Sensor {
            frame_id: name.clone(),
            name,
            kind: s.kind,
            topics: Vec::new(),
            vehicle_from_sensor,
            camera,
        });
    }
    Ok(Rig {
        vehicle_frame: file.vehicle_frame,
        sensors,
    })
}

/// A reference calibration: the native YAML file, or a dataset's JSON layout (told apart by
/// the first non-blank character).
pub fn load_reference(path: &Path) -> Result<Rig, CalibFileError> {
    let text = std::fs::read_to_string(path).map_err(|source| CalibFileError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    if text.trim_start().starts_with('{') {
        parse(&text, path)
    } else {
        let file = CalibrationFile::parse(&text, path)?;
        file.to_rig(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = r#"{"vehicle_frame": "base", "sensors": {
        "lidar": {"kind": "lidar", "vehicle_from_sensor":
            [[0, -1, 0, 1.5], [1, 0, 0, -0.5], [0, 0, 1, 2.0], [0, 0, 0, 1]]},
        "cam": {"kind": "camera", "vehicle_from_sensor":
            [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
            "width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240}}}"#;

    #[test]
    fn reads_extrinsics_and_intrinsics() {
        let rig = parse(SAMPLE, Path::new("gt.json")).unwrap();
        assert_eq!(rig.vehicle_frame, "base");
        let lidar = rig.sensor("lidar").unwrap();
        let p = lidar
            .vehicle_from_sensor
            .transform_point(glam::DVec3::new(1.0, 0.0, 0.0));
        assert!(
            (p - glam::DVec3::new(1.5, 0.5, 2.0)).length() < 1e-12,
            "{p}"
        );
        let cam = rig.sensor("cam").unwrap().camera.as_ref().unwrap();
        assert_eq!((cam.width, cam.fx, cam.cy), (640, 500.0, 240.0));
    }

    #[test]
    fn bad_input_names_the_file_and_the_sensor() {
        let bad = SAMPLE.replace("[0, -1, 0, 1.5]", "[0, -2, 0, 1.5]");
        let e = parse(&bad, Path::new("gt.json")).unwrap_err().to_string();
        assert!(e.contains("gt.json") && e.contains("lidar"), "{e}");
        let no_fx = SAMPLE.replace("\"fx\": 500,", "");
        let e = parse(&no_fx, Path::new("gt.json")).unwrap_err().to_string();
        assert!(e.contains("cam"), "{e}");
        let e = parse("{\"sensors\": 3}", Path::new("x.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.json"), "{e}");
    }
}
