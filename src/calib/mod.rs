//! The rig model and the native calibration file.
//!
//! A [`Rig`] is the set of named sensors with their intrinsics and `vehicle_from_sensor`; it is
//! what every calibrator reads as its initial guess and writes as its answer. [`file`](mod@file) reads and
//! writes it as the `rigcal_calibration: 1` YAML of `docs/interfaces.md`.

pub mod dataset_json;
pub mod file;
pub mod rig;
pub mod transform_text;
pub mod yaml;

pub use file::{CalibFileError, CalibrationFile};
pub use rig::{Rig, Sensor, SensorKind};
