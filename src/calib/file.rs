//! The native calibration file, `rigcal_calibration: 1` (docs/interfaces.md, a contract).
//!
//! On reading, `translation_m` + `rotation_xyzw` are authoritative; `roll_pitch_yaw_rad` and
//! `matrix` are derived and rewritten on every save. Saves are atomic.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use super::rig::{Rig, Sensor, SensorKind};
use crate::geometry::Rigid;
use crate::geometry::camera::CameraIntrinsics;

pub const SCHEMA_VERSION: u32 = 1;

#[derive(Debug, Error)]
pub enum CalibFileError {
    #[error("{path}: cannot read: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: cannot write: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: not a valid rigcal calibration file: {source}")]
    Parse {
        path: PathBuf,
        source: super::yaml::YamlError,
    },
    #[error("{path}: {what}")]
    Invalid { path: PathBuf, what: String },
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ExtrinsicYaml {
    pub translation_m: [f64; 3],
    pub rotation_xyzw: [f64; 4],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roll_pitch_yaw_rad: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matrix: Option<[[f64; 4]; 4]>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SensorYaml {
    pub name: String,
    pub kind: SensorKind,
    #[serde(default)]
    pub frame_id: String,
    #[serde(default)]
    pub topics: Vec<String>,
    pub vehicle_from_sensor: ExtrinsicYaml,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraIntrinsics>,
}

/// The file as it is on disk.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CalibrationFile {
    pub rigcal_calibration: u32,
    pub vehicle_frame: String,
    pub sensors: Vec<SensorYaml>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub provenance: BTreeMap<String, serde_yaml::Value>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub metrics: BTreeMap<String, serde_yaml::Value>,
}

impl ExtrinsicYaml {
    pub fn from_rigid(t: Rigid) -> Self {
        let q = t.rotation.normalize();
        Self {
            translation_m: t.translation.to_array(),
            rotation_xyzw: [q.x, q.y, q.z, q.w],
            roll_pitch_yaw_rad: Some(t.roll_pitch_yaw_rad()),
            matrix: Some(t.to_rows()),
        }
    }

    /// The authoritative transform; errors if the quaternion is far from unit or not finite.
    pub fn to_rigid(&self) -> Result<Rigid, crate::error::ParseError> {
        let [x, y, z, w] = self.rotation_xyzw;
        let q = DQuat::from_xyzw(x, y, z, w);
        let t = DVec3::from_array(self.translation_m);
        if !q.is_finite() || !t.is_finite() {
            return Err("rotation_xyzw or translation_m is not finite".into());
        }
        let norm = q.length();
        if (norm - 1.0).abs() > 1e-3 {
            return Err(
                format!("rotation_xyzw has norm {norm:.6}, expected a unit quaternion").into(),
            );
        }
        Ok(Rigid::new(q / norm, t))
    }
}

impl CalibrationFile {
    pub fn from_rig(rig: &Rig) -> Self {
        Self {
            rigcal_calibration: SCHEMA_VERSION,
            vehicle_frame: rig.vehicle_frame.clone(),
            sensors: rig
                .sensors
                .iter()
                .map(|s| SensorYaml {
                    name: s.name.clone(),
                    kind: s.kind,
                    frame_id: s.frame_id.clone(),
                    topics: s.topics.clone(),
                    vehicle_from_sensor: ExtrinsicYaml::from_rigid(s.vehicle_from_sensor),
                    camera: s.camera.clone(),
                })
                .collect(),
            provenance: BTreeMap::new(),
            metrics: BTreeMap::new(),
        }
    }

