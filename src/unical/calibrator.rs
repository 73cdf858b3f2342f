//! UniCal as a [`Calibrator`] for the studio and the runner: [`DepthCalibration`] (one neural
//! scene and every LiDAR extrinsic, learned jointly from LiDAR depth, intensity and the SDF
//! regulariser) prepared from a drive;
//! with [`UnicalLidarStage::with_cameras`] the cameras join through the colour term (their
//! images downscaled, intrinsics scaled to match).
//!
//! The objective is stochastic (random rays per step) and the scene keeps improving, so the
//! "best" rig is not the one of the lowest single-step loss but the latest iterates' mean
//! ([`super::pose_window`]; the latest iterate itself when averaging is off).

use super::correspondences::training_keypoints;
use super::depth_calib::{CameraData, CameraFrame, DepthCalibConfig, DepthCalibration, LidarData};
use super::masks::{ego_mask, is_masked, mark_traffic};
use super::pose_window::{PoseWindow, window_len};
use super::scene_bounds::{Kept, keep_near_drive};
use super::scene_sweeps;
use super::surface_align::AlignmentLoss;
use super::transient::{TransientStats, Witnesses, remove_transient};
use crate::calib::{Rig, Sensor};
use crate::error::RunError;
use crate::geometry::Rigid;
use crate::geometry::camera::CameraIntrinsics;
use crate::log::{Drive, SensorStream, spread_evenly};
use crate::optim::runner::{Calibrator, StepReport};
use glam::{DVec2, DVec3};
use std::collections::HashMap;

