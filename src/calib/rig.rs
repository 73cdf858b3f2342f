//! Sensors and rigs: names, frames, topics, intrinsics and `vehicle_from_sensor`.

use serde::{Deserialize, Serialize};

use crate::geometry::Rigid;
use crate::geometry::camera::CameraIntrinsics;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SensorKind {
    Camera,
    Lidar,
}

impl SensorKind {
    pub fn as_str(self) -> &'static str {
        match self {
            SensorKind::Camera => "camera",
            SensorKind::Lidar => "lidar",
        }
    }
}

/// One sensor of the rig.
#[derive(Clone, Debug, PartialEq)]
pub struct Sensor {
    /// Unique name; matches the frame id unless told otherwise.
    pub name: String,
    pub kind: SensorKind,
    pub frame_id: String,
    pub topics: Vec<String>,
    /// `p_vehicle = vehicle_from_sensor * p_sensor`.
    pub vehicle_from_sensor: Rigid,
    /// Cameras only; the camera frame is the OpenCV optical frame.
    pub camera: Option<CameraIntrinsics>,
}

/// A vehicle frame and the sensors mounted on it.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Rig {
    pub vehicle_frame: String,
    pub sensors: Vec<Sensor>,
}

impl Rig {
    pub fn sensor(&self, name: &str) -> Option<&Sensor> {
        self.sensors.iter().find(|s| s.name == name)
    }

    pub fn sensor_mut(&mut self, name: &str) -> Option<&mut Sensor> {
        self.sensors.iter_mut().find(|s| s.name == name)
    }

    pub fn cameras(&self) -> impl Iterator<Item = &Sensor> {
        self.sensors.iter().filter(|s| s.kind == SensorKind::Camera)
    }

    pub fn lidars(&self) -> impl Iterator<Item = &Sensor> {
        self.sensors.iter().filter(|s| s.kind == SensorKind::Lidar)
    }

    /// `(name, vehicle_from_sensor)` pairs, the input of [`crate::geometry::rig_errors`].
    pub fn extrinsics(&self) -> Vec<(String, Rigid)> {
        self.sensors
            .iter()
            .map(|s| (s.name.clone(), s.vehicle_from_sensor))
            .collect()
    }
}