    /// The rig, validated; `path` only names the file in errors.
    pub fn to_rig(&self, path: &Path) -> Result<Rig, CalibFileError> {
        let invalid = |what: String| CalibFileError::Invalid {
            path: path.to_path_buf(),
            what,
        };
        if self.rigcal_calibration != SCHEMA_VERSION {
            return Err(invalid(format!(
                "rigcal_calibration is {}, this version reads {SCHEMA_VERSION}",
                self.rigcal_calibration
            )));
        }
        if let Some(why) = name_problem(&self.vehicle_frame) {
            return Err(invalid(format!(
                "vehicle_frame {why}; every export names the frame the extrinsics map into"
            )));
        }
        let mut sensors: Vec<Sensor> = Vec::with_capacity(self.sensors.len());
        for s in &self.sensors {
            if s.name.is_empty() {
                return Err(invalid("a sensor has an empty name".into()));
            }
            if let Some(why) = name_problem(&s.name) {
                return Err(invalid(format!("sensor name {:?} {why}", s.name)));
            }
            if !s.frame_id.is_empty()
                && let Some(why) = name_problem(&s.frame_id)
            {
                return Err(invalid(format!("sensor '{}': frame_id {why}", s.name)));
            }
            if sensors.iter().any(|o| o.name == s.name) {
                return Err(invalid(format!("sensor name '{}' appears twice", s.name)));
            }
            let vehicle_from_sensor = s
                .vehicle_from_sensor
                .to_rigid()
                .map_err(|e| invalid(format!("sensor '{}': {e}", s.name)))?;
            let offset_m = vehicle_from_sensor.translation.length();
            if offset_m > MAX_SENSOR_OFFSET_M {
                return Err(invalid(format!(
                    "sensor '{}' is {offset_m:.3e} m from the vehicle frame; a sensor on a vehicle is within {MAX_SENSOR_OFFSET_M} m (translation_m is in metres)",
                    s.name
                )));
            }
            if s.kind == SensorKind::Camera {
                match &s.camera {
                    None => {
                        return Err(invalid(format!("camera '{}' has no camera: block", s.name)));
                    }
                    Some(c) => c
                        .validate()
                        .map_err(|e| invalid(format!("camera '{}': {e}", s.name)))?,
                }
            } else if s.camera.is_some() {
                // Intrinsics on a LiDAR are a sensor of the wrong kind, not data to carry.
                return Err(invalid(format!(
                    "sensor '{}' is a {} with a camera: block (is its kind wrong?)",
                    s.name,
                    s.kind.as_str()
                )));
            }
            sensors.push(Sensor {
                name: s.name.clone(),
                kind: s.kind,
                frame_id: if s.frame_id.is_empty() {
                    s.name.clone()
                } else {
                    s.frame_id.clone()
                },
                topics: s.topics.clone(),
                vehicle_from_sensor,
                camera: s.camera.clone(),
            });
        }
        // Every exported TF tree names sensors by frame: two sensors on one frame would be one
        // node with two parents' worth of transforms.
        for (i, s) in sensors.iter().enumerate() {
            if let Some(o) = sensors[..i].iter().find(|o| o.frame_id == s.frame_id) {
                return Err(invalid(format!(
                    "sensors '{}' and '{}' have the same frame_id '{}'",
                    o.name, s.name, s.frame_id
                )));
            }
        }
        Ok(Rig {
            vehicle_frame: self.vehicle_frame.clone(),
            sensors,
        })
    }

    pub fn parse(text: &str, path: &Path) -> Result<Self, CalibFileError> {
        super::yaml::from_str(text).map_err(|source| CalibFileError::Parse {
            path: path.to_path_buf(),
            source,
        })
    }

    pub fn load(path: &Path) -> Result<Self, CalibFileError> {
        let text = std::fs::read_to_string(path).map_err(|source| CalibFileError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let file = Self::parse(&text, path)?;
        file.to_rig(path)?; // validate once, on load
        Ok(file)
    }

    /// Load and convert to a rig in one step.
    pub fn load_rig(path: &Path) -> Result<Rig, CalibFileError> {
        Self::load(path)?.to_rig(path)
    }

    pub fn to_yaml(&self) -> String {
        // Serialising plain data with string keys cannot fail.
        serde_yaml::to_string(self).unwrap_or_default()
    }

    pub fn save(&self, path: &Path) -> Result<(), CalibFileError> {
        crate::util::write_atomic(path, self.to_yaml().as_bytes()).map_err(|source| {
            CalibFileError::Write {
                path: path.to_path_buf(),
                source,
            }
        })
    }
}

/// Why `name` (a frame id or sensor name) cannot go into the exports' TF trees, URDF links and
/// file names, if it cannot: it is empty or blank, starts or ends with white space, or holds a
/// control character (a line break would end a line of every text export).
fn name_problem(name: &str) -> Option<&'static str> {
    if name.trim().is_empty() {
        Some("is empty")
    } else if name.trim() != name {
        Some("starts or ends with white space")
    } else if name.chars().any(char::is_control) {
        Some("holds a control character (a line break or tab)")
    } else {
        None
    }
}

/// `name` as the calibration file accepts it (`name_problem`): trimmed, each control
/// character replaced by `_`. Empty stays empty.
pub fn exportable_name(name: &str) -> String {
    name.trim()
        .chars()
        .map(|c| if c.is_control() { '_' } else { c })
        .collect()
}

/// The farthest a sensor may sit from the vehicle frame (m): a larger translation is a unit
/// slip (millimetres read as metres) or a corrupt value.
pub const MAX_SENSOR_OFFSET_M: f64 = 1000.0;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::so3;

