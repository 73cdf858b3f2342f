//! Mutual information as a [`Calibrator`]: every selected camera against one reference LiDAR
//! (which stays fixed), each by its own bounded Barzilai–Borwein ascent ([`super::mutual_info`]);
//! the cameras step in parallel.

use crate::error::RunError;
use rayon::prelude::*;

use super::mutual_info::{MiConfig, MiProblem, MiSearch};
use crate::calib::Rig;
use crate::log::Drive;
use crate::optim::runner::{Calibrator, StepReport};

pub struct MiCalibrator {
    rig: Rig,
    /// Cameras that could not be set up, with the reason.
    pub skipped: Vec<String>,
    problems: Vec<(MiProblem, MiSearch)>,
    max_steps: usize,
}

impl MiCalibrator {
    /// Prepare `cameras` against `lidar` on `frames` frames each (within `segments_nanos`;
    /// empty: the whole drive).
    pub fn from_drive(
        drive: &Drive,
        rig: &Rig,
        lidar: &str,
        cameras: &[String],
        frames: usize,
        segments_nanos: &[(i64, i64)],
        config: MiConfig,
    ) -> Result<Self, RunError> {
        let problems = cameras
            .iter()
            .map(|cam| {
                let p =
                    MiProblem::from_drive(drive, rig, cam, lidar, frames, segments_nanos, &config)
                        .map_err(|e| RunError::from(e).within(format!("{cam} × {lidar}")))?;
                let start = rig
                    .sensor(cam)
                    .map(|s| s.vehicle_from_sensor)
                    .ok_or_else(|| RunError::no_sensor("camera", cam))?;
                let search = MiSearch::new(&p, start, &config);
                Ok((p, search))
            })
            .collect::<Vec<Result<_, RunError>>>();
        let (problems, skipped) = super::per_camera(problems)?;
        Ok(Self {
            rig: rig.clone(),
            problems,
            skipped,
            max_steps: config.iterations,
        })
    }

    /// The per-camera problems and searches (for tests and benchmarks).
    pub fn problems(&self) -> &[(MiProblem, MiSearch)] {
        &self.problems
    }

    fn losses(&self) -> Vec<(String, f64)> {
        let mut out: Vec<(String, f64)> = self
            .problems
            .iter()
            .map(|(p, s)| (format!("mi_nats/{}", p.camera), s.best_mi))
            .collect();
        let mean = out.iter().map(|(_, v)| v).sum::<f64>() / out.len().max(1) as f64;
        out.insert(0, ("mi_nats (mean, higher is better)".into(), mean));
        out
    }
}

impl Calibrator for MiCalibrator {
    fn name(&self) -> &str {
        "mutual-information"
    }

    fn max_steps(&self) -> usize {
        self.max_steps
    }

    fn step(&mut self) -> StepReport {
        self.problems.par_iter_mut().for_each(|(p, s)| s.step(p));
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

    /// A camera whose best pose sits on the search's bounds: the mutual information still rose
    /// towards the bound, so the result is where the search was stopped, not a maximum.
    fn failures(&self) -> Vec<(String, String)> {
        crate::optim::runner::bound_failures(
            "mutual information",
            self.problems
                .iter()
                .map(|(p, s)| (p.camera.as_str(), s.at_bounds())),
        )
    }

    fn best(&self) -> Rig {
        // Steps are accepted only when MI does not drop: current is the best.
        self.rig.clone()
    }
}
