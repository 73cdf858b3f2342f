//! The automatic pipeline: one command calibrates every LiDAR and camera of a drive.
//!
//! [`config::PipelineConfig`] is the whole configuration (one serde type, each default stated
//! once); [`plan::Plan::build`] decides from the data which stages run and says why;
//! [`run`] runs the stages before UniCal and builds UniCal's calibrator; [`report::Report`]
//! says per sensor how far it moved, which axes the drive observed and how sure the result is,
//! and keeps the initial guess where the data cannot decide; [`calibrator::PipelineCalibrator`]
//! is the whole pipeline as one steppable calibrator. The CLI (`rigcal calibrate`), the
//! studio ("Calibrate everything") and `bench` all go through these.

pub mod calibrator;
pub mod config;
pub mod edge_check;
pub mod mi_check;
pub mod plan;
pub mod report;
pub mod run;

pub use config::{PipelineConfig, Quality};
pub use plan::{Plan, PlanRequest, Stage};
pub use report::Report;
