//! Edge-and-plane checkerboard calibration as a [`Calibrator`]: every selected camera against
//! one reference LiDAR (which stays fixed), each by its own Levenberg–Marquardt search
//! ([`super::target`]); the cameras step in parallel. Cameras that see no board with the LiDAR
//! are reported by name when the run is prepared.

use crate::error::RunError;
use rayon::prelude::*;

use super::target::{BoardCache, TargetConfig, TargetProblem, TargetSearch, TargetSolution};
use crate::calib::Rig;
use crate::log::Drive;
use crate::optim::runner::{Calibrator, StepReport};

pub struct TargetCalibrator {
    rig: Rig,
    /// Cameras that could not be set up, with the reason.
    pub skipped: Vec<String>,
    problems: Vec<(TargetProblem, TargetSearch)>,
    max_steps: usize,
}

impl TargetCalibrator {
    /// Prepare `cameras` against `lidar` (within `segments_nanos`; empty: the whole drive), the
    /// cameras' boards taken from (and added to) `boards`.
    pub fn from_drive(
        drive: &Drive,
        rig: &Rig,
        lidar: &str,
        cameras: &[String],
        segments_nanos: &[(i64, i64)],
        config: TargetConfig,
        boards: &BoardCache,
    ) -> Result<Self, RunError> {
        let problems = cameras
            .par_iter()
            .map(|cam| {
                let p = TargetProblem::from_drive(
                    drive,
                    rig,
                    cam,
                    lidar,
                    segments_nanos,
                    &config,
                    boards,
                )
                .map_err(|e| RunError::from(e).within(format!("{cam} × {lidar}")))?;
                let start = rig
                    .sensor(cam)
                    .map(|s| s.vehicle_from_sensor)
                    .ok_or_else(|| RunError::no_sensor("camera", cam))?;
                let search = TargetSearch::new(&p, start);
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

    /// Each camera's problem (boards, views).
    pub fn problems(&self) -> impl Iterator<Item = &TargetProblem> {
        self.problems.iter().map(|(p, _)| p)
    }

    /// Each camera's solution at the current state (information matrices for pose graphs).
    pub fn solutions(&self) -> Vec<(String, String, TargetSolution)> {
        self.problems
            .iter()
            .map(|(p, s)| (p.camera.clone(), p.lidar.clone(), s.solution(p)))
            .collect()
    }

    fn losses(&self) -> Vec<(String, f64)> {
        let mut out = Vec::new();
        let mut sum = 0.0;
        for (p, s) in &self.problems {
            let solution = s.solution(p);
            let cm = 100.0 * (solution.plane_rms_m.powi(2) + solution.border_rms_m.powi(2)).sqrt();
            sum += cm;
            out.push((format!("target_rms_cm/{}", p.camera), cm));
        }
        out.insert(
            0,
            (
                "target_rms_cm (mean)".into(),
                sum / self.problems.len().max(1) as f64,
            ),
        );
        out
    }
}

impl Calibrator for TargetCalibrator {
    fn name(&self) -> &str {
        "checkerboard edges and planes"
    }

    fn max_steps(&self) -> usize {
        self.max_steps
    }

    fn step(&mut self) -> StepReport {
        self.problems.par_iter_mut().for_each(|(p, s)| {
            s.step(p);
        });
        for (p, s) in &self.problems {
            if let Some(sensor) = self.rig.sensor_mut(&p.camera) {
                sensor.vehicle_from_sensor = s.camera_from_vehicle.inverse();
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
        // Steps are accepted only when the cost drops: current is the best.
        self.rig.clone()
    }
}
