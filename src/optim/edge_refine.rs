//! The edge-alignment refinement as a [`Calibrator`]: every selected camera is refined against
//! one reference LiDAR by its own compass search ([`super::edge_align`]); the LiDAR stays fixed.

use crate::calib::Rig;
use crate::log::Drive;

use super::edge_align::{AlignError, CompassSearch, EdgeAlignment};
use super::runner::{Calibrator, StepReport};

pub struct EdgeRefiner {
    rig: Rig,
    problems: Vec<(EdgeAlignment, CompassSearch)>,
    max_steps: usize,
}

impl EdgeRefiner {
    /// Refine `cameras` against `lidar` on `frames` frames each, with the cameras read out as
    /// `readout` (usually the drive's, [`crate::log::Drive::camera_readout`]).
    pub fn new(
        drive: &Drive,
        rig: &Rig,
        (lidar, cameras): (&str, &[String]),
        frames: usize,
        segments_nanos: &[(i64, i64)],
        readout: crate::geometry::RowTimes,
    ) -> Result<Self, AlignError> {
        let mut problems = Vec::new();
        for cam in cameras {
            let p = EdgeAlignment::from_drive(
                drive,
                rig,
                (cam, lidar),
                frames,
                segments_nanos,
                readout,
            )?;
            let start = rig
                .sensor(cam)
                .map(|s| s.vehicle_from_sensor)
                .ok_or_else(|| AlignError::Setup(format!("no sensor '{cam}'")))?;
            // Rotation only: a search in six degrees of freedom (0.3 m trust region) was
            // measured on the real logs and not kept (docs/experiments/real-camera-methods.md).
            let search = CompassSearch::new(&p, start);
            problems.push((p, search));
        }
        if problems.is_empty() {
            return Err(AlignError::Setup("no camera selected".into()));
        }
        Ok(Self::from_problems(rig.clone(), problems))
    }

    pub fn from_problems(rig: Rig, problems: Vec<(EdgeAlignment, CompassSearch)>) -> Self {
        Self {
            rig,
            problems,
            max_steps: 300,
        }
    }

    /// Stop after at most `steps` steps (default 300).
    pub fn with_max_steps(mut self, steps: usize) -> Self {
        self.max_steps = steps;
        self
    }

    fn losses(&self) -> Vec<(String, f64)> {
        let mut out: Vec<(String, f64)> = self
            .problems
            .iter()
            .map(|(p, s)| (format!("edge_px/{}", p.camera), s.best_cost))
            .collect();
        let mean = out.iter().map(|(_, v)| v).sum::<f64>() / out.len().max(1) as f64;
        out.insert(0, ("edge_px (mean)".into(), mean));
        out
    }
}

impl Calibrator for EdgeRefiner {
    fn name(&self) -> &str {
        "edge-align"
    }

    fn max_steps(&self) -> usize {
        self.max_steps
    }

    fn step(&mut self) -> StepReport {
        for (p, s) in &mut self.problems {
            if !s.converged() {
                s.step(p);
            }
        }
        for (p, s) in &self.problems {
            if let Some(sensor) = self.rig.sensor_mut(&p.camera) {
                sensor.vehicle_from_sensor = s.best;
            }
        }
        StepReport {
            losses: self.losses(),
            done: self.problems.iter().all(|(_, s)| s.converged()),
        }
    }

    fn current(&self) -> Rig {
        self.rig.clone()
    }

    fn best(&self) -> Rig {
        // The compass search only ever accepts improvements: current is the best.
        self.rig.clone()
    }
}
