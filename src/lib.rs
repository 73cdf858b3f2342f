//! # rigcal
//!
//! Joint extrinsic calibration of every LiDAR and camera on a vehicle from an ordinary drive,
//! after UniCal (Yang et al., ECCV 2024).
//!
//! The library is GUI-free: the desktop studio lives behind the default `app` feature and only
//! consumes what the library exposes. Module map (see `ARCHITECTURE.md`):
//!
//! - [`geometry`]: rigid transforms named `a_from_b`, SO(3) exp/log, the 6D rotation
//!   representation, trajectory interpolation, rig-error metrics and camera models.
//! - [`calib`]: the rig model (sensors with intrinsics and `vehicle_from_sensor`) and the native
//!   calibration file (`rigcal_calibration: 1`, see `docs/interfaces.md`).
//! - [`log`]: MCAP ingestion (ROS 2 CDR and Foxglove schemas), TF tree resolution and the
//!   indexed, lazily decoded drive log.
//! - [`interop`]: export to and import from the formats other tools read (URDF, ROS, Autoware,
//!   OpenCV, Kalibr, KITTI, nuScenes, MCAP /tf_static).
//! - [`pipeline`]: the automatic pipeline (plan, stages, confidence report) every front end runs.
//! - [`error`]: the shared errors of a run on a drive and of a value a user typed.
//! - [`util`]: atomic file writes and small helpers shared by every module.

pub mod bench;
pub mod calib;
pub mod classical;
pub mod cli;
pub mod error;
pub mod eval;
pub mod features;
pub mod geometry;
pub mod interop;
pub mod log;
pub mod optim;
pub mod pipeline;
pub mod session;
pub mod sim;
pub mod unical;
pub mod util;

pub use error::{ParseError, RunError};

#[cfg(feature = "app")]
pub mod app;
