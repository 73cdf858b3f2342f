//! The library's shared errors: [`RunError`] for setting up and running a calibration or an
//! evaluation on a drive, and [`ParseError`] for a value typed by a user (a transform, a segment,
//! a duration, a readout, a setting).
//!
//! Modules with errors of their own keep them beside their code ([`crate::log::LogError`] for a
//! bad file, [`crate::interop::ExportError`] and [`crate::interop::ImportError`] for other tools'
//! formats, [`crate::calib::CalibFileError`] for the native file); a [`RunError`] wraps the log's
//! with `?`. Every message names what it is about (the sensor, the file, the value), so a front end
//! prints it as it is.

use std::path::PathBuf;

use thiserror::Error;

use crate::classical::hand_eye::HandEyeError;
use crate::classical::pose_graph::PoseGraphError;
use crate::geometry::TrajectoryError;
use crate::log::LogError;
use crate::optim::edge_align::AlignError;
use crate::pipeline::plan::PlanError;

/// Why a calibration, a check or an evaluation cannot run on a drive.
#[derive(Debug, Error)]
pub enum RunError {
    /// The log, or a frame of it, could not be read.
    #[error(transparent)]
    Log(#[from] LogError),
    /// A stamp outside the vehicle's trajectory, or no trajectory.
    #[error("trajectory: {0}")]
    Trajectory(#[from] TrajectoryError),
    /// A LiDAR–camera alignment problem that could not be set up.
    #[error(transparent)]
    Align(#[from] AlignError),
    /// A hand-eye fit of a camera's motion to the vehicle's.
    #[error(transparent)]
    HandEye(#[from] HandEyeError),
    /// A pose graph that could not be built.
    #[error(transparent)]
    PoseGraph(#[from] PoseGraphError),
    /// The pipeline could not plan a run on this drive.
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// A sensor the run was asked about is not in the rig (or not of the kind it needs).
    #[error("no {kind} '{name}' in the rig")]
    NoSensor { kind: &'static str, name: String },
    /// The drive holds too little of what the method needs (frames, motion, matches, poses).
    #[error("{0}")]
    NotEnoughData(String),
    /// A setting or a request outside what the method accepts.
    #[error("{0}")]
    Invalid(String),
    /// A file the run reads or writes beside the log (a cache, a report, a plot).
    #[error("{path}: {what}")]
    File { path: PathBuf, what: String },
    /// `context` gave the error `source`, e.g. a camera–LiDAR pair or a stage.
    #[error("{context}: {source}")]
    In {
        context: String,
        source: Box<RunError>,
    },
}

impl RunError {
    /// `self`, said of `context` ("front_camera × pandar64: …").
    pub fn within(self, context: impl Into<String>) -> Self {
        Self::In {
            context: context.into(),
            source: Box::new(self),
        }
    }

    pub fn no_sensor(kind: &'static str, name: &str) -> Self {
        Self::NoSensor {
            kind,
            name: name.to_owned(),
        }
    }

    /// The innermost error, past every [`RunError::In`].
    pub fn root(&self) -> &RunError {
        match self {
            Self::In { source, .. } => source.root(),
            other => other,
        }
    }
}

/// A value a user typed that does not parse; the message names the value and what was expected.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
#[error("{0}")]
pub struct ParseError(String);

impl ParseError {
    pub fn new(what: impl Into<String>) -> Self {
        Self(what.into())
    }
}

impl From<String> for ParseError {
    fn from(what: String) -> Self {
        Self(what)
    }
}

impl From<&str> for ParseError {
    fn from(what: &str) -> Self {
        Self(what.to_owned())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn context_reads_outside_in_and_root_finds_the_cause() {
        let e = RunError::no_sensor("camera", "left").within("hand-eye");
        assert_eq!(e.to_string(), "hand-eye: no camera 'left' in the rig");
        assert!(matches!(e.root(), RunError::NoSensor { name, .. } if name == "left"));
    }
}