/// A camera frame is masked with the LiDAR sweeps at most this far from it in time.
pub const MASK_SWEEP_SECS: f64 = 0.1;
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
    /// The sweeps as loaded, for finding moving traffic in camera images, with each LiDAR's
    /// name and extrinsic in their order; and what was dropped from the sweeps.
    transient: Option<(Witnesses, Vec<(String, Rigid)>, TransientStats)>,
    /// Returns kept and dropped by `DepthCalibConfig::scene_radius_m` (`None`: not applied).
    scene_bounds: Option<Kept>,
    /// The latest iterates the reported result averages (`None`: the result is the last
    /// iterate; [`DepthCalibConfig::pose_average_fraction`]).
    window: Option<PoseWindow>,
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
    ) -> Result<Self, RunError> {
        Self::from_drive_covering(drive, rig, sweeps_per_lidar, segments_nanos, &[], config)
    }

    /// [`UnicalLidarStage::from_drive`], with each LiDAR's sweep nearest every one of
    /// `image_stamps_nanos` (the cameras' training images: [`training_stamps`]) in the scene
    /// too ([`scene_sweeps`]), so that what the cameras are fitted on was seen by a LiDAR.
    pub fn from_drive_covering(
        drive: &Drive,
        rig: &Rig,
        sweeps_per_lidar: usize,
        segments_nanos: &[(i64, i64)],
        image_stamps_nanos: &[i64],
        config: DepthCalibConfig,
    ) -> Result<Self, RunError> {
        let mut lidars = Vec::new();
        for lidar in rig.lidars() {
            let picked = scene_sweeps::pick(
                drive,
                &lidar.name,
                sweeps_per_lidar,
                segments_nanos,
                image_stamps_nanos,
            );
            // A sweep that does not decode is skipped (and reported by the drive).
            let sweeps: Vec<_> = picked
                .into_iter()
                .filter_map(|i| drive.sweep_or_skip(&lidar.name, i))
                .collect();
            if sweeps.is_empty() {
                continue;
            }
            lidars.push(LidarData {
                name: lidar.name.clone(),
                initial: lidar.vehicle_from_sensor,
                sweeps,
            });
        }
        if lidars.is_empty() {
            return Err(RunError::NotEnoughData(
                "no LiDAR sweeps inside the trajectory and the selected segments".into(),
            ));
        }
        let sources: Vec<(String, Rigid)> =
            lidars.iter().map(|l| (l.name.clone(), l.initial)).collect();
        let transient = config.transient_returns.map(|settings| {
            let (stats, witnesses) = remove_transient(&mut lidars, &drive.trajectory, settings);
            (witnesses, sources, stats)
        });
        let scene_bounds = config
            .scene_radius_m
            .map(|r| keep_near_drive(&mut lidars, &drive.trajectory, r));
        let window = match window_len(config.iterations, config.pose_average_fraction) {
            0 => None,
            n => Some(PoseWindow::new(n)),
        };
        Ok(Self {
            calib: DepthCalibration::new(config, drive.trajectory.clone(), lidars),
            rig: rig.clone(),
            rounds: 1,
            round: 0,
            transient,
            scene_bounds,
            window,
        })
    }

    /// LiDAR returns kept and dropped by the scene's radius around the drive (`None`: every
    /// return kept).
    pub fn scene_bounds(&self) -> Option<Kept> {
        self.scene_bounds
    }

    /// LiDAR returns dropped as moving traffic (`None`: the check is off).
    pub fn transient_stats(&self) -> Option<&TransientStats> {
        self.transient.as_ref().map(|(_, _, stats)| stats)
    }

    /// Pixels of a `width × height` image (intrinsics `camera`, pose `vehicle_from_camera`,
    /// taken at `stamp_nanos`) where moving traffic was: the transient returns of each LiDAR's
    /// sweep nearest in time (within [`MASK_SWEEP_SECS`]), projected and grown
    /// ([`mark_traffic`]). Empty when nothing is masked.
    fn transient_mask(
        &self,
        drive: &Drive,
        camera: &CameraIntrinsics,
        vehicle_from_camera: Rigid,
        stamp_nanos: i64,
        sweeps: &mut HashMap<(usize, usize), Vec<DVec3>>,
    ) -> Vec<bool> {
        let Some((witnesses, sources, _)) = &self.transient else {
            return Vec::new();
        };
        let Ok(world_from_vehicle) = drive.trajectory.world_from_vehicle(stamp_nanos) else {
            return Vec::new();
        };
        let camera_from_world = (world_from_vehicle * vehicle_from_camera).inverse();
        let (w, h) = (camera.width as usize, camera.height as usize);
        if w == 0 || h == 0 {
            return Vec::new();
        }
        let mut mask = Vec::new();
        for (k, (name, vehicle_from_lidar)) in sources.iter().enumerate() {
            let Some(stream) = drive.stream(name) else {
                continue;
            };
            let Some((i, frame)) = stream
                .frames
                .iter()
                .enumerate()
                .min_by_key(|(_, f)| (f.stamp_nanos - stamp_nanos).abs())
            else {
                continue;
            };
            if (frame.stamp_nanos - stamp_nanos).abs() as f64 > MASK_SWEEP_SECS * 1e9 {
                continue;
            }
            if let std::collections::hash_map::Entry::Vacant(slot) = sweeps.entry((k, i)) {
                let Some(sweep) = drive.sweep_or_skip(name, i) else {
                    continue;
                };
                slot.insert(witnesses.transient_points(
                    &sweep,
                    k,
                    *vehicle_from_lidar,
                    &drive.trajectory,
                ));
            }
            let pixels: Vec<DVec2> = sweeps
                .get(&(k, i))
                .into_iter()
                .flatten()
                .filter_map(|q| {
                    let p = camera_from_world.transform_point(*q);
                    camera.project(p).filter(|_| p.z > 0.1)
                })
                .collect();
            mark_traffic(&mut mask, &pixels, w, h);
        }
        mask
    }

    /// Add `frames_per_camera` images of every camera (spread over the segments), downscaled by
    /// `scale` (e.g. 0.125: 1920×1080 → 240×135), to the optimisation.
    pub fn with_cameras(
        self,
        drive: &Drive,
        frames_per_camera: usize,
        segments_nanos: &[(i64, i64)],
        scale: f64,
    ) -> Result<Self, RunError> {
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
    ) -> Result<Self, RunError> {
        if frames_per_camera == 0 {
            return Ok(self);
        }
        if !(scale > 0.0 && scale <= 1.0) {
            return Err(RunError::Invalid(format!(
                "camera image scale {scale} is not in (0, 1]"
            )));
        }
        let with_keypoints = self.calib.config.alignment != AlignmentLoss::None;
        // Every camera with intrinsics and a stream, and the frames it contributes (counted
        // first, for the progress).
        let chosen = cameras_to_train(drive, &self.rig, frames_per_camera, segments_nanos);
        let total: usize = chosen.iter().map(|c| c.3.len()).sum();
        let mut loaded = 0;
        report(LOADING_IMAGES, 0, total);
        let mut cameras = Vec::new();
        let mut transient_sweeps = HashMap::new();
        for (cam, intrinsics, stream, picked) in chosen {
            let small = intrinsics.scaled(scale);
            let mut frames = Vec::new();
            for i in picked {
                let Some(img) = drive.image_or_skip(&cam.name, i) else {
                    continue;
                };
                let resized = working_image(img.as_ref(), &small);
                let stamp_nanos = stream.frames[i].stamp_nanos;
                // Masks are grown around what they cover: the middle row's time will do.
                let masked = self.transient_mask(
                    drive,
                    &small,
                    cam.vehicle_from_sensor,
                    stamp_nanos + drive.camera_readout.middle_nanos(),
                    &mut transient_sweeps,
                );
                let keypoints = if with_keypoints {
                    training_keypoints(img.as_ref(), small.width)
                } else {
                    Vec::new()
                };
                frames.push(CameraFrame {
                    stamp_nanos,
                    rgb: resized.into_raw(),
                    keypoints,
                    masked,
                });
                loaded += 1;
                report(LOADING_IMAGES, loaded, total);
            }
            let ego = if self.calib.config.mask_own_vehicle {
                ego_mask(&frames, small.width as usize, small.height as usize)
            } else {
                Vec::new()
            };
            for f in &mut frames {
                if !ego.is_empty() {
                    if f.masked.is_empty() {
                        f.masked = ego.clone();
                    } else {
                        f.masked.iter_mut().zip(&ego).for_each(|(m, e)| *m |= *e);
                    }
                }
                // A keypoint on a moving car or the vehicle matches that, not the scene.
                let masked = &f.masked;
                f.keypoints
                    .retain(|k| !is_masked(masked, small.width, k.x, k.y));
            }
            if !frames.is_empty() {
                cameras.push(CameraData {
                    name: cam.name.clone(),
                    initial: cam.vehicle_from_sensor,
                    intrinsics: small,
                    frames,
                    readout: drive.camera_readout,
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

    /// Shorten (or lengthen) the schedule to `iterations` steps in all from now on: the rates
    /// decay, the hash levels open and the heat maps start by the new end (each is a fraction
    /// of the run, read at every step). Never below the steps already taken.
    pub fn set_iterations(&mut self, iterations: usize) {
        self.calib.config.iterations = iterations.max(self.calib.iteration + 1);
    }

    /// The optimisation, to step it directly (probes and benchmarks).
    pub fn calibration_mut(&mut self) -> &mut DepthCalibration {
        &mut self.calib
    }

    fn rig_now(&self) -> Rig {
        self.rig_with(self.calib.extrinsics())
    }

    /// The rig with `extrinsics` in place of the initial ones.
    fn rig_with(&self, extrinsics: Vec<(String, Rigid)>) -> Rig {
        let mut rig = self.rig.clone();
        for (name, t) in extrinsics {
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
            if let Some(w) = &mut self.window {
                w.clear();
            }
        }
        let r = self.calib.step();
        if let Some(w) = &mut self.window {
            w.push(self.calib.extrinsics());
        }
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

    /// The extrinsics averaged over the latest iterates ([`PoseWindow`]) once there are any,
    /// else the current ones.
    fn best(&self) -> Rig {
        match &self.window {
            Some(w) if !w.is_empty() => self.rig_with(w.mean()),
            _ => self.rig_now(),
        }
    }
}

/// The images of camera `name` UniCal trains on: `frames_per_camera` of them spread evenly
/// over `segments_nanos` (a check of its result keeps off them).
pub fn training_images(
    drive: &Drive,
    name: &str,
    frames_per_camera: usize,
    segments_nanos: &[(i64, i64)],
) -> Vec<usize> {
    spread_evenly(
        &drive.frames_within(name, segments_nanos),
        frames_per_camera,
    )
}

/// The cameras of `rig` UniCal trains on (those with intrinsics and a stream in `drive`), each
/// with its intrinsics, stream and training images ([`training_images`]).
fn cameras_to_train<'a>(
    drive: &'a Drive,
    rig: &'a Rig,
    frames_per_camera: usize,
    segments_nanos: &[(i64, i64)],
) -> Vec<(
    &'a Sensor,
    &'a CameraIntrinsics,
    &'a SensorStream,
    Vec<usize>,
)> {
    rig.cameras()
        .filter_map(|cam| {
            let (intrinsics, stream) = (cam.camera.as_ref()?, drive.stream(&cam.name)?);
            Some((
                cam,
                intrinsics,
                stream,
                training_images(drive, &cam.name, frames_per_camera, segments_nanos),
            ))
        })
        .collect()
}

/// The stamps of the images [`UnicalLidarStage::with_cameras`] trains on: `frames_per_camera`
/// of every camera of `rig` with intrinsics and a stream in `drive`.
pub fn training_stamps(
    drive: &Drive,
    rig: &Rig,
    frames_per_camera: usize,
    segments_nanos: &[(i64, i64)],
) -> Vec<i64> {
    if frames_per_camera == 0 {
        return Vec::new();
    }
    cameras_to_train(drive, rig, frames_per_camera, segments_nanos)
        .into_iter()
        .flat_map(|(_, _, stream, images)| {
            images
                .into_iter()
                .filter_map(|i| stream.frames.get(i).map(|f| f.stamp_nanos))
        })
        .collect()
}

/// A camera image resized to the working `intrinsics` (triangle filter), as the colour term
/// and the held-out check compare rendered images with it.
pub fn working_image(img: &image::RgbImage, intrinsics: &CameraIntrinsics) -> image::RgbImage {
    image::imageops::resize(
        img,
        intrinsics.width.max(1),
        intrinsics.height.max(1),
        image::imageops::FilterType::Triangle,
    )
}