    pub(crate) fn sample_rig() -> Rig {
        Rig {
            vehicle_frame: "base_link".into(),
            sensors: vec![
                Sensor {
                    name: "lidar_top".into(),
                    kind: SensorKind::Lidar,
                    frame_id: "lidar_top".into(),
                    topics: vec!["/lidar_top/points".into()],
                    vehicle_from_sensor: Rigid::new(
                        so3::exp(DVec3::new(0.01, -0.02, 1.5)),
                        DVec3::new(1.0, 0.0, 1.8),
                    ),
                    camera: None,
                },
                Sensor {
                    name: "front_camera".into(),
                    kind: SensorKind::Camera,
                    frame_id: "front_camera".into(),
                    topics: vec!["/front_camera/image/compressed".into()],
                    vehicle_from_sensor: Rigid::new(
                        DQuat::from_xyzw(-0.5, 0.5, -0.5, 0.5),
                        DVec3::new(1.5, 0.0, 1.5),
                    ),
                    camera: Some(CameraIntrinsics::pinhole(
                        1920, 1080, 1970.0, 1970.5, 970.2, 483.1,
                    )),
                },
            ],
        }
    }

    #[test]
    fn round_trip_through_yaml() {
        let rig = sample_rig();
        let file = CalibrationFile::from_rig(&rig);
        let text = file.to_yaml();
        assert!(text.starts_with("rigcal_calibration: 1\n"), "{text}");
        let back = CalibrationFile::parse(&text, Path::new("x.yaml")).unwrap();
        assert_eq!(back, file);
        let rig_back = back.to_rig(Path::new("x.yaml")).unwrap();
        for (a, b) in rig.sensors.iter().zip(&rig_back.sensors) {
            let (r, t) = a.vehicle_from_sensor.difference(b.vehicle_from_sensor);
            assert!(r < 1e-15 && t < 1e-15);
            assert_eq!(a.camera, b.camera);
        }
    }

