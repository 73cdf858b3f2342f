//! UniCal as a [`Calibrator`] for the studio and the runner: the LiDAR stage
//! ([`DepthCalibration`]: one neural scene and every LiDAR extrinsic, learned jointly from LiDAR
//! depth) prepared from a drive. Cameras are not optimised by this stage yet.
//!
//! The objective is stochastic (random rays per step) and the scene keeps improving, so the
//! "best" rig is the latest one rather than the lowest single-step loss.

use super::depth_calib::{DepthCalibConfig, DepthCalibration, LidarData};
use crate::calib::Rig;
use crate::log::{Drive, spread_evenly};
use crate::optim::runner::{Calibrator, StepReport};

pub struct UnicalLidarStage {
    calib: DepthCalibration,
    rig: Rig,
}

impl UnicalLidarStage {
    /// Take `sweeps_per_lidar` sweeps of every LiDAR, spread over `segments_nanos` (empty: the
    /// whole drive) and inside the trajectory, starting from `rig`'s extrinsics.
    pub fn from_drive(
        drive: &Drive,
        rig: &Rig,
        sweeps_per_lidar: usize,
        segments_nanos: &[(i64, i64)],
        config: DepthCalibConfig,
    ) -> Result<Self, String> {
        let mut lidars = Vec::new();
        for lidar in rig.lidars() {
            let usable = drive.frames_within(&lidar.name, segments_nanos);
            if usable.is_empty() {
                continue;
            }
            let sweeps = spread_evenly(&usable, sweeps_per_lidar)
                .into_iter()
                .map(|i| drive.load_sweep(&lidar.name, i).map_err(|e| e.to_string()))
                .collect::<Result<Vec<_>, _>>()?;
            lidars.push(LidarData {
                name: lidar.name.clone(),
                initial: lidar.vehicle_from_sensor,
                sweeps,
            });
        }
        if lidars.is_empty() {
            return Err("no LiDAR sweeps inside the trajectory and the selected segments".into());
        }
        Ok(Self {
            calib: DepthCalibration::new(config, drive.trajectory.clone(), lidars),
            rig: rig.clone(),
        })
    }

    fn rig_now(&self) -> Rig {
        let mut rig = self.rig.clone();
        for (name, t) in self.calib.extrinsics() {
            if let Some(s) = rig.sensor_mut(&name) {
                s.vehicle_from_sensor = t;
            }
        }
        rig
    }
}

impl Calibrator for UnicalLidarStage {
    fn name(&self) -> &str {
        "UniCal (LiDAR depth stage)"
    }

    fn max_steps(&self) -> usize {
        self.calib.config.iterations
    }

    fn step(&mut self) -> StepReport {
        let r = self.calib.step();
        StepReport {
            losses: vec![
                ("depth loss".into(), r.loss),
                ("|depth error| m".into(), r.mean_abs_error_m),
            ],
            done: self.calib.iteration >= self.calib.config.iterations,
        }
    }

    fn current(&self) -> Rig {
        self.rig_now()
    }

    fn best(&self) -> Rig {
        self.rig_now()
    }
}
