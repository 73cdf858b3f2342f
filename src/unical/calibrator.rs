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
use super::transient::{TransientStats, Witnesses, remove_transient};
use crate::calib::Rig;
use crate::geometry::Rigid;
use crate::geometry::camera::CameraIntrinsics;
use crate::log::{Drive, spread_evenly};
use crate::optim::runner::{Calibrator, StepReport};
use glam::{DVec2, DVec3};
use std::collections::HashMap;

/// A camera frame is masked with the LiDAR sweeps at most this far from it in time.
pub const MASK_SWEEP_SECS: f64 = 0.1;
/// Each transient return masks a disc of this fraction of the image width around it: a car's
/// returns are a few pixels apart at training resolution, the camera's starting extrinsic may
/// be off by a degree, and the car moves between the sweep and the exposure.
pub const MASK_RADIUS_FRACTION: f64 = 0.025;

/// Transient returns that must fall near one another, in an image, for them to mask it.
pub const MASK_MIN_SUPPORT: usize = 4;

/// A pixel whose brightness changes by less than this (standard deviation over a camera's
/// frames, of 255) while the vehicle drives sees the vehicle itself.
pub const EGO_STD_MAX: f64 = 4.0;

/// The part of a camera's view the vehicle itself fills (its bonnet or boot): pixels whose
/// brightness hardly changes over `frames` while the scene moves past, joined to the image's
/// bottom row (so a plain sky is not taken for it). Empty when none is, or with fewer than
/// four frames to tell.
pub fn ego_mask(frames: &[CameraFrame], width: usize, height: usize) -> Vec<bool> {
    let n = width * height;
    if frames.len() < 4 || n == 0 || frames.iter().any(|f| f.rgb.len() != 3 * n) {
        return Vec::new();
    }
    let (mut sum, mut sum_sq) = (vec![0.0f64; n], vec![0.0f64; n]);
    for f in frames {
        for (i, px) in f.rgb.chunks_exact(3).enumerate() {
            let y = 0.299 * px[0] as f64 + 0.587 * px[1] as f64 + 0.114 * px[2] as f64;
            sum[i] += y;
            sum_sq[i] += y * y;
        }
    }
    let m = frames.len() as f64;
    let still: Vec<bool> = (0..n)
        .map(|i| {
            let mean = sum[i] / m;
            (sum_sq[i] / m - mean * mean).max(0.0).sqrt() < EGO_STD_MAX
        })
        .collect();
    // Flood fill from the still pixels of the bottom row.
    let mut mask = vec![false; n];
    let mut stack: Vec<usize> = ((height - 1) * width..n).filter(|&i| still[i]).collect();
    for &i in &stack {
        mask[i] = true;
    }
    while let Some(i) = stack.pop() {
        let (x, y) = (i % width, i / width);
        let neighbours = [
            (x > 0).then(|| i - 1),
            (x + 1 < width).then(|| i + 1),
            (y > 0).then(|| i - width),
            (y + 1 < height).then(|| i + width),
        ];
        for j in neighbours.into_iter().flatten() {
            if still[j] && !mask[j] {
                mask[j] = true;
                stack.push(j);
            }
        }
    }
    if mask.iter().any(|m| *m) {
        mask
    } else {
        Vec::new()
    }
}

