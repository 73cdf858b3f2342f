//! Point-to-plane ICP as a [`Calibrator`]: every LiDAR against one reference LiDAR (which stays
//! fixed), on sweeps spread over the drive or its selected segments. For each source sweep the
//! reference's sweeps nearest in time (the nearest and its two neighbours) form the target, all
//! deskewed with the trajectory at each point's firing time; one step is one Gauss–Newton step
//! of every pair ([`super::icp`]).

use crate::error::RunError;
use glam::DVec3;

use super::icp::{IcpConfig, IcpProblem, SourcePoint};
use crate::calib::Rig;
use crate::geometry::Rigid;
use crate::geometry::projection::world_points;
use crate::log::{Drive, LidarSweep, spread_evenly};
use crate::optim::runner::{Calibrator, StepReport};

pub struct IcpCalibrator {
    rig: Rig,
    problems: Vec<(String, IcpProblem)>,
    max_steps: usize,
}

/// Every `stride`-th point of `sweep` in its own frame with the vehicle pose at its firing time.
pub fn source_points(
    sweep: &LidarSweep,
    trajectory: &crate::geometry::Trajectory,
    stride: usize,
) -> Vec<SourcePoint> {
    (0..sweep.points_in_sensor.len())
        .step_by(stride.max(1))
        .filter_map(|i| {
            let offset = sweep
                .time_offset_secs
                .as_ref()
                .and_then(|t| t.get(i))
                .map_or(0, |s| (*s as f64 * 1e9) as i64);
            let p = sweep.points_in_sensor[i];
            Some(SourcePoint {
                in_sensor: DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64),
                world_from_vehicle: trajectory
                    .world_from_vehicle(sweep.stamp_nanos + offset)
                    .ok()?,
            })
        })
        .collect()
}

/// The target of one source sweep stamped `stamp_nanos`: the `reference` LiDAR's sweep among
/// `frames` nearest in time and its two neighbours, in the world (each return at its firing
/// time, the reference at `vehicle_from_reference`). Empty without such sweeps.
pub fn reference_points_near(
    drive: &Drive,
    reference: &str,
    vehicle_from_reference: Rigid,
    frames: &[usize],
    stamp_nanos: i64,
) -> Result<Vec<DVec3>, RunError> {
    let Some(stream) = drive.stream(reference) else {
        return Ok(Vec::new());
    };
    let Some(nearest) = (0..frames.len())
        .min_by_key(|&k| (stream.frames[frames[k]].stamp_nanos - stamp_nanos).abs())
    else {
        return Ok(Vec::new());
    };
    let mut out = Vec::new();
    for &j in &frames[nearest.saturating_sub(1)..(nearest + 2).min(frames.len())] {
        let Some(t) = drive.sweep_or_skip(reference, j) else {
            continue;
        };
        out.extend(
            world_points(&t.view(), &drive.trajectory, vehicle_from_reference, 1)
                .map_err(|e| RunError::from(e).within(reference))?,
        );
    }
    Ok(out)
}

impl IcpCalibrator {
    /// Register every LiDAR of `rig` but `reference` against it on `frames` sweeps each.
    pub fn from_drive(
        drive: &Drive,
        rig: &Rig,
        reference: &str,
        frames: usize,
        segments_nanos: &[(i64, i64)],
        config: IcpConfig,
    ) -> Result<Self, RunError> {
        let fixed = rig
            .sensor(reference)
            .ok_or_else(|| RunError::no_sensor("LiDAR", reference))?
            .vehicle_from_sensor;
        let targets = drive.frames_within(reference, segments_nanos);
        if drive.stream(reference).is_none() {
            return Err(RunError::NotEnoughData(format!(
                "no sweeps of '{reference}' in {}",
                drive.path().display()
            )));
        }
        let mut problems = Vec::new();
        for lidar in rig.lidars().filter(|l| l.name != reference) {
            let Some(stream) = drive.stream(&lidar.name) else {
                continue;
            };
            let mut target = Vec::new();
            let mut source = Vec::new();
            for i in spread_evenly(&drive.frames_within(&lidar.name, segments_nanos), frames) {
                let Some(sweep) = drive.sweep_or_skip(&lidar.name, i) else {
                    continue;
                };
                source.extend(source_points(&sweep, &drive.trajectory, 1));
                target.extend(reference_points_near(
                    drive,
                    reference,
                    fixed,
                    &targets,
                    stream.frames[i].stamp_nanos,
                )?);
            }
            if source.is_empty() || target.is_empty() {
                continue;
            }
            let problem =
                IcpProblem::new(&target, &source, lidar.vehicle_from_sensor, config.clone());
            problems.push((lidar.name.clone(), problem));
        }
        if problems.is_empty() {
            return Err(RunError::NotEnoughData(format!(
                "no LiDAR to register against '{reference}' inside the trajectory and the selected segments"
            )));
        }
        let max_steps = config.levels.len() * config.iterations_per_level;
        Ok(Self {
            rig: rig.clone(),
            problems,
            max_steps,
        })
    }

    /// Each registered LiDAR's problem.
    pub fn problems(&self) -> &[(String, IcpProblem)] {
        &self.problems
    }

    fn rig_now(&self) -> Rig {
        let mut rig = self.rig.clone();
        for (name, p) in &self.problems {
            if let Some(s) = rig.sensor_mut(name) {
                s.vehicle_from_sensor = p.vehicle_from_source;
            }
        }
        rig
    }
}

impl Calibrator for IcpCalibrator {
    fn name(&self) -> &str {
        "point-to-plane ICP"
    }

    fn max_steps(&self) -> usize {
        self.max_steps
    }

    fn step(&mut self) -> StepReport {
        let mut losses = Vec::new();
        for (name, p) in &mut self.problems {
            let s = p.step();
            losses.push((format!("icp rmse cm/{name}"), s.inlier_rmse_m * 100.0));
            losses.push((format!("icp fitness/{name}"), s.fitness));
        }
        StepReport {
            losses,
            done: self.problems.iter().all(|(_, p)| p.done),
        }
    }

    fn current(&self) -> Rig {
        self.rig_now()
    }

    fn best(&self) -> Rig {
        self.rig_now()
    }
}