    #[test]
    fn save_and_load() {
        let dir = std::env::temp_dir().join(format!("rigcal-calib-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("calib.yaml");
        CalibrationFile::from_rig(&sample_rig())
            .save(&path)
            .unwrap();
        let rig = CalibrationFile::load_rig(&path).unwrap();
        assert_eq!(rig.sensors.len(), 2);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_files_name_the_file_and_the_problem() {
        let p = Path::new("bad.yaml");
        let err = CalibrationFile::parse("rigcal_calibration: [", p)
            .unwrap_err()
            .to_string();
        assert!(err.contains("bad.yaml"), "{err}");
        let mut file = CalibrationFile::from_rig(&sample_rig());
        file.sensors[0].vehicle_from_sensor.rotation_xyzw = [0.0, 0.0, 0.0, 2.0];
        let err = file.to_rig(p).unwrap_err().to_string();
        assert!(
            err.contains("bad.yaml") && err.contains("lidar_top") && err.contains("norm"),
            "{err}"
        );
        // A LiDAR with intrinsics: a sensor of the wrong kind.
        let mut file = CalibrationFile::from_rig(&sample_rig());
        let camera = file.sensors.iter().find_map(|s| s.camera.clone());
        let lidar = file
            .sensors
            .iter_mut()
            .find(|s| s.kind == SensorKind::Lidar);
        lidar.unwrap().camera = camera;
        let err = file.to_rig(p).unwrap_err().to_string();
        assert!(
            err.contains("lidar_top") && err.contains("camera: block"),
            "{err}"
        );
        let mut file = CalibrationFile::from_rig(&sample_rig());
        file.sensors[1].name = "lidar_top".into();
        assert!(file.to_rig(p).unwrap_err().to_string().contains("twice"));
        let mut file = CalibrationFile::from_rig(&sample_rig());
        file.sensors[1].frame_id = file.sensors[0].frame_id.clone();
        let err = file.to_rig(p).unwrap_err().to_string();
        assert!(err.contains("same frame_id"), "{err}");
        for bad in [f64::NAN, f64::INFINITY, 0.0] {
            let mut file = CalibrationFile::from_rig(&sample_rig());
            let cam = file
                .sensors
                .iter_mut()
                .find(|s| s.camera.is_some())
                .unwrap();
            let name = cam.name.clone();
            cam.camera.as_mut().unwrap().fx = bad;
            let err = file.to_rig(p).unwrap_err().to_string();
            assert!(err.contains(&name) && err.contains("focal"), "{err}");
        }
        let mut file = CalibrationFile::from_rig(&sample_rig());
        let cam = file
            .sensors
            .iter_mut()
            .find(|s| s.camera.is_some())
            .unwrap();
        cam.camera.as_mut().unwrap().cy = f64::NAN;
        assert!(
            file.to_rig(p)
                .unwrap_err()
                .to_string()
                .contains("principal point")
        );
        let mut file = CalibrationFile::from_rig(&sample_rig());
        file.rigcal_calibration = 2;
        assert!(file.to_rig(p).is_err());
        // Names that exports cannot carry: an empty or blank vehicle frame, a line break in a
        // frame id, white space around a sensor's name.
        for (vehicle, frame, name, says) in [
            ("", "lidar_top", "lidar_top", "vehicle_frame is empty"),
            ("  ", "lidar_top", "lidar_top", "vehicle_frame is empty"),
            (
                "base_link",
                "lidar\ntop",
                "lidar_top",
                "frame_id holds a control character",
            ),
            (
                "base_link",
                "lidar_top",
                " lidar_top",
                "starts or ends with white space",
            ),
        ] {
            let mut file = CalibrationFile::from_rig(&sample_rig());
            file.vehicle_frame = vehicle.into();
            file.sensors[0].frame_id = frame.into();
            file.sensors[0].name = name.into();
            let err = file.to_rig(p).unwrap_err().to_string();
            assert!(err.contains("bad.yaml") && err.contains(says), "{err}");
        }
        let err = CalibrationFile::load(Path::new("/nonexistent/c.yaml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("/nonexistent/c.yaml"));
        // A sensor kilometres off, brackets nested thousands deep.
        let mut file = CalibrationFile::from_rig(&sample_rig());
        file.sensors[0].vehicle_from_sensor.translation_m = [1e308, 0.0, 0.0];
        let err = file.to_rig(p).unwrap_err().to_string();
        assert!(err.contains("within 1000 m"), "{err}");
        let deep = format!("ignored: {}{}\n", "[".repeat(5000), "]".repeat(5000));
        let started = std::time::Instant::now();
        let err = CalibrationFile::parse(&deep, p).unwrap_err().to_string();
        assert!(
            err.contains("nested 5000 deep") && err.contains("bad.yaml"),
            "{err}"
        );
        assert!(started.elapsed().as_secs_f64() < 1.0);
        // Quoted brackets and comments do not count; a byte-order mark is read past.
        let text = format!(
            "\u{feff}{}",
            CalibrationFile::from_rig(&sample_rig()).to_yaml()
        );
        let text = text.replace("vehicle_frame:", "# [[[[ a comment\nvehicle_frame:");
        assert!(CalibrationFile::parse(&text, p).unwrap().to_rig(p).is_ok());
    }

    #[test]
    fn reads_the_documented_example_layout() {
        let text = r#"
rigcal_calibration: 1
vehicle_frame: base_link
sensors:
  - name: front_camera
    kind: camera
    frame_id: front_camera
    topics: [/front_camera/image/compressed, /front_camera/camera_info]
    vehicle_from_sensor:
      translation_m: [1.0, 2.0, 3.0]
      rotation_xyzw: [0.0, 0.0, 0.0, 1.0]
      roll_pitch_yaw_rad: [0, 0, 0]
      matrix: [[1, 0, 0, 1], [0, 1, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]]
    camera:
      width: 1920
      height: 1080
      model: plumb_bob
      fx: 1000.0
      fy: 1000.0
      cx: 960.0
      cy: 540.0
      distortion: [0.1, -0.01, 0.0, 0.0, 0.0]
provenance:
  method: unical
metrics:
  loss: 0.5
"#;
        let rig = CalibrationFile::parse(text, Path::new("doc.yaml"))
            .unwrap()
            .to_rig(Path::new("doc.yaml"))
            .unwrap();
        let cam = rig.sensor("front_camera").unwrap();
        assert_eq!(
            cam.vehicle_from_sensor.translation,
            DVec3::new(1.0, 2.0, 3.0)
        );
        assert_eq!(
            cam.camera.as_ref().unwrap().model,
            crate::geometry::camera::CameraModel::PlumbBob
        );
    }
}