/// Whether pixel `(x, y)` of a `width`-wide frame is in `masked` (empty: nothing is).
pub fn is_masked(masked: &[bool], width: u32, x: f32, y: f32) -> bool {
    if masked.is_empty() || !(x >= 0.0 && y >= 0.0) {
        return false;
    }
    let (x, y) = (x as usize, y as usize);
    (x < width as usize) && masked.get(y * width as usize + x).copied().unwrap_or(false)
}

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
        let sources: Vec<(String, Rigid)> =
            lidars.iter().map(|l| (l.name.clone(), l.initial)).collect();
        let transient = config.transient_returns.map(|settings| {
            let (stats, witnesses) = remove_transient(&mut lidars, &drive.trajectory, settings);
            (witnesses, sources, stats)
        });
        Ok(Self {
            calib: DepthCalibration::new(config, drive.trajectory.clone(), lidars),
            rig: rig.clone(),
            rounds: 1,
            round: 0,
            transient,
        })
    }

    /// LiDAR returns dropped as moving traffic (`None`: the check is off).
    pub fn transient_stats(&self) -> Option<&TransientStats> {
        self.transient.as_ref().map(|(_, _, stats)| stats)
    }

    /// Pixels of a `width × height` image (intrinsics `camera`, pose `vehicle_from_camera`,
    /// taken at `stamp_nanos`) where moving traffic was: the transient returns of each LiDAR's
    /// sweep nearest in time (within [`MASK_SWEEP_SECS`]), projected and grown by
    /// [`MASK_RADIUS_FRACTION`] of the width. Empty when nothing is masked.
    fn transient_mask(
        &self,
        drive: &Drive,
        camera: &CameraIntrinsics,
        vehicle_from_camera: Rigid,
        stamp_nanos: i64,
        sweeps: &mut HashMap<(usize, usize), Vec<DVec3>>,
    ) -> Result<Vec<bool>, String> {
        let Some((witnesses, sources, _)) = &self.transient else {
            return Ok(Vec::new());
        };
        let Ok(world_from_vehicle) = drive.trajectory.world_from_vehicle(stamp_nanos) else {
            return Ok(Vec::new());
        };
        let camera_from_world = (world_from_vehicle * vehicle_from_camera).inverse();
        let (w, h) = (camera.width as usize, camera.height as usize);
        if w == 0 || h == 0 {
            return Ok(Vec::new());
        }
        let radius = (MASK_RADIUS_FRACTION * w as f64).max(1.0);
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
                let sweep = drive.load_sweep(name, i).map_err(|e| e.to_string())?;
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
                .filter(|px| px.x >= 0.0 && px.y >= 0.0 && px.x < w as f64 && px.y < h as f64)
                .collect();
            // A lone return (a leaf, a wire, a grazing ray) masks nothing: only returns with
            // MASK_MIN_SUPPORT or more within about a disc's radius do.
            let cell = radius.max(1.0);
            let (cw, ch) = (
                (w as f64 / cell).ceil() as usize,
                (h as f64 / cell).ceil() as usize,
            );
            let cell_of = |px: &DVec2| {
                ((px.x / cell) as usize).min(cw - 1) + cw * ((px.y / cell) as usize).min(ch - 1)
            };
            let mut counts = vec![0usize; cw * ch];
            for px in &pixels {
                counts[cell_of(px)] += 1;
            }
            let support = |px: &DVec2| {
                let (cx, cy) = (
                    ((px.x / cell) as usize).min(cw - 1),
                    ((px.y / cell) as usize).min(ch - 1),
                );
                let mut n = 0;
                for y in cy.saturating_sub(1)..=(cy + 1).min(ch - 1) {
                    for x in cx.saturating_sub(1)..=(cx + 1).min(cw - 1) {
                        n += counts[x + cw * y];
                    }
                }
                n
            };
            for px in pixels.iter().filter(|px| support(px) >= MASK_MIN_SUPPORT) {
                if mask.is_empty() {
                    mask = vec![false; w * h];
                }
                let r = radius.ceil() as i64;
                let (cx, cy) = (px.x.floor() as i64, px.y.floor() as i64);
                for y in (cy - r).max(0)..=(cy + r).min(h as i64 - 1) {
                    for x in (cx - r).max(0)..=(cx + r).min(w as i64 - 1) {
                        let (dx, dy) = ((x - cx) as f64, (y - cy) as f64);
                        if dx * dx + dy * dy <= radius * radius {
                            mask[y as usize * w + x as usize] = true;
                        }
                    }
                }
            }
        }
        Ok(mask)
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
        let mut transient_sweeps = HashMap::new();
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
                let stamp_nanos = stream.frames[i].stamp_nanos;
                let masked = self.transient_mask(
                    drive,
                    &small,
                    cam.vehicle_from_sensor,
                    stamp_nanos,
                    &mut transient_sweeps,
                )?;
                let mut keypoints = if with_keypoints {
                    training_keypoints(img.as_ref(), small.width)
                } else {
                    Vec::new()
                };
                // A keypoint on a moving car matches the car, not the scene.
                keypoints.retain(|k| !is_masked(&masked, small.width, k.x, k.y));
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
            if !ego.is_empty() {
                for f in &mut frames {
                    if f.masked.is_empty() {
                        f.masked = ego.clone();
                    } else {
                        f.masked.iter_mut().zip(&ego).for_each(|(m, e)| *m |= *e);
                    }
                    let width = small.width;
                    let masked = &f.masked;
                    f.keypoints.retain(|k| !is_masked(masked, width, k.x, k.y));
                }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A 16 × 12 frame: a scene that shifts one pixel per frame above the bottom third, and
    /// the vehicle's grey boot, fixed, below it; the sky (top row) is plain.
    fn frame(t: usize) -> CameraFrame {
        let (w, h) = (16, 12);
        let mut rgb = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                let v = if y == 0 {
                    200
                } else if y >= 8 {
                    90 + (x % 2) as u8
                } else {
                    (((x + t) * 37 + y * 11) % 256) as u8
                };
                rgb.extend([v, v, v]);
            }
        }
        CameraFrame {
            stamp_nanos: t as i64,
            rgb,
            keypoints: Vec::new(),
            masked: Vec::new(),
        }
    }

    #[test]
    fn the_vehicles_own_body_is_masked_and_a_plain_sky_is_not() {
        let frames: Vec<CameraFrame> = (0..6).map(frame).collect();
        let mask = ego_mask(&frames, 16, 12);
        assert_eq!(mask.len(), 16 * 12);
        for y in 0..12 {
            for x in 0..16 {
                assert_eq!(mask[y * 16 + x], y >= 8, "pixel ({x}, {y})");
            }
        }
        assert!(is_masked(&mask, 16, 3.5, 9.2));
        assert!(
            !is_masked(&mask, 16, 3.5, 0.2),
            "the sky is still too, but not the vehicle"
        );
        assert!(!is_masked(&mask, 16, 17.0, 9.0), "outside the image");
        assert!(!is_masked(&[], 16, 3.5, 9.2), "no mask");
    }

    #[test]
    fn too_few_frames_or_a_moving_bottom_row_mask_nothing() {
        let frames: Vec<CameraFrame> = (0..3).map(frame).collect();
        assert!(ego_mask(&frames, 16, 12).is_empty());
        let mut frames: Vec<CameraFrame> = (0..6).map(frame).collect();
        for (t, f) in frames.iter_mut().enumerate() {
            for px in f.rgb[3 * 16 * 8..].iter_mut() {
                *px = (t * 40) as u8;
            }
        }
        assert!(ego_mask(&frames, 16, 12).is_empty());
    }
}
