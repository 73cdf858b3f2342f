//! UniCal as a [`Calibrator`] for the studio and the runner: [`DepthCalibration`] (one neural
//! scene and every LiDAR extrinsic, learned jointly from LiDAR depth, intensity and the SDF
//! regulariser) prepared from a drive;
//! with [`UnicalLidarStage::with_cameras`] the cameras join through the colour term (their
//! images downscaled, intrinsics scaled to match).
//!
//! The objective is stochastic (random rays per step) and the scene keeps improving, so the
//! "best" rig is the latest one rather than the lowest single-step loss.

use super::correspondences::training_keypoints;
use super::depth_calib::{CameraData, CameraFrame, DepthCalibConfig, DepthCalibration, LidarData};
use super::surface_align::AlignmentLoss;
use crate::calib::Rig;
use crate::log::{Drive, spread_evenly};
use crate::optim::runner::{Calibrator, StepReport};

/// What [`UnicalLidarStage::with_cameras_reporting`] reports while it loads images.
pub const LOADING_IMAGES: &str = "images and keypoints";
/// What it reports while it matches keypoints between frames.
pub const MATCHING: &str = "matching keypoints";

pub struct UnicalLidarStage {
    calib: DepthCalibration,
    rig: Rig,
    /// Rounds of `config.iterations` each, every one with a fresh scene
    /// ([`DepthCalibration::restart`]), and the current one.
    rounds: usize,
    round: usize,
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
            rounds: 1,
            round: 0,
        })
    }

    /// Add `frames_per_camera` images of every camera (spread over the segments), downscaled by
    /// `scale` (e.g. 0.125: 1920×1080 → 240×135), to the optimisation.
    pub fn with_cameras(
        self,
        drive: &Drive,
        frames_per_camera: usize,
        segments_nanos: &[(i64, i64)],
        scale: f64,
    ) -> Result<Self, String> {
        self.with_cameras_reporting(
            drive,
            frames_per_camera,
            segments_nanos,
            scale,
            &|_, _, _| {},
        )
    }

    /// [`UnicalLidarStage::with_cameras`], reporting its two slow parts as `(what, done, total)`:
    /// [`LOADING_IMAGES`] (images decoded and searched for keypoints) and [`MATCHING`]
    /// (candidate frame pairs matched; read back at once from the cache when there).
    pub fn with_cameras_reporting(
        mut self,
        drive: &Drive,
        frames_per_camera: usize,
        segments_nanos: &[(i64, i64)],
        scale: f64,
        report: &(dyn Fn(&str, usize, usize) + Sync),
    ) -> Result<Self, String> {
        if frames_per_camera == 0 {
            return Ok(self);
        }
        if !(scale > 0.0 && scale <= 1.0) {
            return Err(format!("camera image scale {scale} is not in (0, 1]"));
        }
        let with_keypoints = self.calib.config.alignment != AlignmentLoss::None;
        // Every camera with intrinsics and a stream, and the frames it contributes (counted
        // first, for the progress).
        let chosen: Vec<_> = self
            .rig
            .cameras()
            .filter_map(|cam| {
                let (intrinsics, stream) = (cam.camera.as_ref()?, drive.stream(&cam.name)?);
                let usable = drive.frames_within(&cam.name, segments_nanos);
                Some((
                    cam,
                    intrinsics,
                    stream,
                    spread_evenly(&usable, frames_per_camera),
                ))
            })
            .collect();
        let total: usize = chosen.iter().map(|c| c.3.len()).sum();
        let mut loaded = 0;
        report(LOADING_IMAGES, 0, total);
        let mut cameras = Vec::new();
        for (cam, intrinsics, stream, picked) in chosen {
            let small = intrinsics.scaled(scale);
            let mut frames = Vec::new();
            for i in picked {
                let img = drive.load_image(&cam.name, i).map_err(|e| e.to_string())?;
                let resized = image::imageops::resize(
                    img.as_ref(),
                    small.width.max(1),
                    small.height.max(1),
                    image::imageops::FilterType::Triangle,
                );
                let keypoints = if with_keypoints {
                    training_keypoints(img.as_ref(), small.width)
                } else {
                    Vec::new()
                };
                frames.push(CameraFrame {
                    stamp_nanos: stream.frames[i].stamp_nanos,
                    rgb: resized.into_raw(),
                    keypoints,
                });
                loaded += 1;
                report(LOADING_IMAGES, loaded, total);
            }
            if !frames.is_empty() {
                cameras.push(CameraData {
                    name: cam.name.clone(),
                    initial: cam.vehicle_from_sensor,
                    intrinsics: small,
                    frames,
                });
            }
        }
        self.calib = self
            .calib
            .with_cameras_reporting(cameras, &|done, total| report(MATCHING, done, total));
        Ok(self)
    }

    /// Run in `rounds` rounds of the configured iterations, each with a fresh scene formed
    /// at the extrinsics the previous one reached (at least 1).
    pub fn in_rounds(mut self, rounds: usize) -> Self {
        self.rounds = rounds.max(1);
        self
    }

    /// The optimisation itself (its scene can render cameras: `render_camera`).
    pub fn calibration(&self) -> &DepthCalibration {
        &self.calib
    }

    /// The optimisation, to step it directly (probes and benchmarks).
    pub fn calibration_mut(&mut self) -> &mut DepthCalibration {
        &mut self.calib
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
        if !self.calib.has_cameras() {
            "UniCal (LiDAR terms)"
        } else {
            "UniCal (LiDAR + camera terms)"
        }
    }

    fn max_steps(&self) -> usize {
        self.calib.config.iterations * self.rounds
    }

    fn step(&mut self) -> StepReport {
        if self.calib.iteration >= self.calib.config.iterations && self.round + 1 < self.rounds {
            self.calib.restart();
            self.round += 1;
        }
        let r = self.calib.step();
        let done =
            self.calib.iteration >= self.calib.config.iterations && self.round + 1 >= self.rounds;
        if let Some(loss) = r.geometry_init_loss {
            let mut losses = vec![("geometry init loss".into(), loss)];
            // Cameras released early follow the correspondence term during the initialisation.
            if r.alignment_matches > 0 {
                losses.push(("alignment px".into(), r.alignment_loss));
            }
            return StepReport { losses, done };
        }
        let mut losses = vec![
            ("depth loss".into(), r.loss),
            ("|depth error| m".into(), r.mean_abs_error_m),
        ];
        if self.calib.has_intensity() {
            losses.push(("intensity loss".into(), r.intensity_loss));
        }
        losses.push(("regulariser".into(), r.regulariser_loss));
        if self.calib.has_cameras() {
            losses.push(("colour loss".into(), r.colour_loss));
        }
        if !self.calib.correspondences.pairs.is_empty() {
            losses.push(("alignment px".into(), r.alignment_loss));
        }
        StepReport { losses, done }
    }

    fn current(&self) -> Rig {
        self.rig_now()
    }

    fn best(&self) -> Rig {
        self.rig_now()
    }
}
