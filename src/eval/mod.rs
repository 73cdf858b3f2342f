//! Evaluation: metrics that tell how well a calibration aligns the sensors.

pub mod checkerboard;
pub mod edges;
pub mod fast;
pub mod photometric;
pub mod registration;
