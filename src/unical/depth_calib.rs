//! The UniCal optimisation step: one scene field learned jointly with every sensor's extrinsic,
//! anchored by the vehicle trajectory (method.md §8): `L_rgb + 0.1·L_depth + 0.1·L_int +
//! 0.01·L_reg` (the surface-alignment slot comes with the correspondences).
//!
//! Each step draws the same number of returns from every LiDAR (§7), builds their rays from the
//! trajectory at each return's firing time and the current extrinsic (rolling shutter, §5),
//! samples them every 10 cm in the occupancy grid (stratified jitter), and renders depth,
//! intensity and the regulariser ([`super::lidar_terms`]); cameras add the same number of
//! pixels each through the colour term ([`super::camera_rgb`]). Gradients go to the hash table
//! (sparse Adam), the geometry MLP, the decoders, β (through ln β), the per-sensor exposure and
//! intensity mappings and the 6D + translation pose of each sensor (dense Adam), all computed
//! in parallel chunks of rays and summed. One sensor can be frozen as the root, others held.
//! Cameras have their own pose rate (Adam moves a parameter by about its rate per step, so the
//! rate bounds how far a camera can travel in a run). [`DepthCalibration::restart`] starts a
//! fresh scene at the extrinsics reached (calibration in rounds).

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::adam::{AdamConfig, DenseAdam, SparseAdam, decayed_lr};
use super::background::{Background, BackgroundConfig};
use super::camera_rgb::{
    Appearance, CameraModel, ColourRay, ExposureMap, colour_step, render_colour,
};
use super::composite::{Opacity, OpacityModel};
use super::correspondences::Correspondences;
use super::field::{FieldConfig, SceneField};
use super::hash_grid::{GradAccumulator, HashGridConfig, Scaled};
use super::hash_load::{LevelLoad, level_loads};
use super::intensity::{IntensityDecoder, IntensityMap, normaliser};
use super::lidar_terms::{DepthRay, LidarModel, LidarWeights, lidar_step};
use super::observability::PoseInformation;
use super::occupancy::OccupancyGrid;
use super::pose::PoseParams;
use super::pose_newton::{NewtonConfig, NewtonState, PoseUpdate, TangentSystem, robust_system};
use super::sdf_init::{PointIndex, SdfRay, sdf_fit_step};
use super::surface_align::{
    AlignCamera, AlignRay, AlignSettings, AlignStep, AlignmentLoss, projected_ray_step,
    surface_alignment_step,
};
use super::transient::TransientSettings;
use crate::features::orb::Keypoint;
use crate::geometry::camera::CameraIntrinsics;
use crate::geometry::projection::world_points;
use crate::geometry::{Rigid, RowTimes, Trajectory};
use crate::log::LidarSweep;

/// The camera ray budget [`DepthCalibConfig::lr_camera_pose`] is meant for.
pub const CAMERA_RATE_RAYS: usize = 512;

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DepthCalibConfig {
    pub field: FieldConfig,
    pub rays_per_sensor: usize,
    pub step_m: f64,
    pub max_samples_per_ray: usize,
    pub beta_init: f32,
    pub lr_field: f32,
    /// LiDAR pose rate (Adam), decaying to 1 % of it from the end of the warm-up.
    pub lr_pose: f32,
    /// Camera pose rate at [`CAMERA_RATE_RAYS`] rays per camera, same schedule. Adam moves
    /// each pose parameter by about its rate per step, so the rate bounds how far a camera can
    /// travel in a run; with fewer rays the gradient is noisier and the rate is scaled by
    /// rays / [`CAMERA_RATE_RAYS`] (short runs with few rays otherwise random-walk the cameras
    /// away: docs/experiments/unical-camera-poses.md).
    pub lr_camera_pose: f32,
    /// The cameras' translation rate as a multiple of their rotation's (translations are the
    /// weaker-observed and slower part of a camera's pose).
    pub camera_translation_rate: f32,
    /// Whether the cameras also share one translation, stepped by its own Adam on the sum of
    /// the free cameras' translation gradients and added to each of them. A shift common to
    /// every camera (the camera rig against the LiDARs, e.g. the height a level drive leaves
    /// the reference LiDAR at) is the colour term's weakest direction; each camera alone sees
    /// it through its own noisy gradient, their sum sees it with √n less noise.
    pub shared_camera_translation: bool,
    /// What the camera pose rate decays to by the last iteration, as a fraction of
    /// `lr_camera_pose` (geometric from the end of the warm-up).
    pub camera_pose_final_fraction: f32,
    /// What the cameras' translation rate decays to by the last iteration, as a fraction of
    /// its value at the end of the warm-up (`None`: as the rotation's,
    /// `camera_pose_final_fraction`). A translation that is still far off when the rotations
    /// have settled (the height a level drive leaves, a hand-eye start's sideways offset)
    /// needs its rate late in the run more than early, where a fast translation lets a camera
    /// slide into a wrong basin before the scene holds detail (docs/experiments/hand-eye-start.md).
    pub camera_translation_final_fraction: Option<f32>,
    /// Cameras whose rotation stays within this many degrees of its start, by name: a start an
    /// independent measurement fixed (the hand-eye fit to the camera's own motion). Early in a
    /// run the colour field is still coarse, and a camera stepping at full rate can slide into
    /// a wrong basin degrees away and not come back (docs/experiments/hand-eye-start.md, "Large initial errors");
    /// the bound keeps it in the trust region its start earned. Empty: no bound.
    #[serde(skip)]
    pub camera_rotation_bounds_deg: Vec<(String, f64)>,
    /// The first iterations fit the SDF directly to the LiDAR returns ([`super::sdf_init`])
    /// with this many rays each (split evenly across LiDARs); poses stay fixed.
    pub geometry_init_steps: usize,
    pub geometry_init_rays: usize,
    /// Poses stay fixed for this many iterations while the scene forms from the initial
    /// calibration (a scene that is still mostly empty gives poses misleading gradients).
    pub pose_warmup: usize,
    /// After the warm-up the pose rates rise linearly from 0 to their value over this many
    /// iterations (Adam's first steps are full-size whatever the gradient's noise, so a pose
    /// released at its full rate jumps by about its rate per parameter before Adam has
    /// measured how noisy its gradient is; docs/experiments/unical-camera-poses.md). At most a quarter of the iterations
    /// in which poses move, so that a short run still reaches its rate. 0: the full rate at once.
    pub pose_ramp: usize,
    /// Cameras may start to move before `pose_warmup`, at this iteration, following the
    /// correspondence term alone (§9: a matched ray's rendered surface point needs the
    /// geometry the LiDARs fitted, not a painted colour field, which a camera released early
    /// would wander in), their rate ramping up over `pose_ramp`. At `pose_warmup` the colour
    /// term joins and the cameras' schedule starts again as without this (Adam's state reset:
    /// the colour gradient is far larger than the correspondence term's, and Adam's memory of
    /// the small one would turn it into steps many times the rate). `None`: cameras wait for
    /// `pose_warmup`.
    pub alignment_release: Option<usize>,
    /// The cameras' rate before the warm-up's end, as a fraction of their rate (after an
    /// [`Self::alignment_release`]).
    pub alignment_release_rate: f32,
    /// Whether the cameras' rotations move too after an [`Self::alignment_release`] (else only
    /// their translations do until the warm-up's end: after a hand-eye start the rotations are
    /// already close, and the correspondence term, with translations still off, turns them
    /// to make up for the offset; docs/experiments/correspondence-term.md, "The cameras' first move").
    pub alignment_release_rotates: bool,
    #[serde(skip)]
    pub iterations: usize,
    #[serde(skip)]
    pub seed: u64,
    /// Camera rays per camera and step (the budget is split evenly across sensors, §7).
    pub rays_per_camera: usize,
    /// Loss weights (§8): colour 1, depth 0.1, intensity 0.1, regulariser 0.01.
    pub rgb_weight: f32,
    pub depth_weight: f32,
    pub intensity_weight: f32,
    pub regulariser_weight: f32,
    /// Registration phase (iterations after the pose warm-up): until it ends only the anchor
    /// LiDAR (the frozen root if it is a LiDAR, else the first) initialises and trains the
    /// scene, and the other LiDARs track it without shaping it; then every sensor trains the
    /// scene as in the paper. A scene trained by all LiDARs from a wrong start follows each
    /// one's error wherever it sees most, and the relative signal fades (docs/experiments/unical-lidar-terms.md). 0: no
    /// such phase. Only with preconditioned LiDAR pose steps (with Adam a LiDAR that places no
    /// surface gets no pose gradient).
    pub registration_steps: usize,
    /// Coarse-to-fine hash grid (BARF): the scene starts with this many open levels and
    /// opens the rest evenly until this fraction of the iterations (`None`: all open).
    pub coarse_to_fine: Option<CoarseToFine>,
    /// How LiDAR poses move: the paper's Adam, or preconditioned steps (the objective's
    /// gradient scaled by the rendered depth's curvature, [`super::pose_newton`]). Cameras
    /// always use Adam.
    pub lidar_pose_update: PoseUpdate,
    /// Camera rays are sampled up to this distance (the scene box clips them further).
    pub camera_far_m: f64,
    /// The background model beyond the scene box for camera rays (`None`: the sky feature
    /// takes whatever light leaves the box).
    pub background: Option<BackgroundConfig>,
    /// A sensor whose extrinsic stays fixed (the root); `None`: all move, the trajectory fixes
    /// the gauge (§11).
    #[serde(skip)]
    pub frozen_sensor: Option<String>,
    /// Further sensors whose extrinsics stay at their initial values (they still shape the
    /// scene): the sensors a user did not ask to calibrate.
    #[serde(skip)]
    pub held_sensors: Vec<String>,
    /// The correspondence term between cameras (§9; the Table A9 ablation switch).
    pub alignment: AlignmentLoss,
    /// Its weight λ_align (the paper: 0.001 on 1920-wide pixels).
    pub alignment_weight: f32,
    /// Matches per camera and step.
    pub alignment_matches_per_camera: usize,
    pub alignment_settings: AlignSettings,
    /// Where matched correspondences are kept between runs (`None`: matched every run).
    #[serde(skip)]
    pub correspondence_cache: Option<std::path::PathBuf>,
    /// Coarse-to-fine sampling (§10): from this fraction of the iterations on, camera pixels
    /// are drawn from keypoint heat maps (the paper: 2000 of 30 000); 1.0 keeps them uniform.
    pub heatmap_start_fraction: f32,
    /// The heat maps' Gaussian σ at the start and at the end, in pixels of a 1920-wide image.
    pub heatmap_sigma_px: (f64, f64),
    /// Share of camera pixels still drawn uniformly once heat maps are on.
    pub heatmap_uniform_share: f64,
    /// Share of the camera pixel draws, once heat maps are on, centred on LiDAR silhouettes:
    /// depth discontinuities of the sweep nearest each frame, projected into it under the
    /// current poses (refreshed every [`SILHOUETTE_REFRESH`] iterations). The rest are drawn
    /// as without it ([`Self::heatmap_uniform_share`] of them uniformly, the others around
    /// keypoints); a frame without silhouettes draws as with 0. Where colour texture may
    /// slide along a surface with a camera's translation, a silhouette cannot: it ties the
    /// camera to the LiDARs' geometry. 0 draws around keypoints only (the paper); the CPU
    /// preset draws half of them here.
    pub silhouette_share: f64,
    /// How signed distances become opacities (method.md §3's per-sample form, or the
    /// unbiased per-section form; [`OpacityModel`]).
    pub opacity: OpacityModel,
    /// Whether surface colour depends on the view direction (the paper's decoder;
    /// [`Appearance::view_dependent`]).
    pub view_dependent_colour: bool,
    /// Drop LiDAR returns that other sweeps saw through (moving traffic) before the scene is
    /// built ([`super::transient`]), and mask camera pixels near them; `None` keeps every
    /// return and pixel.
    pub transient_returns: Option<TransientSettings>,
    /// Drop LiDAR returns farther than this (m, horizontally) from the box around the
    /// trajectory before the scene box is formed ([`super::scene_bounds`]): the scene then
    /// spans the drive's surroundings instead of the LiDARs' whole reach, and the rest is the
    /// background model's. `None` keeps every return.
    pub scene_radius_m: Option<f64>,
    /// Mask the part of each camera's view that the vehicle itself fills (pixels still over
    /// the camera's frames, joined to the bottom row; `super::masks::ego_mask`).
    pub mask_own_vehicle: bool,
    /// Draw camera rays only up to the elevation of the LiDARs' highest returns
    /// ([`super::coverage`]): above it the scene has no geometry, so what the cameras see
    /// there can only be painted on the sky, which pulls their pitch.
    pub camera_rays_below_lidar_top: bool,
    /// Solution remapping ([`super::observability`]): each camera step keeps only the
    /// directions the correspondence term observes at least this fraction as well as the
    /// camera's best observed one, so a direction the drive hardly sees stays where the initial
    /// guess put it. `None`: every direction moves (the paper).
    pub camera_hold_unobserved: Option<f64>,
    /// Hold each camera's translation along its own optical axis at the initial guess: a step
    /// keeps only its part square to the axis. Along the axis a camera is observed least (a
    /// shift δ scales what it sees by about δ / depth), and there the colour term pulls a
    /// camera away from what it sees (docs/experiments/colour-field-and-hash-grid.md, "Blurred colour targets", "Where the real
    /// drive's right camera comes to rest"). Off: every direction moves (the paper).
    pub camera_hold_axial: bool,
    /// Hold each camera's translation along this vehicle-frame unit direction at the initial
    /// guess (a step keeps only its part square to it): the plan sets it to the direction of
    /// travel where the drive is too straight to pin a camera's position along it (Table A8).
    /// Decided from the drive, not a setting; `None`: every direction moves.
    #[serde(skip)]
    pub camera_hold_translation_along: Option<[f64; 3]>,
    /// How many of the hash grids' coarsest levels the colour term's camera-pose gradient
    /// flows through (`None`: every open level, the paper). The scene still learns its detail
    /// from every open level; only ∂L/∂x, which moves the cameras, is limited: the finest
    /// levels' detail is where a young scene is most wrong, and its gradient is the least
    /// smooth in the pose (BARF's reason for coarse-to-fine).
    pub colour_pose_levels: Option<f32>,
    /// The result a run reports is every sensor's pose averaged over this fraction of the
    /// iterations, the latest ones ([`super::pose_window`]): the pose steps are stochastic, and
    /// the mean of the last iterates holds still where single ones jitter. 0: the last iterate
    /// (the paper). The live pose, which the optimiser steps and the studio shows, is the
    /// iterate either way.
    pub pose_average_fraction: f32,
}

/// The iteration of the geometry initialisation from which cameras fitted by the hand-eye
/// move their translations ([`DepthCalibConfig::after_hand_eye`]).
pub const HAND_EYE_RELEASE: usize = 30;

impl Default for DepthCalibConfig {
    /// CPU preset: a few thousand rays per step (method.md §18), paper learning rates for the
    /// scene, a larger pose rate than the paper's 1e-4 because the run is far shorter.
    fn default() -> Self {
        Self {
            field: FieldConfig::default(),
            rays_per_sensor: 1024,
            step_m: 0.1,
            max_samples_per_ray: 256,
            beta_init: 20.0,
            lr_field: 1e-2,
            lr_pose: 1e-3,
            lr_camera_pose: 1e-2,
            camera_translation_rate: 1.0,
            // Off: end to end on the simulator it takes the cameras to the height the LiDAR
            // fit leaves (drive 7: 2.2-2.8 cm instead of 4.2 cm on average), but on the real
            // PandaSet drive the six cameras drift together, 14.5 cm instead of 8.3 cm
            // (docs/experiments/unical-camera-poses.md, "A translation the cameras share"); `--shared-camera-translation`.
            shared_camera_translation: false,
            camera_pose_final_fraction: 0.01,
            camera_translation_final_fraction: None,
            camera_rotation_bounds_deg: Vec::new(),
            geometry_init_steps: 150,
            geometry_init_rays: 8192,
            // Poses wait for 50 rendering steps, then their rates ramp up. Released at full
            // rate, cameras on the real PandaSet drive jumped 4-6° off their reference even
            // against a frozen scene; released after 25 initialisation steps (moving 3.7 s into
            // a run), one of seed 2's cameras ran 4° off (docs/experiments/unical-camera-poses.md, "Pose rates that ramp
            // up").
            pose_warmup: 200,
            pose_ramp: 150,
            // Not in the preset: released at the 30th initialisation step at a tenth of their
            // rate, cameras first move 2.2 s into a run instead of 28-34 s, but end to end the
            // three simulator seeds end with their rotations 0.02-0.05° worse and seed 7's right
            // pair at 0.37° / 0.32° instead of 0.21° / 0.19° (docs/experiments/correspondence-term.md, "The cameras'
            // first move").
            alignment_release: None,
            alignment_release_rate: 0.1,
            alignment_release_rotates: true,
            iterations: 2000,
            seed: 1,
            rays_per_camera: 512,
            rgb_weight: 1.0,
            depth_weight: 0.1,
            intensity_weight: 0.1,
            regulariser_weight: 0.01,
            lidar_pose_update: PoseUpdate::Adam,
            registration_steps: 0,
            // Four of the hash grid's levels open at the start, all by 60 % of the run (BARF):
            // the same accuracy on the simulator's drives as every level from the start, and
            // the early steps are cheaper, so a run takes a fifth less time and its cameras
            // first move twice as soon (docs/experiments/unical-camera-poses.md, "Issue 5 end to end").
            coarse_to_fine: Some(CoarseToFine {
                start_levels: 4.0,
                end_fraction: 0.6,
            }),
            camera_far_m: 120.0,
            background: Some(BackgroundConfig::default()),
            frozen_sensor: None,
            held_sensors: Vec::new(),
            alignment: AlignmentLoss::SurfaceAlignment,
            alignment_weight: 0.001,
            alignment_matches_per_camera: 32,
            alignment_settings: AlignSettings::default(),
            correspondence_cache: None,
            heatmap_start_fraction: 2000.0 / 30_000.0,
            heatmap_sigma_px: (40.0, 5.0),
            heatmap_uniform_share: 0.2,
            // Without it a camera translation that all cameras share is barely observed on a
            // drive that turns little (docs/experiments/unical-camera-poses.md: 7.0 cm with the back camera off by 3.8°,
            // against 2.35 cm with every camera within 0.24°, after 1400 iterations).
            silhouette_share: 0.5,
            opacity: OpacityModel::PerSample,
            // Lambertian surfaces: the paper's view-dependent decoder lets a colour that
            // changes with the direction explain two cameras' disagreement (docs/experiments/unical-camera-poses.md:
            // 0.27° against 0.46° after 600 iterations from 2°); `paper()` keeps it.
            view_dependent_colour: false,
            // Off: on the real PandaSet drive they find the passing cars and the vehicle's boot
            // (5 % of the returns; docs/experiments/unical-real-pandaset.md, "Moving traffic"), but its cameras end no
            // closer to the reference, and on the simulator's static drive 7 a few masked
            // façade windows changed where the back camera ended (17.6 cm instead of 7.3).
            transient_returns: None,
            scene_radius_m: None,
            mask_own_vehicle: false,
            // Off: on the real PandaSet drive it takes the cameras' rotations from 0.60° to
            // 0.41–0.49° off the reference but their translations from 9.6 to 11.6–13.2 cm
            // (docs/experiments/robustness-protocol.md, "… the cameras' pitch against the LiDARs' highest beam").
            camera_rays_below_lidar_top: false,
            camera_hold_unobserved: None,
            camera_hold_axial: false,
            camera_hold_translation_along: None,
            // Off: with 12 of 16 levels the real PandaSet drive's left pair no longer turned off
            // on seed 1, but the simulator's drive 7 lost its back camera (0.24° / 9.6 cm), and
            // the limited gradient is not that of any loss (docs/experiments/colour-field-and-hash-grid.md, "Camera poses moved
            // through the hash grid's coarse levels only").
            colour_pose_levels: None,
            // Averaged over the last 10 % of the run (140 of 1400 steps): on the simulator's
            // drives the reported poses hold issue 5's thresholds 100-200 s sooner (drive 7:
            // from 240 s), and the end result is the same within a few millimetres
            // (docs/experiments/colour-field-and-hash-grid.md, "Issue 5's three drives on this machine, and poses averaged").
            pose_average_fraction: 0.1,
        }
    }
}

/// A coarse-to-fine schedule of the scene's hash-grid levels.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoarseToFine {
    pub start_levels: f32,
    pub end_fraction: f32,
}

impl CoarseToFine {
    /// `LEVELS,FRACTION` (levels open at the start ≥ 1, the fraction of the run by which all
    /// are open in (0, 1]) or `off` (`None`: every level from the start).
    pub fn parse_setting(text: &str) -> Result<Option<Self>, String> {
        if text.trim() == "off" {
            return Ok(None);
        }
        let bad = || format!("expected LEVELS,FRACTION (e.g. 4,0.6) or off, got '{text}'");
        let (a, b) = text.split_once(',').ok_or_else(bad)?;
        let start_levels: f32 = a.trim().parse().map_err(|_| bad())?;
        let end_fraction: f32 = b.trim().parse().map_err(|_| bad())?;
        if !(start_levels >= 1.0 && end_fraction > 0.0 && end_fraction <= 1.0) {
            return Err(bad());
        }
        Ok(Some(Self {
            start_levels,
            end_fraction,
        }))
    }
}

impl DepthCalibConfig {
    /// The paper's values (method.md §2, §7, §12; supplementary A2): hash table 2^21 per level,
    /// 16 levels from 16 to 4096, 2^19 samples per step (≈ 5000 rays at 10 cm steps, split
    /// evenly across sensors: set `rays_per_sensor`/`rays_per_camera` for the rig), pose rate
    /// 1e-4, 30 000 iterations. Sized for a GPU; [`DepthCalibConfig::default`] is the CPU preset.
    pub fn paper() -> Self {
        Self {
            field: FieldConfig {
                grid: HashGridConfig {
                    levels: 16,
                    log2_table_size: 21,
                    base_resolution: 16.0,
                    max_resolution: 4096.0,
                },
                ..FieldConfig::default()
            },
            rays_per_sensor: 625,
            rays_per_camera: 625,
            lr_pose: 1e-4,
            lr_camera_pose: 1e-4,
            camera_translation_rate: 1.0,
            view_dependent_colour: true,
            lidar_pose_update: PoseUpdate::Adam,
            registration_steps: 0,
            geometry_init_steps: 0,
            pose_warmup: 0,
            pose_ramp: 0,
            alignment_release: None,
            iterations: 30_000,
            // The paper draws its heat maps around keypoints only, and opens every level.
            silhouette_share: 0.0,
            coarse_to_fine: None,
            ..Self::default()
        }
    }

    /// The camera schedule after a hand-eye start ([`crate::classical::hand_eye`]) for the
    /// cameras it `fitted` (unchanged when it fitted none): their rotations start within a few
    /// tenths of a degree, so they move at half the CPU preset's rate and at most
    /// `rotation_bound_deg` from the fit ([`Self::camera_rotation_bounds_deg`]); their
    /// translations start as far off as before in the directions the drive did not observe
    /// (height, mostly sideways), so they keep the preset's rate (twice the halved one) and
    /// decay only to 5 % of it, moving late in the run when the rotations have settled. On the
    /// simulator's three drives this meets every threshold of issue 5 where neither the preset
    /// nor either change alone did (docs/experiments/hand-eye-start.md, "A hand-eye start"). Their translations
    /// start moving early, at [`HAND_EYE_RELEASE`], on the correspondence term alone (the
    /// rotations wait for the warm-up: [`Self::alignment_release_rotates`]), so the first
    /// extrinsic update comes 1–2 s into the run instead of 28–34 s. Every pose then waits
    /// for 2/7 of the run (at least the preset's warm-up) and ramps up over 3/14 of it (at
    /// least the preset's ramp): 400 and 300 of 1400 steps. A camera that starts this close
    /// has little to gain from the young scene and much to lose to it: with the preset's 200
    /// and 150, drive 7's back camera, started 0.02° / 3.3 cm from the truth, was pulled to
    /// 0.48° / 20 cm and ended 0.41° / 8.7 cm off; with these, 0.08° / 3.4 cm (docs/experiments/correspondence-term.md,
    /// "A tighter rotation bound"). Call it with [`Self::iterations`] set.
    pub fn after_hand_eye(self, fitted: &[String], rotation_bound_deg: f64) -> Self {
        if fitted.is_empty() {
            return self;
        }
        Self {
            lr_camera_pose: self.lr_camera_pose * 0.5,
            camera_translation_rate: self.camera_translation_rate * 2.0,
            camera_translation_final_fraction: Some(0.05),
            alignment_release: Some(HAND_EYE_RELEASE),
            alignment_release_rotates: false,
            camera_rotation_bounds_deg: fitted
                .iter()
                .map(|name| (name.clone(), rotation_bound_deg))
                .collect(),
            pose_warmup: self.pose_warmup.max(self.iterations * 2 / 7),
            pose_ramp: self.pose_ramp.max(self.iterations * 3 / 14),
            ..self
        }
    }

    /// A pose rate at `iteration`: 0 during the warm-up, then rising linearly over `pose_ramp`
    /// iterations while it decays geometrically to `final_fraction` of `rate` by the last
    /// iteration. The decay counts from the end of the warm-up, over the iterations in which
    /// poses move (from iteration 0 a short run's poses would start at a few percent of their
    /// rate).
    pub fn pose_rate(&self, rate: f32, final_fraction: f32, iteration: usize) -> f32 {
        let Some(since) = iteration.checked_sub(self.pose_warmup) else {
            return 0.0;
        };
        let moving = self.moving_iterations();
        let ramp = match self.pose_ramp.min(moving / 4) {
            0 => 1.0,
            n => ((since + 1) as f32 / n as f32).min(1.0),
        };
        ramp * decayed_lr(rate, final_fraction, since, moving)
    }

    /// A camera's pose rate: from [`Self::camera_release`] to the warm-up's end ramped up as
    /// after the warm-up, then [`Self::pose_rate`].
    pub fn camera_pose_rate(&self, rate: f32, final_fraction: f32, iteration: usize) -> f32 {
        let release = self.camera_release();
        if iteration >= self.pose_warmup {
            return self.pose_rate(rate, final_fraction, iteration);
        }
        match (iteration.checked_sub(release), self.pose_ramp) {
            (None, _) => 0.0,
            (Some(_), 0) => rate * self.alignment_release_rate,
            (Some(since), n) => {
                rate * self.alignment_release_rate * ((since + 1) as f32 / n as f32).min(1.0)
            }
        }
    }

    /// How far a camera's translation steps at `iteration` relative to its rotation:
    /// `camera_translation_rate`, times the ratio of the two decays when the translation
    /// decays to its own [`Self::camera_translation_final_fraction`] (the translation's rate is
    /// then `lr · final^s` at the fraction `s` of the iterations in which poses move).
    pub fn camera_translation_scale(&self, iteration: usize) -> f64 {
        let rate = self.camera_translation_rate as f64;
        let Some(final_fraction) = self.camera_translation_final_fraction else {
            return rate;
        };
        let since = iteration.saturating_sub(self.pose_warmup);
        let ratio = final_fraction / self.camera_pose_final_fraction.max(1e-12);
        rate * decayed_lr(1.0, ratio, since, self.moving_iterations()) as f64
    }

    /// The iterations in which poses move (from the warm-up's end), at least 1: what their
    /// rates decay over.
    fn moving_iterations(&self) -> usize {
        self.iterations.saturating_sub(self.pose_warmup).max(1)
    }

    /// The iteration from which camera poses move: [`Self::alignment_release`] if it comes
    /// before the warm-up's end, else `pose_warmup`.
    pub fn camera_release(&self) -> usize {
        self.alignment_release
            .map_or(self.pose_warmup, |r| r.min(self.pose_warmup))
    }

    fn lidar_weights(&self) -> LidarWeights {
        LidarWeights {
            pose_rows: match self.lidar_pose_update {
                PoseUpdate::Newton(n) => Some(n),
                PoseUpdate::Adam => None,
            },
            free_space_only: false,
            depth: self.depth_weight,
            intensity: self.intensity_weight,
            regulariser: self.regulariser_weight,
        }
    }
}

/// One LiDAR's data.
#[derive(Clone, Debug)]
pub struct LidarData {
    pub name: String,
    pub initial: Rigid,
    pub sweeps: Vec<LidarSweep>,
}

/// One camera image, usually downscaled, with the intrinsics that match it.
#[derive(Clone, Debug)]
pub struct CameraFrame {
    pub stamp_nanos: i64,
    /// Row-major RGB, `intrinsics.width × intrinsics.height × 3`.
    pub rgb: Vec<u8>,
    /// Keypoints for the correspondences and heat maps, in training pixels (empty when the
    /// optimisation uses no correspondences).
    pub keypoints: Vec<Keypoint>,
    /// Pixels no ray is drawn from (moving traffic, the vehicle itself; `super::masks`), row-major;
    /// empty when none is.
    pub masked: Vec<bool>,
}

/// One camera's data.
#[derive(Clone, Debug)]
pub struct CameraData {
    pub name: String,
    pub initial: Rigid,
    pub intrinsics: CameraIntrinsics,
    pub frames: Vec<CameraFrame>,
    /// When each image row was exposed relative to its frame's stamp (rolling shutter).
    pub readout: RowTimes,
}

impl CameraData {
    /// When the row at training pixel `y` of a frame stamped `stamp_nanos` was exposed.
    pub fn row_stamp_nanos(&self, stamp_nanos: i64, y: f64) -> i64 {
        stamp_nanos + self.readout.offset_nanos(y, self.intrinsics.height)
    }

    /// When the middle row of a frame stamped `stamp_nanos` was exposed: the one time that
    /// stands for the whole image where a single pose is needed.
    pub fn middle_stamp_nanos(&self, stamp_nanos: i64) -> i64 {
        stamp_nanos + self.readout.middle_nanos()
    }

    /// The training pixel where world point `p_world` appears in the frame stamped
    /// `stamp_nanos`, seen in front of the camera within ~78° of its axis (no folded-over
    /// pixels). With a rolling shutter the point is projected at the middle row's time, then
    /// twice again at the time of the row it fell on: each pass shrinks the row's error by
    /// the pixels the point moves in one row's readout, a small fraction.
    pub fn project_world(
        &self,
        trajectory: &Trajectory,
        vehicle_from_camera: Rigid,
        stamp_nanos: i64,
        p_world: DVec3,
    ) -> Option<DVec2> {
        let middle = self.camera_from_world_at(
            trajectory,
            vehicle_from_camera,
            self.middle_stamp_nanos(stamp_nanos),
        )?;
        self.project_world_from(
            trajectory,
            vehicle_from_camera,
            stamp_nanos,
            middle,
            p_world,
        )
    }

    /// `camera_from_world` at `stamp_nanos` (`None` outside the trajectory).
    pub fn camera_from_world_at(
        &self,
        trajectory: &Trajectory,
        vehicle_from_camera: Rigid,
        stamp_nanos: i64,
    ) -> Option<Rigid> {
        let wv = trajectory.world_from_vehicle(stamp_nanos).ok()?;
        Some((wv * vehicle_from_camera).inverse())
    }

    /// [`Self::project_world`] given `camera_from_world` at the middle row's time (the same for
    /// every point of a frame, so callers projecting many look it up once).
    pub fn project_world_from(
        &self,
        trajectory: &Trajectory,
        vehicle_from_camera: Rigid,
        stamp_nanos: i64,
        middle_camera_from_world: Rigid,
        p_world: DVec3,
    ) -> Option<DVec2> {
        let project = |camera_from_world: Rigid| {
            let in_camera = camera_from_world.transform_point(p_world);
            if in_camera.z < 0.2 * in_camera.length() {
                return None;
            }
            self.intrinsics.project(in_camera)
        };
        let mut px = project(middle_camera_from_world)?;
        if self.readout.first_row_nanos != self.readout.last_row_nanos {
            for _ in 0..2 {
                let stamp = self.row_stamp_nanos(stamp_nanos, px.y);
                px = project(self.camera_from_world_at(trajectory, vehicle_from_camera, stamp)?)?;
            }
        }
        self.intrinsics.in_image(px).then_some(px)
    }
}

/// Everything the colour term adds: camera poses, exposure maps, decoders and their optimisers.
struct CameraStage {
    cameras: Vec<CameraData>,
    poses: Vec<PoseParams>,
    pose_opt: Vec<DenseAdam>,
    /// The translation every camera shares ([`DepthCalibConfig::shared_camera_translation`]).
    shared_translation_opt: DenseAdam,
    exposure: Vec<ExposureMap>,
    exposure_opt: Vec<DenseAdam>,
    appearance: Appearance,
    colour_params: Vec<f32>,
    colour_opt: DenseAdam,
    sky_params: Vec<f32>,
    sky_opt: DenseAdam,
    background: Option<BackgroundStage>,
    /// Camera rays above this vehicle-frame elevation are not drawn
    /// ([`DepthCalibConfig::camera_rays_below_lidar_top`]).
    ray_top_elevation_rad: Option<f64>,
    /// What the correspondence term observes of each camera's pose, with forgetting.
    information: Vec<PoseInformation>,
}

/// The background field and its optimisers.
struct BackgroundStage {
    field: Background,
    grid_opt: SparseAdam,
    /// One per parallel chunk of rays (chunk i always sums into accumulator i: deterministic).
    grid_accs: Vec<GradAccumulator>,
    mlp_params: Vec<f32>,
    mlp_opt: DenseAdam,
}

pub struct DepthCalibration {
    pub config: DepthCalibConfig,
    pub trajectory: Trajectory,
    pub lidars: Vec<LidarData>,
    pub field: SceneField,
    pub occupancy: OccupancyGrid,
    pub poses: Vec<PoseParams>,
    ln_beta: f32,
    grid_opt: SparseAdam,
    /// One per parallel chunk of rays (chunk i always sums into accumulator i: deterministic).
    grid_accs: Vec<GradAccumulator>,
    mlp_opt: DenseAdam,
    mlp_params: Vec<f32>,
    pose_opt: Vec<DenseAdam>,
    beta_opt: DenseAdam,
    /// The aggregated returns under the initial calibration (for the geometry initialisation,
    /// indexed on first use and dropped after it).
    aggregated: Vec<DVec3>,
    point_index: Option<PointIndex>,
    /// Per LiDAR: the factor that normalises its intensities to [0, 1] (`None`: no intensity).
    intensity_norm: Vec<Option<f32>>,
    intensity_maps: Vec<IntensityMap>,
    /// The LiDAR that alone shapes the scene during the registration phase.
    anchor: usize,
    /// Per LiDAR: the state of its preconditioned pose steps (unused with Adam).
    newton: Vec<NewtonState>,
    intensity_map_opt: Vec<DenseAdam>,
    decoder: IntensityDecoder,
    decoder_params: Vec<f32>,
    decoder_opt: DenseAdam,
    pub iteration: usize,
    rng: u64,
    camera: Option<CameraStage>,
    /// Matched pixels between camera frames (empty without cameras or correspondences).
    pub correspondences: Correspondences,
    /// Per LiDAR and sweep: the indices of its silhouette points (computed on first use).
    silhouette_points: Vec<Vec<Vec<u32>>>,
    /// Per camera and frame: those points projected into it (training pixels), and the
    /// iteration they were projected at.
    silhouette_pixels: (Vec<Vec<Vec<(f32, f32)>>>, usize),
}

/// Iterations between re-projections of the LiDAR silhouettes into the camera frames.
pub const SILHOUETTE_REFRESH: usize = 50;

/// One LiDAR return rendered by the current scene (diagnostics).
#[derive(Clone, Copy, Debug)]
pub struct DepthResidual {
    pub range_m: f32,
    /// Rendered expected range minus the measured range (negative: rendered too short).
    pub error_m: f32,
    pub elevation_rad: f32,
    /// Accumulated opacity A of the ray's samples.
    pub accumulation: f32,
}

/// Report of one step.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthReport {
    /// LiDAR depth loss (unweighted).
    pub loss: f64,
    pub mean_abs_error_m: f64,
    pub beta: f32,
    /// Camera colour loss (mean squared error in [0, 1] units; 0 without cameras).
    pub colour_loss: f64,
    /// LiDAR intensity loss (normalised intensities; 0 when no LiDAR reports intensity).
    pub intensity_loss: f64,
    /// The SDF regulariser (Eikonal near hits + weight suppression away from them).
    pub regulariser_loss: f64,
    /// During the geometry initialisation: its loss (the other terms are 0 then).
    pub geometry_init_loss: Option<f64>,
    /// The correspondence term (1920-wide pixels; 0 when off) and the matches it kept.
    pub alignment_loss: f64,
    pub alignment_matches: usize,
}

/// The correspondence term's contribution to a step.
struct AlignmentGrads {
    /// Per camera, flattened like [`pose_grad_flat`].
    pose: Vec<[f32; 9]>,
    geo: super::mlp::MlpGrad,
    beta_grad: f64,
    loss: f64,
    kept: usize,
}

/// One gradient accumulator per parallel chunk of rays: one chunk per thread (each is a
/// table-sized buffer every step reads back).
fn accumulators(entries: usize) -> Vec<GradAccumulator> {
    let chunks = rayon::current_num_threads().max(1);
    (0..chunks).map(|_| GradAccumulator::new(entries)).collect()
}

/// Uniform in [0, 1).
fn unit(rng: &mut u64) -> f64 {
    (next(rng) >> 11) as f64 / (1u64 << 53) as f64
}

/// Two independent standard normal values (Box–Muller).
fn gaussian_pair(rng: &mut u64) -> (f64, f64) {
    let u1 = unit(rng).max(1e-12);
    let u2 = unit(rng);
    let r = (-2.0 * u1.ln()).sqrt();
    let (s, c) = (2.0 * std::f64::consts::PI * u2).sin_cos();
    (r * c, r * s)
}

fn next(rng: &mut u64) -> u64 {
    *rng = rng.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *rng;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn mlp_flat(m: &super::mlp::Mlp) -> Vec<f32> {
    m.layers
        .iter()
        .flat_map(|l| l.weights.iter().chain(l.bias.iter()).copied())
        .collect()
}

fn mlp_set(m: &mut super::mlp::Mlp, p: &[f32]) {
    let mut k = 0;
    for l in &mut m.layers {
        for v in l.weights.iter_mut().chain(l.bias.iter_mut()) {
            *v = p[k];
            k += 1;
        }
    }
}

fn add_scaled(acc: &mut super::mlp::MlpGrad, g: &super::mlp::MlpGrad, w: f32) {
    for (a, b) in acc.weights.iter_mut().zip(&g.weights) {
        a.iter_mut().zip(b).for_each(|(x, y)| *x += y * w);
    }
    for (a, b) in acc.bias.iter_mut().zip(&g.bias) {
        a.iter_mut().zip(b).for_each(|(x, y)| *x += y * w);
    }
}

fn grad_flat(g: &super::mlp::MlpGrad) -> Vec<f32> {
    g.weights
        .iter()
        .zip(&g.bias)
        .flat_map(|(w, b)| w.iter().chain(b.iter()).copied())
        .collect()
}

/// One Adam step of a pose from its 9 gradients, applied as a delta so the f64 pose keeps its
/// precision.
/// `translation_scale` multiplies the translation's step (its rate relative to the rotation's).
fn pose_step(
    opt: &mut DenseAdam,
    p: &mut PoseParams,
    grad: &[f32; 9],
    lr: f32,
    translation_scale: f64,
) {
    if lr == 0.0 {
        return;
    }
    let mut flat: Vec<f32> =
        p.r6.iter()
            .map(|v| *v as f32)
            .chain(p.translation_m.to_array().iter().map(|v| *v as f32))
            .collect();
    let before = flat.clone();
    opt.step(&mut flat, grad, lr);
    for k in 0..6 {
        p.r6[k] += (flat[k] - before[k]) as f64;
    }
    for k in 0..3 {
        p.translation_m[k] += (flat[6 + k] - before[6 + k]) as f64 * translation_scale;
    }
}

/// Reprojections a camera's information must hold before its poorly observed directions are
/// held ([`DepthCalibConfig::camera_hold_unobserved`]).
const INFORMATION_MIN_COUNT: f64 = 200.0;
/// Per step, what the information keeps of what it held (about 30 steps' memory).
const INFORMATION_FORGETTING: f64 = 0.97;

/// Undo the part of the step from `before` to `pose` along the directions the correspondence
/// term observes less than `ratio` times its best ([`super::observability`]).
fn hold_unobserved(pose: &mut PoseParams, before: &PoseParams, info: &PoseInformation, ratio: f64) {
    let (r0, r1) = (before.rotation(), pose.rotation());
    let omega =
        crate::geometry::so3::log(glam::DQuat::from_mat3(&(r1 * r0.transpose())).normalize());
    let v = pose.translation_m - before.translation_m;
    let (omega, v) = info.observed_step((omega, v), ratio, INFORMATION_MIN_COUNT);
    let rotation = crate::geometry::so3::exp_mat(omega) * r0;
    pose.r6 = crate::geometry::rot6d::from_matrix(rotation);
    pose.translation_m = before.translation_m + v;
}

/// Undo the part of the translation step from `before` to `pose` along the camera's optical
/// axis (its frame's z in the vehicle frame, after the step)
/// ([`DepthCalibConfig::camera_hold_axial`]).
fn hold_axial(pose: &mut PoseParams, before: &PoseParams) {
    let axis = pose.rotation().col(2).normalize_or_zero();
    let step = pose.translation_m - before.translation_m;
    pose.translation_m -= axis * step.dot(axis);
}

/// Undo the part of the translation step from `before` to `pose` along the vehicle-frame
/// direction `along` ([`DepthCalibConfig::camera_hold_translation_along`]).
fn hold_along(pose: &mut PoseParams, before: &PoseParams, along: glam::DVec3) {
    let d = along.normalize_or_zero();
    let step = pose.translation_m - before.translation_m;
    pose.translation_m -= d * step.dot(d);
}

/// Keep `pose`'s rotation within `bound_rad` of `start`: a rotation further off is turned back
/// along the geodesic to the bound (its translation is left as it is).
fn bound_rotation(pose: &mut PoseParams, start: glam::DQuat, bound_rad: f64) {
    let now = glam::DQuat::from_mat3(&pose.rotation()).normalize();
    let offset = crate::geometry::so3::log(start.inverse() * now);
    let angle = offset.length();
    if angle <= bound_rad {
        return;
    }
    let held = start * crate::geometry::so3::exp(offset * (bound_rad / angle));
    pose.r6 = crate::geometry::rot6d::from_matrix(glam::DMat3::from_quat(held));
}

impl CameraStage {
    /// One step of every free camera's pose on its gradient (`grads[k]`, rotation then
    /// translation), and with [`DepthCalibConfig::shared_camera_translation`] of the
    /// translation they share on the sum of theirs.
    fn step_poses(
        &mut self,
        grads: &[[f32; 9]],
        frozen: &[bool],
        lr: f32,
        config: &DepthCalibConfig,
        iteration: usize,
    ) {
        let translation_scale = config.camera_translation_scale(iteration);
        let free: Vec<usize> = (0..self.poses.len().min(grads.len()))
            .filter(|&k| !frozen.get(k).copied().unwrap_or(true))
            .collect();
        for &k in &free {
            let before = self.poses[k];
            pose_step(
                &mut self.pose_opt[k],
                &mut self.poses[k],
                &grads[k],
                lr,
                translation_scale,
            );
            if config.camera_hold_axial {
                hold_axial(&mut self.poses[k], &before);
            }
            if let Some(d) = config.camera_hold_translation_along {
                hold_along(&mut self.poses[k], &before, glam::DVec3::from_array(d));
            }
            if let (Some(ratio), Some(info)) =
                (config.camera_hold_unobserved, self.information.get(k))
            {
                hold_unobserved(&mut self.poses[k], &before, info, ratio);
            }
            let name = &self.cameras[k].name;
            if let Some((_, bound_deg)) = config
                .camera_rotation_bounds_deg
                .iter()
                .find(|(n, _)| n == name)
            {
                bound_rotation(
                    &mut self.poses[k],
                    self.cameras[k].initial.rotation,
                    bound_deg.to_radians(),
                );
            }
        }
        if !config.shared_camera_translation || free.len() < 2 || lr == 0.0 {
            return;
        }
        let mut shift = shared_translation_step(&mut self.shared_translation_opt, grads, &free, lr);
        if let Some(d) = config.camera_hold_translation_along {
            let d = glam::DVec3::from_array(d).normalize_or_zero();
            shift -= d * shift.dot(d);
        }
        for &k in &free {
            self.poses[k].translation_m += shift * translation_scale;
        }
    }

    /// Fresh pose optimisers for every camera and the translation they share.
    fn restart_pose_optimisers(&mut self) {
        for opt in &mut self.pose_opt {
            *opt = DenseAdam::new(9, AdamConfig::STANDARD);
        }
        self.shared_translation_opt = DenseAdam::new(3, AdamConfig::STANDARD);
    }
}

/// The step of the translation the `free` cameras share: Adam on the sum of their translation
/// gradients (the last three of each `grads[k]`).
fn shared_translation_step(
    opt: &mut DenseAdam,
    grads: &[[f32; 9]],
    free: &[usize],
    lr: f32,
) -> DVec3 {
    let mut sum = [0.0f32; 3];
    for &k in free {
        sum.iter_mut()
            .zip(&grads[k][6..])
            .for_each(|(a, b)| *a += b);
    }
    let mut shift = [0.0f32; 3];
    opt.step(&mut shift, &sum, lr);
    DVec3::new(shift[0] as f64, shift[1] as f64, shift[2] as f64)
}

fn pose_grad_flat(g: &super::pose::PoseGrad, w: f64) -> [f32; 9] {
    let mut out = [0.0f32; 9];
    for k in 0..6 {
        out[k] = (g.r6[k] * w) as f32;
    }
    for k in 0..3 {
        out[6 + k] = (g.translation_m[k] * w) as f32;
    }
    out
}

/// Every `every`-th return of `sweep` in the world, each placed with the trajectory at its own
/// firing time (method.md §5; [`world_points`]), or at the sweep's stamp for a deskewed sweep.
/// A sweep reaching outside the trajectory gives none.
fn deskewed_points(
    trajectory: &Trajectory,
    sweep: &LidarSweep,
    vehicle_from_lidar: Rigid,
    every: usize,
) -> Vec<DVec3> {
    world_points(&sweep.view(), trajectory, vehicle_from_lidar, every).unwrap_or_default()
}

impl DepthCalibration {
    /// Build the scene box and occupancy from the sweeps under the initial extrinsics.
    pub fn new(config: DepthCalibConfig, trajectory: Trajectory, lidars: Vec<LidarData>) -> Self {
        let anchor = lidars
            .iter()
            .position(|l| config.frozen_sensor.as_deref() == Some(l.name.as_str()))
            .unwrap_or(0);
        let mut points = Vec::new();
        let mut anchor_points = Vec::new();
        for (k, l) in lidars.iter().enumerate() {
            for s in &l.sweeps {
                for x in deskewed_points(&trajectory, s, l.initial, 4) {
                    points.push(x);
                    if k == anchor {
                        anchor_points.push(x);
                    }
                }
            }
        }
        let occupancy = OccupancyGrid::from_points(&points, 0.5, 1.0, 1);
        let field = SceneField::new(
            occupancy.box_min,
            occupancy.box_max(),
            &config.field,
            config.seed,
        );
        let mlp_params = mlp_flat(&field.geo);
        let poses: Vec<PoseParams> = lidars
            .iter()
            .map(|l| PoseParams::from_rigid(l.initial))
            .collect();
        let intensity_norm: Vec<Option<f32>> = lidars
            .iter()
            .map(|l| normaliser(l.sweeps.iter().flat_map(|s| s.intensity.iter())))
            .collect();
        let decoder = IntensityDecoder::new(config.field.feature_dim, config.seed);
        let decoder_params = mlp_flat(&decoder.mlp);
        let registering =
            config.registration_steps > 0 && config.lidar_pose_update != PoseUpdate::Adam;
        let aggregated = match (config.geometry_init_steps, registering) {
            (0, _) => Vec::new(),
            (_, false) => points,
            (_, true) => anchor_points,
        };
        Self {
            anchor,
            aggregated,
            point_index: None,
            intensity_maps: vec![IntensityMap::default(); lidars.len()],
            newton: lidars
                .iter()
                .map(|_| {
                    NewtonState::new(match config.lidar_pose_update {
                        PoseUpdate::Newton(n) => n,
                        PoseUpdate::Adam => NewtonConfig::default(),
                    })
                })
                .collect(),
            intensity_map_opt: lidars
                .iter()
                .map(|_| DenseAdam::new(2, AdamConfig::STANDARD))
                .collect(),
            intensity_norm,
            decoder_opt: DenseAdam::new(decoder_params.len(), AdamConfig::NGP),
            decoder_params,
            decoder,
            grid_opt: SparseAdam::new(field.grid.params.len(), AdamConfig::NGP),
            grid_accs: accumulators(field.grid.entry_count()),
            mlp_opt: DenseAdam::new(mlp_params.len(), AdamConfig::NGP),
            pose_opt: poses
                .iter()
                .map(|_| DenseAdam::new(9, AdamConfig::STANDARD))
                .collect(),
            beta_opt: DenseAdam::new(1, AdamConfig::STANDARD),
            ln_beta: config.beta_init.ln(),
            mlp_params,
            rng: config.seed,
            iteration: 0,
            camera: None,
            correspondences: Correspondences::default(),
            silhouette_points: Vec::new(),
            silhouette_pixels: (Vec::new(), 0),
            config,
            trajectory,
            lidars,
            field,
            occupancy,
            poses,
        }
    }

    pub fn beta(&self) -> f32 {
        self.ln_beta.exp()
    }

    /// The opacity model at the current β.
    pub fn opacity(&self) -> Opacity {
        Opacity {
            model: self.config.opacity,
            beta: self.beta(),
        }
    }

    /// Add cameras: their extrinsics, exposure maps and the colour term join the optimisation.
    pub fn with_cameras(self, cameras: Vec<CameraData>) -> Self {
        self.with_cameras_reporting(cameras, &|_, _| {})
    }

    /// [`DepthCalibration::with_cameras`], reporting the keypoint matching of the alignment
    /// term as `(pairs done, pairs)`.
    pub fn with_cameras_reporting(
        mut self,
        cameras: Vec<CameraData>,
        matching: super::correspondences::MatchProgress,
    ) -> Self {
        if cameras.is_empty() {
            self.camera = None;
            return self;
        }
        if self.config.alignment != AlignmentLoss::None {
            let extrinsics: Vec<Rigid> = cameras.iter().map(|c| c.initial).collect();
            self.correspondences = super::correspondences::build_cached(
                &cameras,
                &extrinsics,
                &self.trajectory,
                self.config.correspondence_cache.as_deref(),
                matching,
            );
        }
        self.camera = Some(self.camera_stage(cameras));
        self
    }

    /// A fresh scene (field, decoders, exposure maps, optimisers) with every sensor starting
    /// where it is now, the data and the matched correspondences kept: the next round of a
    /// calibration in rounds (a scene formed around the cameras' errors holds them back,
    /// docs/experiments/unical-camera-poses.md; a new one formed at their improved poses does less so).
    pub fn restart(&mut self) {
        let mut lidars = std::mem::take(&mut self.lidars);
        for (l, p) in lidars.iter_mut().zip(&self.poses) {
            l.initial = p.to_rigid();
        }
        let correspondences = std::mem::take(&mut self.correspondences);
        let cameras = self.camera.take().map(|stage| {
            let mut cameras = stage.cameras;
            for (c, p) in cameras.iter_mut().zip(&stage.poses) {
                c.initial = p.to_rigid();
            }
            cameras
        });
        let mut next = Self::new(self.config.clone(), self.trajectory.clone(), lidars);
        next.correspondences = correspondences;
        if let Some(cameras) = cameras.filter(|c| !c.is_empty()) {
            next.camera = Some(next.camera_stage(cameras));
        }
        *self = next;
    }

    /// How crowded the scene's hash tables are over its occupied voxels, level by level
    /// ([`super::hash_load`]).
    pub fn hash_loads(&self) -> Vec<LevelLoad> {
        let (min, size) = (self.field.box_min, self.field.box_size);
        let boxes: Vec<([f64; 3], [f64; 3])> = self
            .occupancy
            .occupied_boxes()
            .map(|(lo, hi)| {
                (
                    ((lo - min) / size).to_array(),
                    ((hi - min) / size).to_array(),
                )
            })
            .collect();
        level_loads(&self.field.grid, &boxes)
    }

    /// The vehicle-frame elevation (rad) above which no camera ray is drawn
    /// ([`DepthCalibConfig::camera_rays_below_lidar_top`]); `None` when every ray is.
    pub fn camera_ray_top_elevation_rad(&self) -> Option<f64> {
        self.camera.as_ref()?.ray_top_elevation_rad
    }

    /// The colour term's state for `cameras`, starting at their `initial` extrinsics.
    fn camera_stage(&self, cameras: Vec<CameraData>) -> CameraStage {
        let appearance = Appearance {
            view_dependent: self.config.view_dependent_colour,
            ..Appearance::new(self.config.field.feature_dim, self.config.seed)
        };
        let (colour_params, sky_params) = (mlp_flat(&appearance.colour), mlp_flat(&appearance.sky));
        let poses: Vec<PoseParams> = cameras
            .iter()
            .map(|c| PoseParams::from_rigid(c.initial))
            .collect();
        let background = self.config.background.as_ref().map(|config| {
            let field = Background::new(
                self.occupancy.box_min,
                self.occupancy.box_max(),
                self.config.field.feature_dim,
                config,
                self.config.seed,
            );
            let mlp_params = mlp_flat(&field.geo);
            BackgroundStage {
                grid_opt: SparseAdam::new(field.grid.params.len(), AdamConfig::NGP),
                grid_accs: accumulators(field.grid.entry_count()),
                mlp_opt: DenseAdam::new(mlp_params.len(), AdamConfig::NGP),
                mlp_params,
                field,
            }
        });
        CameraStage {
            background,
            pose_opt: poses
                .iter()
                .map(|_| DenseAdam::new(9, AdamConfig::STANDARD))
                .collect(),
            shared_translation_opt: DenseAdam::new(3, AdamConfig::STANDARD),
            exposure: vec![ExposureMap::default(); cameras.len()],
            information: vec![PoseInformation::default(); cameras.len()],
            exposure_opt: cameras
                .iter()
                .map(|_| DenseAdam::new(6, AdamConfig::STANDARD))
                .collect(),
            colour_opt: DenseAdam::new(colour_params.len(), AdamConfig::NGP),
            colour_params,
            sky_opt: DenseAdam::new(sky_params.len(), AdamConfig::NGP),
            sky_params,
            appearance,
            poses,
            cameras,
            ray_top_elevation_rad: self
                .config
                .camera_rays_below_lidar_top
                .then(|| super::coverage::lidar_top_elevation_rad(&self.lidars))
                .flatten(),
        }
    }

    /// Current extrinsics, by sensor name (LiDARs, then cameras).
    pub fn extrinsics(&self) -> Vec<(String, Rigid)> {
        let mut out: Vec<(String, Rigid)> = self
            .lidars
            .iter()
            .zip(&self.poses)
            .map(|(l, p)| (l.name.clone(), p.to_rigid()))
            .collect();
        if let Some(c) = &self.camera {
            out.extend(
                c.cameras
                    .iter()
                    .zip(&c.poses)
                    .map(|(cam, p)| (cam.name.clone(), p.to_rigid())),
            );
        }
        out
    }

    /// Move sensor `name` to `vehicle_from_sensor` and restart its pose optimiser (probes:
    /// a scene learned at one calibration, the sensor started elsewhere). False for an unknown
    /// name.
    pub fn set_extrinsic(&mut self, name: &str, vehicle_from_sensor: Rigid) -> bool {
        if let Some(k) = self.lidars.iter().position(|l| l.name == name) {
            self.poses[k] = PoseParams::from_rigid(vehicle_from_sensor);
            self.pose_opt[k] = DenseAdam::new(9, AdamConfig::STANDARD);
            return true;
        }
        let Some(stage) = self.camera.as_mut() else {
            return false;
        };
        let Some(k) = stage.cameras.iter().position(|c| c.name == name) else {
            return false;
        };
        stage.poses[k] = PoseParams::from_rigid(vehicle_from_sensor);
        stage.pose_opt[k] = DenseAdam::new(9, AdamConfig::STANDARD);
        true
    }

    /// Whether LiDAR `s` shapes the scene at this iteration (outside the registration phase
    /// every LiDAR does; inside it only the anchor).
    fn shapes_scene(&self, s: usize) -> bool {
        s == self.anchor
            || self.iteration >= self.config.pose_warmup + self.config.registration_steps
            || self.config.registration_steps == 0
            || self.config.lidar_pose_update == PoseUpdate::Adam
    }

    /// The cameras' pose rate at this iteration, scaled by their ray budget against
    /// [`CAMERA_RATE_RAYS`] ([`DepthCalibConfig::lr_camera_pose`]).
    fn camera_rate_now(&self) -> f32 {
        let ray_share = (self.config.rays_per_camera as f32 / CAMERA_RATE_RAYS as f32).min(1.0);
        self.config.camera_pose_rate(
            self.config.lr_camera_pose * ray_share,
            self.config.camera_pose_final_fraction,
            self.iteration,
        )
    }

    /// Per camera, whether its extrinsic stays fixed.
    fn frozen_cameras(&self) -> Vec<bool> {
        self.camera.as_ref().map_or_else(Vec::new, |c| {
            c.cameras
                .iter()
                .map(|cam| self.is_frozen(&cam.name))
                .collect()
        })
    }

    /// Whether `name`'s extrinsic stays fixed: the root or a held sensor.
    fn is_frozen(&self, name: &str) -> bool {
        self.config.frozen_sensor.as_deref() == Some(name)
            || self.config.held_sensors.iter().any(|h| h == name)
    }

    /// Current intensity mappings, by LiDAR name (only LiDARs that report intensity).
    pub fn intensity_maps(&self) -> Vec<(String, IntensityMap)> {
        self.lidars
            .iter()
            .zip(&self.intensity_maps)
            .zip(&self.intensity_norm)
            .filter(|(_, norm)| norm.is_some())
            .map(|((l, m), _)| (l.name.clone(), *m))
            .collect()
    }

    /// Whether any LiDAR reports intensity (the intensity term is on).
    pub fn has_intensity(&self) -> bool {
        self.intensity_norm.iter().any(Option::is_some)
    }

    /// Whether cameras take part (the colour term is on).
    pub fn has_cameras(&self) -> bool {
        self.camera.is_some()
    }

    /// Current exposure maps, by camera name.
    pub fn exposures(&self) -> Vec<(String, ExposureMap)> {
        self.camera.as_ref().map_or_else(Vec::new, |c| {
            c.cameras
                .iter()
                .zip(&c.exposure)
                .map(|(cam, e)| (cam.name.clone(), *e))
                .collect()
        })
    }

    /// Render what camera `name` sees at `stamp_nanos` with the current scene, pose and
    /// exposure, at the resolution it trains on (row-major RGB, `width × height × 3`; `None`
    /// for an unknown camera or a time outside the trajectory). Forward only, parallel over
    /// rows; samples sit at the middle of their 10 cm steps. For photometric checks of frames
    /// the optimisation did not see (method.md §13).
    pub fn render_camera(&self, name: &str, stamp_nanos: i64) -> Option<(u32, u32, Vec<u8>)> {
        let stage = self.camera.as_ref()?;
        let k = stage.cameras.iter().position(|c| c.name == name)?;
        let (cam, pose, exposure) = (&stage.cameras[k], stage.poses[k], stage.exposure[k]);
        // Each row's vehicle pose; `None` when a row's time is outside the trajectory.
        let row_poses: Vec<Rigid> = (0..cam.intrinsics.height)
            .map(|y| {
                self.trajectory
                    .world_from_vehicle(cam.row_stamp_nanos(stamp_nanos, y as f64))
                    .ok()
            })
            .collect::<Option<_>>()?;
        let model = CameraModel {
            field: &self.field,
            background: stage.background.as_ref().map(|b| &b.field),
            appearance: &stage.appearance,
            opacity: self.opacity(),
            pose_levels: None,
        };
        let (w, h) = (cam.intrinsics.width, cam.intrinsics.height);
        let rows: Vec<Vec<u8>> = (0..h)
            .into_par_iter()
            .map(|y| {
                let mut row = Vec::with_capacity(3 * w as usize);
                let wv = row_poses[y as usize];
                for x in 0..w {
                    let rgb = match cam.intrinsics.unproject(DVec2::new(x as f64, y as f64)) {
                        Some(u) => {
                            let (o, d) = pose.ray(wv, u);
                            let ray = ColourRay {
                                world_from_vehicle: wv,
                                dir_in_sensor: u,
                                target: [0.0; 3],
                                taus_m: self.camera_taus(o, d, 0.5),
                                background_taus_m: stage
                                    .background
                                    .as_ref()
                                    .map_or_else(Vec::new, |b| b.field.taus(o, d, 0.5)),
                            };
                            render_colour(model, &pose, &exposure, &ray)
                        }
                        None => [0.0; 3],
                    };
                    row.extend(rgb.map(|v| (v * 255.0).round() as u8));
                }
                row
            })
            .collect();
        Some((w, h, rows.concat()))
    }

    /// The intrinsics camera `name` trains with (its images' size), if it takes part.
    pub fn camera_intrinsics(&self, name: &str) -> Option<&CameraIntrinsics> {
        let stage = self.camera.as_ref()?;
        stage
            .cameras
            .iter()
            .find(|c| c.name == name)
            .map(|c| &c.intrinsics)
    }

    /// Sample distances of a camera ray from `o` along `d` in the occupied space (10 cm steps,
    /// from 0.3 m to `camera_far_m`, stratified by `jitter`).
    fn camera_taus(&self, o: DVec3, d: DVec3, jitter: f64) -> Vec<f32> {
        self.occupancy.sample(
            o,
            d,
            0.3,
            self.config.camera_far_m,
            self.config.step_m,
            jitter,
            self.config.max_samples_per_ray,
        )
    }

    /// A matched pixel's ray at its frame's time, sampled like a colour ray.
    fn align_ray(&mut self, (camera, frame): (usize, usize), pixel: DVec2) -> Option<AlignRay> {
        let stage = self.camera.as_ref()?;
        let cam = stage.cameras.get(camera)?;
        let stamp = cam.row_stamp_nanos(cam.frames.get(frame)?.stamp_nanos, pixel.y);
        let u = cam.intrinsics.unproject(pixel)?;
        let wv = self.trajectory.world_from_vehicle(stamp).ok()?;
        let (o, d) = stage.poses[camera].ray(wv, u);
        let jitter = unit(&mut self.rng);
        let taus_m = self.camera_taus(o, d, jitter);
        Some(AlignRay {
            world_from_vehicle: wv,
            dir_in_sensor: u,
            pixel,
            taus_m,
        })
    }

    /// The correspondence term of this step (§9): every camera takes a random pair it is part
    /// of and up to `alignment_matches_per_camera` of its matches; gradients are weighted by
    /// λ_align / cameras, the hash table's go to the first accumulator.
    fn alignment_gradients(&mut self) -> AlignmentGrads {
        let cameras = self.camera.as_ref().map_or(0, |c| c.cameras.len());
        let mut out = AlignmentGrads {
            pose: vec![[0.0; 9]; cameras],
            geo: self.field.geo.zero_grad(),
            beta_grad: 0.0,
            loss: 0.0,
            kept: 0,
        };
        if self.config.alignment == AlignmentLoss::None || self.correspondences.pairs.is_empty() {
            return out;
        }
        // Draw every batch first (the generator advances), then evaluate them.
        let mut batches = Vec::new();
        for k in 0..cameras {
            let owned = self.correspondences.by_camera[k].len();
            if owned == 0 {
                continue;
            }
            let pi =
                self.correspondences.by_camera[k][(next(&mut self.rng) % owned as u64) as usize];
            let (a, b, count) = {
                let p = &self.correspondences.pairs[pi];
                (p.a, p.b, p.pixels.len())
            };
            let n = self.config.alignment_matches_per_camera.min(count);
            let mut rays = Vec::with_capacity(n);
            for _ in 0..n {
                let j = (next(&mut self.rng) % count as u64) as usize;
                let (ua, ub) = self.correspondences.pairs[pi].pixels[j];
                if let (Some(ra), Some(rb)) = (self.align_ray(a, ua), self.align_ray(b, ub)) {
                    rays.push((ra, rb));
                }
            }
            batches.push((a.0, b.0, rays));
        }
        let Some(stage) = self.camera.as_ref() else {
            return out;
        };
        let opacity = self.opacity();
        let w = self.config.alignment_weight as f64 / cameras.max(1) as f64;
        let track_information = self.config.camera_hold_unobserved.is_some();
        let settings = AlignSettings {
            information: track_information,
            ..self.config.alignment_settings
        };
        let alignment = self.config.alignment;
        let batch_count = batches.len().max(1) as f64;
        let field = &self.field;
        // Batches in parallel, each group of them into its own accumulator (deterministic).
        let group = batches.len().div_ceil(self.grid_accs.len()).max(1);
        let steps: Vec<Vec<(usize, usize, AlignStep)>> = batches
            .chunks(group)
            .zip(self.grid_accs.iter_mut())
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|(chunk, acc)| {
                chunk
                    .iter()
                    .map(|(a, b, rays)| {
                        let camera = |k: usize| AlignCamera {
                            pose: &stage.poses[k],
                            intrinsics: &stage.cameras[k].intrinsics,
                            pixel_scale: 1920.0 / stage.cameras[k].intrinsics.width.max(1) as f64,
                        };
                        let step = match alignment {
                            AlignmentLoss::SurfaceAlignment => surface_alignment_step(
                                field,
                                opacity,
                                (camera(*a), camera(*b)),
                                rays,
                                &settings,
                                &mut Scaled {
                                    acc: &mut *acc,
                                    scale: w as f32,
                                },
                            ),
                            AlignmentLoss::ProjectedRayDistance => projected_ray_step(
                                (camera(*a), camera(*b)),
                                rays,
                                settings.max_error_px,
                            ),
                            AlignmentLoss::None => AlignStep::default(),
                        };
                        (*a, *b, step)
                    })
                    .collect()
            })
            .collect();
        let mut information = vec![PoseInformation::default(); cameras];
        for (a, b, step) in steps.into_iter().flatten() {
            if track_information {
                information[a].merge(&step.info_a);
                information[b].merge(&step.info_b);
            }
            let (ga, gb) = (
                pose_grad_flat(&step.pose_a, w),
                pose_grad_flat(&step.pose_b, w),
            );
            out.pose[a].iter_mut().zip(ga).for_each(|(x, y)| *x += y);
            out.pose[b].iter_mut().zip(gb).for_each(|(x, y)| *x += y);
            add_scaled(&mut out.geo, &step.geo, w as f32);
            out.beta_grad += step.beta_grad * w;
            out.loss += step.loss / batch_count;
            out.kept += step.kept;
        }
        if let Some(stage) = self.camera.as_mut().filter(|_| track_information) {
            for (held, new) in stage.information.iter_mut().zip(&information) {
                held.decay(INFORMATION_FORGETTING);
                held.merge(new);
            }
        }
        out
    }

    /// The heat maps' σ in pixels of an image `width` wide at this iteration (§10: geometric
    /// from the first to the last value), or `None` while pixels are drawn uniformly.
    pub fn heatmap_sigma(&self, width: f64) -> Option<f64> {
        let total = self.config.iterations.max(1) as f64;
        let start = (self.config.heatmap_start_fraction as f64 * total).round();
        if self.config.heatmap_start_fraction >= 1.0 || (self.iteration as f64) < start {
            return None;
        }
        let progress = ((self.iteration as f64 - start) / (total - start).max(1.0)).clamp(0.0, 1.0);
        let (first, last) = self.config.heatmap_sigma_px;
        let sigma_1920 = first * (last / first).powf(progress);
        Some(sigma_1920 * width / 1920.0)
    }

    /// Project every LiDAR's silhouette points (of its sweep nearest each frame) into every
    /// camera frame under the current poses, for [`DepthCalibConfig::silhouette_share`].
    fn refresh_silhouettes(&mut self) {
        let Some(stage) = &self.camera else {
            return;
        };
        if self.silhouette_points.is_empty() {
            self.silhouette_points = self
                .lidars
                .iter()
                .map(|l| {
                    l.sweeps
                        .par_iter()
                        .map(|s| {
                            crate::eval::edges::depth_discontinuities(&s.points_in_sensor, 0.05)
                                .into_iter()
                                .map(|i| i as u32)
                                .collect()
                        })
                        .collect()
                })
                .collect();
        }
        let lidar_poses: Vec<Rigid> = self.poses.iter().map(|p| p.to_rigid()).collect();
        let (lidars, trajectory, points) =
            (&self.lidars, &self.trajectory, &self.silhouette_points);
        let pixels = stage
            .cameras
            .iter()
            .zip(&stage.poses)
            .map(|(cam, pose)| {
                let vehicle_from_camera = pose.to_rigid();
                cam.frames
                    .par_iter()
                    .map(|f| {
                        let Some(middle) = cam.camera_from_world_at(
                            trajectory,
                            vehicle_from_camera,
                            cam.middle_stamp_nanos(f.stamp_nanos),
                        ) else {
                            return Vec::new();
                        };
                        let mut out = Vec::new();
                        for ((lidar, vehicle_from_lidar), indices) in
                            lidars.iter().zip(&lidar_poses).zip(points)
                        {
                            let Some((s, idx)) = lidar
                                .sweeps
                                .iter()
                                .zip(indices)
                                .min_by_key(|(s, _)| (s.stamp_nanos - f.stamp_nanos).abs())
                            else {
                                continue;
                            };
                            for &i in idx {
                                let [x, y, z] = s.points_in_sensor[i as usize];
                                let offset_s = s
                                    .time_offset_secs
                                    .as_ref()
                                    .and_then(|t| t.get(i as usize))
                                    .map_or(0.0, |&t| t as f64);
                                let stamp = s.stamp_nanos + (offset_s * 1e9) as i64;
                                let Ok(wv_point) = trajectory.world_from_vehicle(stamp) else {
                                    continue;
                                };
                                let p = DVec3::new(x as f64, y as f64, z as f64);
                                let p_world =
                                    wv_point.transform_point(vehicle_from_lidar.transform_point(p));
                                if let Some(px) = cam.project_world_from(
                                    trajectory,
                                    vehicle_from_camera,
                                    f.stamp_nanos,
                                    middle,
                                    p_world,
                                ) {
                                    out.push((px.x as f32, px.y as f32));
                                }
                            }
                        }
                        out
                    })
                    .collect()
            })
            .collect();
        self.silhouette_pixels = (pixels, self.iteration);
    }

    fn draw_camera_rays(&mut self, camera: usize) -> Vec<ColourRay> {
        let Some(stage) = &self.camera else {
            return Vec::new();
        };
        let (cam, pose) = (&stage.cameras[camera], stage.poses[camera]);
        let mut rays = Vec::with_capacity(self.config.rays_per_camera);
        if cam.frames.is_empty() {
            return rays;
        }
        let (w, h) = (cam.intrinsics.width as u64, cam.intrinsics.height as u64);
        let sigma = self.heatmap_sigma(w as f64);
        let mut attempts = 0;
        while rays.len() < self.config.rays_per_camera && attempts < 4 * self.config.rays_per_camera
        {
            attempts += 1;
            let frame = (next(&mut self.rng) % cam.frames.len() as u64) as usize;
            let f = &cam.frames[frame];
            let silhouettes = self
                .silhouette_pixels
                .0
                .get(camera)
                .and_then(|frames| frames.get(frame))
                .filter(|pixels| !pixels.is_empty());
            let from_silhouette = sigma.is_some()
                && silhouettes.is_some()
                && unit(&mut self.rng) < self.config.silhouette_share;
            let from_heatmap = !from_silhouette
                && sigma.is_some_and(|_| {
                    !f.keypoints.is_empty()
                        && unit(&mut self.rng) >= self.config.heatmap_uniform_share
                });
            let centre = match (from_silhouette, silhouettes) {
                (true, Some(pixels)) => {
                    Some(pixels[(next(&mut self.rng) % pixels.len() as u64) as usize])
                }
                _ if from_heatmap => {
                    let k = &f.keypoints[(next(&mut self.rng) % f.keypoints.len() as u64) as usize];
                    Some((k.x, k.y))
                }
                _ => None,
            };
            let (x, y) = match sigma.zip(centre) {
                // A draw from Σ_k G_σ(u − u_k): a random keypoint (or silhouette pixel) plus
                // Gaussian noise.
                Some((sigma, (kx, ky))) => {
                    let (gx, gy) = gaussian_pair(&mut self.rng);
                    let px = (kx as f64 + sigma * gx).round().clamp(0.0, (w - 1) as f64);
                    let py = (ky as f64 + sigma * gy).round().clamp(0.0, (h - 1) as f64);
                    (px as u64, py as u64)
                }
                None => (
                    next(&mut self.rng) % w.max(1),
                    next(&mut self.rng) % h.max(1),
                ),
            };
            if f.masked.get((y * w + x) as usize) == Some(&true) {
                continue;
            }
            let k = 3 * (y * w + x) as usize;
            let Some(px) = f.rgb.get(k..k + 3) else {
                continue;
            };
            let Some(u) = cam.intrinsics.unproject(DVec2::new(x as f64, y as f64)) else {
                continue;
            };
            let stamp = cam.row_stamp_nanos(f.stamp_nanos, y as f64);
            let Ok(wv) = self.trajectory.world_from_vehicle(stamp) else {
                continue;
            };
            let (o, d) = pose.ray(wv, u);
            if stage
                .ray_top_elevation_rad
                .is_some_and(|top| super::coverage::ray_elevation_rad(wv, d) > top)
            {
                continue;
            }
            let jitter = unit(&mut self.rng);
            let taus = self.camera_taus(o, d, jitter);
            let background_taus_m = stage.background.as_ref().map_or_else(Vec::new, |b| {
                let jitter = (next(&mut self.rng) >> 11) as f64 / (1u64 << 53) as f64;
                b.field.taus(o, d, jitter)
            });
            rays.push(ColourRay {
                world_from_vehicle: wv,
                dir_in_sensor: u,
                target: [px[0], px[1], px[2]].map(|v| v as f32 / 255.0),
                taus_m: taus,
                background_taus_m,
            });
        }
        rays
    }

    /// A random return of `sensor`: `world_from_vehicle` at its firing time, its direction
    /// in the sensor frame, range and normalised intensity (`None` if unusable).
    fn draw_return(&mut self, sensor: usize) -> Option<(Rigid, DVec3, f64, Option<f32>)> {
        let sweeps = &self.lidars[sensor].sweeps;
        if sweeps.is_empty() {
            return None;
        }
        let s = &sweeps[(next(&mut self.rng) % sweeps.len() as u64) as usize];
        if s.points_in_sensor.is_empty() {
            return None;
        }
        let i = (next(&mut self.rng) % s.points_in_sensor.len() as u64) as usize;
        let p = s.points_in_sensor[i];
        let intensity = self.intensity_norm[sensor]
            .zip(s.intensity.get(i))
            .map(|(k, raw)| (raw * k).clamp(0.0, 1.0));
        let v = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        let range = v.length();
        let u = v.try_normalize()?;
        if range < 1.0 {
            return None;
        }
        let t = s.stamp_nanos
            + s.time_offset_secs
                .as_ref()
                .and_then(|t| t.get(i))
                .map_or(0, |x| (*x as f64 * 1e9) as i64);
        let wv = self.trajectory.world_from_vehicle(t).ok()?;
        Some((wv, u, range, intensity))
    }

    fn draw_rays(&mut self, sensor: usize, count: usize) -> Vec<DepthRay> {
        let pose = self.poses[sensor];
        let mut rays = Vec::with_capacity(count);
        if self.lidars[sensor].sweeps.is_empty() {
            return rays;
        }
        let mut attempts = 0;
        while rays.len() < count && attempts < 4 * count {
            attempts += 1;
            let Some((wv, u, range, intensity)) = self.draw_return(sensor) else {
                continue;
            };
            let (o, d) = pose.ray(wv, u);
            let jitter = (next(&mut self.rng) >> 11) as f64 / (1u64 << 53) as f64;
            let taus = self.occupancy.sample_towards(
                o,
                d,
                0.5,
                range + 2.0,
                self.config.step_m,
                jitter,
                self.config.max_samples_per_ray,
            );
            if taus.is_empty() {
                continue;
            }
            rays.push(DepthRay {
                world_from_vehicle: wv,
                dir_in_sensor: u,
                range_m: range as f32,
                intensity,
                taus_m: taus,
            });
        }
        rays
    }

    /// One iteration of the geometry initialisation: the SDF fitted to LiDAR returns under the
    /// current (initial) extrinsics, in parallel chunks, Adam on the grid and geometry MLP.
    fn geometry_init_step(&mut self) -> DepthReport {
        let (alignment_loss, alignment_matches) = self.alignment_pose_step();
        let lidars = self.lidars.len().max(1);
        let per_sensor = self.config.geometry_init_rays.div_ceil(lidars);
        let mut rays = Vec::with_capacity(per_sensor * lidars);
        for s in 0..self.lidars.len() {
            if !self.shapes_scene(s) {
                continue;
            }
            let pose = self.poses[s];
            let mut drawn = 0;
            for _ in 0..2 * per_sensor {
                if drawn == per_sensor {
                    break;
                }
                let Some((wv, u, range, _)) = self.draw_return(s) else {
                    continue;
                };
                let (origin, dir) = pose.ray(wv, u);
                let uniform = |rng: &mut u64| (next(rng) >> 11) as f64 / (1u64 << 53) as f64;
                let (u_front, u_behind) = (uniform(&mut self.rng), uniform(&mut self.rng));
                rays.push((origin, dir, range, u_front, u_behind));
                drawn += 1;
            }
        }
        let index = self
            .point_index
            .get_or_insert_with(|| PointIndex::new(&self.aggregated));
        let rays: Vec<SdfRay> = rays
            .into_par_iter()
            .map(|(o, d, range, u_front, u_behind)| {
                SdfRay::new(o, d, range, u_front, u_behind, index)
            })
            .collect();
        let chunk = rays.len().div_ceil(self.grid_accs.len()).max(1);
        let total = rays.len().max(1) as f64;
        let field = &self.field;
        let parts: Vec<(f64, super::mlp::MlpGrad)> = rays
            .par_chunks(chunk)
            .zip(self.grid_accs.par_iter_mut())
            .map(|(c, acc)| {
                let share = c.len() as f64 / total;
                let mut sink = Scaled { acc, scale: 1.0 };
                let mut mlp = field.geo.zero_grad();
                let loss = sdf_fit_step(field, c, share as f32, &mut sink, &mut mlp);
                (loss * share, mlp)
            })
            .collect();
        let mut geo = self.field.geo.zero_grad();
        let mut loss = 0.0;
        for (l, g) in parts {
            loss += l;
            add_scaled(&mut geo, &g, 1.0);
        }
        let lr = decayed_lr(
            self.config.lr_field,
            0.1,
            self.iteration,
            self.config.iterations,
        );
        self.grid_opt
            .step_accumulated(&mut self.field.grid.params, &mut self.grid_accs, lr);
        self.mlp_opt
            .step(&mut self.mlp_params, &grad_flat(&geo), lr);
        mlp_set(&mut self.field.geo, &self.mlp_params);
        self.iteration += 1;
        DepthReport {
            loss: 0.0,
            mean_abs_error_m: 0.0,
            beta: self.beta(),
            colour_loss: 0.0,
            intensity_loss: 0.0,
            regulariser_loss: 0.0,
            geometry_init_loss: Some(loss),
            alignment_loss,
            alignment_matches,
        }
    }

    /// During the geometry initialisation, from [`DepthCalibConfig::alignment_release`]: the
    /// cameras step on the correspondence term alone, rendered through the SDF as it is being
    /// fitted (whose parameters take no gradient from it). Returns the term and its kept
    /// matches.
    fn alignment_pose_step(&mut self) -> (f64, usize) {
        if self.iteration < self.config.camera_release() || self.camera.is_none() {
            return (0.0, 0);
        }
        let lr = self.camera_rate_now();
        let mut align = self.alignment_gradients();
        if !self.config.alignment_release_rotates {
            // Adam's moments stay at zero for the rotation: it does not move.
            align.pose.iter_mut().for_each(|g| g[..6].fill(0.0));
        }
        // Its hash-grid gradients went to the accumulators: the SDF fit must not see them.
        drop(GradAccumulator::drain_all(&mut self.grid_accs));
        let frozen = self.frozen_cameras();
        if let Some(stage) = self.camera.as_mut() {
            stage.step_poses(&align.pose, &frozen, lr, &self.config, self.iteration);
        }
        (align.loss, align.kept)
    }

    /// Diagnostics: `(true range, rendered − true range, elevation of the ray in the world,
    /// rad)` for `count` random returns of LiDAR `sensor` under the current state.
    pub fn depth_residuals(&mut self, sensor: usize, count: usize) -> Vec<DepthResidual> {
        let rays = self.draw_rays(sensor, count);
        let (field, opacity, pose) = (&self.field, self.opacity(), self.poses[sensor]);
        rays.par_iter()
            .map(|r| {
                let c = super::lidar_terms::render_composite(field, opacity, &pose, r);
                let (_, d) = pose.ray(r.world_from_vehicle, r.dir_in_sensor);
                DepthResidual {
                    range_m: r.range_m,
                    error_m: c.depth_m - r.range_m,
                    elevation_rad: d.z.asin() as f32,
                    accumulation: c.accumulation,
                }
            })
            .collect()
    }

    /// Diagnostics: `count` rays of LiDAR `sensor` drawn under its current pose (their sample
    /// distances fixed), to evaluate [`DepthCalibration::lidar_objective`] on one batch.
    pub fn lidar_batch(&mut self, sensor: usize, count: usize) -> Vec<DepthRay> {
        self.draw_rays(sensor, count)
    }

    /// Diagnostics: the weighted LiDAR objective of `rays` (depth, intensity, regulariser) with
    /// `sensor` at `pose`, its gradient with respect to that pose, and (with preconditioned
    /// pose steps) the robust point-to-plane system those steps solve.
    pub fn lidar_objective(
        &self,
        sensor: usize,
        pose: &PoseParams,
        rays: &[DepthRay],
    ) -> (f64, super::pose::PoseGrad, TangentSystem) {
        self.lidar_objective_where(sensor, pose, rays, |_| true)
    }

    /// [`Self::lidar_objective`] with the preconditioned steps' system built from the rows
    /// `keep` accepts (e.g. only surfaces another sensor sees too).
    pub fn lidar_objective_where(
        &self,
        sensor: usize,
        pose: &PoseParams,
        rays: &[DepthRay],
        keep: impl Fn(&super::pose_newton::PoseRow) -> bool,
    ) -> (f64, super::pose::PoseGrad, TangentSystem) {
        let model = LidarModel {
            field: &self.field,
            opacity: self.opacity(),
            decoder: self.intensity_norm[sensor].map(|_| &self.decoder),
        };
        let weights = self.config.lidar_weights();
        let mut sink: Option<super::hash_grid::SparseGrad> = None;
        let part = lidar_step(
            model,
            pose,
            &self.intensity_maps[sensor],
            &weights,
            rays,
            &mut sink,
        );
        let loss = weights.depth as f64 * part.depth_loss
            + weights.intensity as f64 * part.intensity_loss
            + weights.regulariser as f64 * part.regulariser_loss;
        let system = match self.config.lidar_pose_update {
            PoseUpdate::Newton(n) => {
                let mut rows = part.pose_rows;
                rows.retain(|r| keep(r));
                robust_system(&rows, n.robust_scale, n.robust_floor_m)
            }
            PoseUpdate::Adam => TangentSystem::default(),
        };
        (loss, part.pose, system)
    }

    /// Whether the next step is still part of the geometry initialisation.
    pub fn initialising_geometry(&self) -> bool {
        self.iteration < self.config.geometry_init_steps
    }

    /// One optimisation step over every sensor: the same number of rays from each LiDAR (depth)
    /// and each camera (colour), gradients weighted by the objective's λs (§8).
    pub fn step(&mut self) -> DepthReport {
        if let Some(c2f) = self.config.coarse_to_fine {
            let levels = self.field.grid.config.levels as f32;
            let end = (c2f.end_fraction * self.config.iterations as f32).max(1.0);
            let progress = (self.iteration as f32 / end).min(1.0);
            let active = c2f.start_levels + (levels - c2f.start_levels) * progress;
            self.field.grid.set_active_levels(active);
        }
        if self.initialising_geometry() {
            return self.geometry_init_step();
        }
        if self.point_index.is_some() || !self.aggregated.is_empty() {
            self.point_index = None;
            self.aggregated = Vec::new();
        }
        let total = self.config.iterations;
        let lr_field = decayed_lr(self.config.lr_field, 0.1, self.iteration, total);
        let lr_pose = self
            .config
            .pose_rate(self.config.lr_pose, 0.01, self.iteration);
        let lr_camera_pose = self.camera_rate_now();
        // Before the warm-up's end only the correspondence term moves cameras; at its end their
        // schedule starts again (DepthCalibConfig::alignment_release).
        let colour_moves_poses = self.iteration >= self.config.pose_warmup;
        if self.iteration == self.config.pose_warmup
            && self.config.camera_release() < self.config.pose_warmup
            && let Some(stage) = self.camera.as_mut()
        {
            stage.restart_pose_optimisers();
        }
        let mut geo = self.field.geo.zero_grad();
        let mut beta_grad = 0.0;
        let (mut loss, mut mae, mut colour_loss) = (0.0, 0.0, 0.0);
        let (mut intensity_loss, mut regulariser_loss) = (0.0, 0.0);
        let lidars = self.lidars.len().max(1) as f64;
        let base_weights = self.config.lidar_weights();
        let mut decoder_grad = self.decoder.mlp.zero_grad();
        let with_intensity = self.intensity_norm.iter().flatten().count().max(1) as f64;
        for s in 0..self.lidars.len() {
            let rays = self.draw_rays(s, self.config.rays_per_sensor);
            if rays.is_empty() {
                continue;
            }
            let chunk = rays.len().div_ceil(self.grid_accs.len()).max(1);
            let model = LidarModel {
                field: &self.field,
                opacity: self.opacity(),
                decoder: self.intensity_norm[s].map(|_| &self.decoder),
            };
            let (pose, map) = (&self.poses[s], &self.intensity_maps[s]);
            // Registration phase: a LiDAR other than the anchor clears free space in front of
            // its returns and tracks the anchor's surfaces, but places none of its own.
            let weights = LidarWeights {
                free_space_only: !self.shapes_scene(s),
                ..base_weights
            };
            let total_rays = rays.len() as f64;
            let parts: Vec<_> = rays
                .par_chunks(chunk)
                .zip(self.grid_accs.par_iter_mut())
                .map(|(c, acc)| {
                    // lidar_step averages over its chunk: weight chunks by size, sensors
                    // equally.
                    let share = c.len() as f64 / total_rays / lidars;
                    let mut sink = Scaled {
                        acc,
                        scale: share as f32,
                    };
                    let part = lidar_step(model, pose, map, &weights, c, &mut sink);
                    (c.len(), part)
                })
                .collect();
            let mut pose_grad = [0.0f32; 9];
            let mut map_grad = [0.0f32; 2];
            let mut rows = Vec::new();
            for (n, mut part) in parts {
                let share = n as f64 / total_rays / lidars;
                loss += part.depth_loss * share;
                mae += part.mean_abs_error_m * share * lidars;
                intensity_loss += part.intensity_loss * share * lidars / with_intensity;
                regulariser_loss += part.regulariser_loss * share;
                beta_grad += part.beta_grad * share;
                add_scaled(&mut geo, &part.mlp, share as f32);
                add_scaled(&mut decoder_grad, &part.decoder, share as f32);
                let g = pose_grad_flat(&part.pose, share);
                pose_grad.iter_mut().zip(g).for_each(|(a, b)| *a += b);
                map_grad[0] += (part.intensity_map[0] * share) as f32;
                map_grad[1] += (part.intensity_map[1] * share) as f32;
                rows.append(&mut part.pose_rows);
            }
            if !self.is_frozen(&self.lidars[s].name) {
                match self.config.lidar_pose_update {
                    PoseUpdate::Adam => pose_step(
                        &mut self.pose_opt[s],
                        &mut self.poses[s],
                        &pose_grad,
                        lr_pose,
                        1.0,
                    ),
                    // The step fraction follows the pose learning rate's schedule.
                    // Full steps after the warm-up: each solves the gathered rows, which
                    // already average the batches' noise (no learning-rate decay).
                    PoseUpdate::Newton(_) if lr_pose > 0.0 => {
                        if self.newton[s].gather(&mut rows) {
                            self.newton[s].step(&mut self.poses[s], 1.0);
                        }
                    }
                    PoseUpdate::Newton(_) => {}
                }
            }
            if self.intensity_norm[s].is_some() {
                let m = &mut self.intensity_maps[s];
                let mut flat = [m.scale, m.offset];
                self.intensity_map_opt[s].step(&mut flat, &map_grad, lr_field);
                (m.scale, m.offset) = (flat[0], flat[1]);
            }
        }
        if self.intensity_norm.iter().any(Option::is_some) {
            self.decoder_opt.step(
                &mut self.decoder_params,
                &grad_flat(&decoder_grad),
                lr_field,
            );
            mlp_set(&mut self.decoder.mlp, &self.decoder_params);
        }
        let cameras = self.camera.as_ref().map_or(0, |c| c.cameras.len());
        let frozen = self.frozen_cameras();
        let align = self.alignment_gradients();
        add_scaled(&mut geo, &align.geo, 1.0);
        beta_grad += align.beta_grad;
        if let Some(stage) = self.camera.as_ref() {
            let mut colour = stage.appearance.colour.zero_grad();
            let mut sky = stage.appearance.sky.zero_grad();
            let mut background_mlp = stage
                .background
                .as_ref()
                .map_or_else(super::mlp::MlpGrad::default, |b| b.field.geo.zero_grad());
            let rgb_weight = self.config.rgb_weight as f64;
            let opacity = self.opacity();
            let stale = self.silhouette_pixels.0.is_empty()
                || self.iteration >= self.silhouette_pixels.1 + SILHOUETTE_REFRESH;
            if self.config.silhouette_share > 0.0 && self.heatmap_sigma(1920.0).is_some() && stale {
                self.refresh_silhouettes();
            }
            let mut pose_grads = vec![[0.0f32; 9]; cameras];
            // Cameras without rays this step keep their pose.
            let mut held = frozen.clone();
            for k in 0..cameras {
                let rays = self.draw_camera_rays(k);
                let Some(stage) = self.camera.as_mut() else {
                    break;
                };
                if rays.is_empty() {
                    held[k] = true;
                    continue;
                }
                let chunk = rays.len().div_ceil(self.grid_accs.len()).max(1);
                let (background, mut background_accs) = match stage.background.as_mut() {
                    Some(b) => (Some(&b.field), Some(b.grid_accs.iter_mut())),
                    None => (None, None),
                };
                let model = CameraModel {
                    field: &self.field,
                    background,
                    appearance: &stage.appearance,
                    opacity,
                    pose_levels: self.config.colour_pose_levels,
                };
                let (pose, exposure) = (&stage.poses[k], &stage.exposure[k]);
                let total_rays = rays.len() as f64;
                let jobs: Vec<_> = rays
                    .chunks(chunk)
                    .zip(self.grid_accs.iter_mut())
                    .map(|(c, acc)| (c, acc, background_accs.as_mut().and_then(|a| a.next())))
                    .collect();
                let parts: Vec<_> = jobs
                    .into_par_iter()
                    .map(|(c, acc, background_acc)| {
                        let w = (c.len() as f64 / total_rays / cameras as f64 * rgb_weight) as f32;
                        let mut sink = Scaled { acc, scale: w };
                        let mut background_sink =
                            background_acc.map(|acc| Scaled { acc, scale: w });
                        let part =
                            colour_step(model, pose, exposure, c, &mut sink, &mut background_sink);
                        (c.len(), part)
                    })
                    .collect();
                let mut pose_grad = align.pose[k];
                let mut exposure_grad = [0.0f32; 6];
                for (n, part) in parts {
                    let share = n as f64 / total_rays / cameras as f64;
                    let w = share * rgb_weight;
                    colour_loss += part.loss * share;
                    beta_grad += part.beta_grad * w;
                    add_scaled(&mut geo, &part.geo, w as f32);
                    add_scaled(&mut colour, &part.colour, w as f32);
                    add_scaled(&mut sky, &part.sky, w as f32);
                    add_scaled(&mut background_mlp, &part.background_mlp, w as f32);
                    if colour_moves_poses {
                        let g = pose_grad_flat(&part.pose, w);
                        pose_grad.iter_mut().zip(g).for_each(|(a, b)| *a += b);
                    }
                    for (a, b) in exposure_grad.iter_mut().zip(part.exposure) {
                        *a += (b * w) as f32;
                    }
                }
                // Stepped after every camera's rays (each camera's rays see only its own pose).
                pose_grads[k] = pose_grad;
                let e = &mut stage.exposure[k];
                let mut flat: Vec<f32> = e.scale.iter().chain(&e.offset).copied().collect();
                stage.exposure_opt[k].step(&mut flat, &exposure_grad, lr_field);
                e.scale.copy_from_slice(&flat[..3]);
                e.offset.copy_from_slice(&flat[3..]);
            }
            if let Some(stage) = self.camera.as_mut() {
                stage.step_poses(
                    &pose_grads,
                    &held,
                    lr_camera_pose,
                    &self.config,
                    self.iteration,
                );
                stage
                    .colour_opt
                    .step(&mut stage.colour_params, &grad_flat(&colour), lr_field);
                mlp_set(&mut stage.appearance.colour, &stage.colour_params);
                if let Some(b) = stage.background.as_mut() {
                    b.grid_opt.step_accumulated(
                        &mut b.field.grid.params,
                        &mut b.grid_accs,
                        lr_field,
                    );
                    b.mlp_opt
                        .step(&mut b.mlp_params, &grad_flat(&background_mlp), lr_field);
                    mlp_set(&mut b.field.geo, &b.mlp_params);
                }
                stage
                    .sky_opt
                    .step(&mut stage.sky_params, &grad_flat(&sky), lr_field);
                mlp_set(&mut stage.appearance.sky, &stage.sky_params);
            }
        }
        self.grid_opt
            .step_accumulated(&mut self.field.grid.params, &mut self.grid_accs, lr_field);
        self.mlp_opt
            .step(&mut self.mlp_params, &grad_flat(&geo), lr_field);
        mlp_set(&mut self.field.geo, &self.mlp_params);
        let mut lb = [self.ln_beta];
        self.beta_opt.step(
            &mut lb,
            &[(beta_grad * self.beta() as f64) as f32],
            lr_field,
        );
        self.ln_beta = lb[0].clamp(0.0, 8.0);
        self.iteration += 1;
        DepthReport {
            loss,
            mean_abs_error_m: mae / lidars,
            beta: self.beta(),
            colour_loss,
            intensity_loss,
            regulariser_loss,
            geometry_init_loss: None,
            alignment_loss: align.loss,
            alignment_matches: align.kept,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::hash_grid::HashGridConfig;
    use super::*;

    /// A straight drive at 8 m/s and a LiDAR 2 m above flat ground.
    fn flat_drive() -> (Trajectory, Rigid, Vec<LidarSweep>) {
        let trajectory = Trajectory::new(
            (0..=20)
                .map(|i| {
                    (
                        i * 50_000_000,
                        Rigid::from_translation(DVec3::new(i as f64 * 0.4, 0.0, 0.0)),
                    )
                })
                .collect(),
        );
        let mount = Rigid::from_translation(DVec3::new(0.0, 0.0, 2.0));
        let sweeps: Vec<LidarSweep> = (1..10)
            .map(|k| {
                let points: Vec<[f32; 3]> = (0..400)
                    .map(|j| {
                        let az = j as f32 * 0.0157;
                        let el = -0.2 - 0.3 * ((j * 7 % 11) as f32 / 11.0);
                        let r = 2.0 / -el.sin();
                        [
                            r * el.cos() * az.cos(),
                            r * el.cos() * az.sin(),
                            r * el.sin(),
                        ]
                    })
                    .collect();
                // Intensity falls with incidence: steep beams (near the car) return brighter,
                // which the decoder can learn from the view direction before the surface forms
                // (a release run learns 1 m reflectivity stripes too, once the surface has
                // formed after ~200 steps).
                let intensity = points
                    .iter()
                    .map(|p| {
                        if p[2] / p[0].hypot(p[1]) < -0.4 {
                            200.0
                        } else {
                            40.0
                        }
                    })
                    .collect();
                LidarSweep {
                    stamp_nanos: k * 100_000_000,
                    frame_id: "lidar".into(),
                    intensity,
                    points_in_sensor: points,
                    time_offset_secs: None,
                }
            })
            .collect();
        (trajectory, mount, sweeps)
    }

    /// A wall at x = 20 m seen by a sweep whose returns fire over ±50 ms while the car drives
    /// at 8 m/s: each return is measured from where the LiDAR was at its own time, so it lands
    /// on the wall only when placed at that time (within the 0.5 ms of the pose buckets, 4 mm;
    /// at the stamp it would sit up to 40 cm off).
    #[test]
    fn aggregated_returns_are_placed_at_their_firing_time() {
        let (trajectory, mount, _) = flat_drive();
        let stamp = 500_000_000; // the car at x = 4 m
        let offsets: Vec<f32> = (0..11).map(|k| -0.05 + 0.01 * k as f32).collect();
        let points: Vec<[f32; 3]> = offsets
            .iter()
            .map(|&t| {
                let car_x = 4.0 + 8.0 * t as f64;
                [(20.0 - car_x) as f32, 1.0, 0.0]
            })
            .collect();
        let mut sweep = LidarSweep {
            stamp_nanos: stamp,
            frame_id: "lidar".into(),
            intensity: vec![100.0; points.len()],
            points_in_sensor: points,
            time_offset_secs: Some(offsets),
        };
        let placed = deskewed_points(&trajectory, &sweep, mount, 1);
        assert_eq!(placed.len(), 11);
        for p in &placed {
            assert!((p.x - 20.0).abs() < 4e-3, "{p}");
        }
        // Every other return, and the same returns of a sweep without times: at the stamp.
        assert_eq!(deskewed_points(&trajectory, &sweep, mount, 2).len(), 6);
        sweep.time_offset_secs = None;
        let at_stamp = deskewed_points(&trajectory, &sweep, mount, 1);
        assert!((at_stamp[0].x - 20.4).abs() < 1e-4 && (at_stamp[10].x - 19.6).abs() < 1e-4);
        // A sweep reaching outside the trajectory (a second before it) gives none.
        sweep.stamp_nanos = 0;
        sweep.time_offset_secs = Some(vec![-1.0; 11]);
        assert!(deskewed_points(&trajectory, &sweep, mount, 1).is_empty());
    }

    #[test]
    fn pose_rates_wait_ramp_up_then_decay() {
        let config = DepthCalibConfig {
            pose_warmup: 10,
            pose_ramp: 4,
            iterations: 110,
            ..DepthCalibConfig::default()
        };
        let rate = |it| config.pose_rate(1.0, 0.01, it);
        assert_eq!(rate(0), 0.0);
        assert_eq!(rate(9), 0.0);
        // Linear over the ramp (times the decay, 0.01^(k/100) after k iterations).
        for k in 0..4 {
            let expected = (k + 1) as f32 / 4.0 * 0.01f32.powf(k as f32 / 100.0);
            assert!(
                (rate(10 + k) - expected).abs() < 1e-6,
                "{k}: {}",
                rate(10 + k)
            );
        }
        assert!((rate(60) - 0.1).abs() < 1e-5, "{}", rate(60));
        assert!((rate(110) - 0.01).abs() < 1e-6 && rate(500) == rate(110));
        // Without a ramp the full (decayed) rate starts at once.
        let at_once = DepthCalibConfig {
            pose_ramp: 0,
            ..config.clone()
        };
        assert_eq!(at_once.pose_rate(1.0, 0.01, 10), 1.0);
        // A run too short for the ramp ramps over a quarter of its moving iterations.
        let short = DepthCalibConfig {
            pose_ramp: 150,
            iterations: 50,
            ..config.clone()
        };
        let expected = 0.01f32.powf(9.0 / 40.0);
        assert!((short.pose_rate(1.0, 0.01, 19) - expected).abs() < 1e-6);
        assert!((short.pose_rate(1.0, 0.01, 14) - 0.5 * 0.01f32.powf(4.0 / 40.0)).abs() < 1e-6);
    }

    /// Cameras released early by the correspondence term ramp up from their release and start
    /// the usual schedule again at the warm-up's end; LiDARs still wait for it; a release after
    /// the warm-up changes nothing.
    #[test]
    fn a_bounded_rotation_is_turned_back_to_its_bound_along_the_geodesic() {
        use crate::geometry::so3;
        let start = so3::exp(DVec3::new(0.2, -0.4, 1.0));
        let axis = DVec3::new(1.0, 2.0, -0.5).normalize_or_zero();
        let bound = 1f64.to_radians();
        // Inside the bound nothing changes.
        let inside = Rigid::new(start * so3::exp(axis * 0.5f64.to_radians()), DVec3::X);
        let mut p = PoseParams::from_rigid(inside);
        let before = p;
        bound_rotation(&mut p, start, bound);
        assert_eq!(p, before);
        // Outside it, back to the bound about the same axis; the translation stays.
        let outside = Rigid::new(start * so3::exp(axis * 3f64.to_radians()), DVec3::X);
        let mut p = PoseParams::from_rigid(outside);
        bound_rotation(&mut p, start, bound);
        let got = p.to_rigid();
        let offset = so3::log(start.inverse() * got.rotation);
        assert!(
            (offset.length() - bound).abs() < 1e-9,
            "{}",
            offset.length()
        );
        assert!(offset.normalize_or_zero().dot(axis) > 1.0 - 1e-9);
        assert_eq!(got.translation, DVec3::X);
    }

    /// A camera looking at a far wall: a step along the turn-and-shift it cannot tell apart is
    /// undone, the step's observed part is applied, and a pose with nothing held moves freely.
    #[test]
    fn holding_unobserved_directions_undoes_only_their_part_of_a_step() {
        use crate::geometry::so3;
        use crate::unical::observability::fixtures::{camera_rotation, information_of, wall};
        let rotation = camera_rotation();
        let camera = Rigid::new(glam::DQuat::from_mat3(&rotation), DVec3::new(1.0, 0.0, 1.5));
        let info = information_of(&wall(40.0, 4.0, 10));
        let before = PoseParams::from_rigid(camera);
        // Shift 10 cm sideways (+y) while turning so the wall's centre stays put.
        let turn = so3::exp(DVec3::new(0.0, 0.0, -0.1 / 40.0));
        let moved = Rigid::new(turn * camera.rotation, camera.translation + DVec3::Y * 0.1);
        let mut p = PoseParams::from_rigid(moved);
        hold_unobserved(&mut p, &before, &info, 0.05);
        let got = p.to_rigid();
        assert!(
            (got.translation - camera.translation).length() < 0.02,
            "{got:?}"
        );
        assert!(so3::log(camera.rotation.inverse() * got.rotation).length() < 0.02 / 40.0);
        // A pan alone is observed: most of it is kept.
        let pan = so3::exp(DVec3::new(0.0, 0.0, 0.01));
        let mut p = PoseParams::from_rigid(Rigid::new(pan * camera.rotation, camera.translation));
        hold_unobserved(&mut p, &before, &info, 0.05);
        let kept = so3::log(p.to_rigid().rotation * camera.rotation.inverse());
        assert!(kept.z > 0.009, "{kept:?}");
        // Nothing held yet: the step passes whole.
        let mut p = PoseParams::from_rigid(moved);
        hold_unobserved(&mut p, &before, &PoseInformation::default(), 0.05);
        assert!((p.to_rigid().translation - moved.translation).length() < 1e-12);
    }

    #[test]
    fn the_travel_hold_keeps_only_the_step_square_to_the_travel() {
        // A camera looking left, the vehicle driving along (0.6, 0.8, 0): a step of 5 cm
        // along the travel and 2 cm up keeps only the 2 cm up, whatever way the camera looks.
        let looking_left =
            glam::DMat3::from_cols(glam::DVec3::X, glam::DVec3::NEG_Z, glam::DVec3::Y);
        let before = PoseParams {
            r6: crate::geometry::rot6d::from_matrix(looking_left),
            translation_m: glam::DVec3::new(0.5, 0.8, 1.5),
        };
        let travel = glam::DVec3::new(0.6, 0.8, 0.0);
        let mut p = before;
        p.translation_m += travel * 0.05 + glam::DVec3::new(0.0, 0.0, 0.02);
        hold_along(&mut p, &before, travel);
        assert!((p.translation_m - glam::DVec3::new(0.5, 0.8, 1.52)).length() < 1e-12);
        assert_eq!(p.r6, before.r6);
    }

    #[test]
    fn the_axial_hold_keeps_only_the_step_square_to_the_optical_axis() {
        // A camera looking along the vehicle's +x (its z axis), stepping 3 cm forward, 2 cm
        // left and 1 cm up: the forward part is undone, the rest and the rotation stay.
        let looking_forward =
            glam::DMat3::from_cols(glam::DVec3::NEG_Y, glam::DVec3::NEG_Z, glam::DVec3::X);
        let before = PoseParams {
            r6: crate::geometry::rot6d::from_matrix(looking_forward),
            translation_m: glam::DVec3::new(1.0, 0.0, 1.5),
        };
        let mut p = before;
        p.translation_m += glam::DVec3::new(0.03, 0.02, 0.01);
        hold_axial(&mut p, &before);
        assert!((p.translation_m - glam::DVec3::new(1.0, 0.02, 1.51)).length() < 1e-12);
        assert_eq!(p.r6, before.r6);
    }

    #[test]
    fn a_translation_with_its_own_decay_keeps_more_of_its_rate_late() {
        let config = DepthCalibConfig {
            iterations: 1200,
            pose_warmup: 200,
            camera_pose_final_fraction: 0.01,
            camera_translation_rate: 2.0,
            camera_translation_final_fraction: Some(0.05),
            ..DepthCalibConfig::default()
        };
        // At the warm-up's end the plain multiple; by the end the two decays' ratio on top.
        assert!((config.camera_translation_scale(0) - 2.0).abs() < 1e-12);
        assert!((config.camera_translation_scale(200) - 2.0).abs() < 1e-12);
        assert!((config.camera_translation_scale(1200) - 10.0).abs() < 1e-5);
        assert!((config.camera_translation_scale(5000) - 10.0).abs() < 1e-5);
        // The translation's own rate is the rate decayed to its own final fraction.
        for it in [300, 700, 1100] {
            let s = (it - 200) as f64 / 1000.0;
            let rotation = decayed_lr(1.0, 0.01, it - 200, 1000) as f64;
            let translation = rotation * config.camera_translation_scale(it);
            assert!((translation - 2.0 * 0.05f64.powf(s)).abs() < 1e-5, "{it}");
        }
        // Without its own decay it is the plain multiple throughout.
        let plain = DepthCalibConfig {
            camera_translation_final_fraction: None,
            ..config
        };
        assert_eq!(plain.camera_translation_scale(900), 2.0);
        // After a hand-eye start: rotations at half the preset's rate, translations at its
        // full rate when poses are released, decaying to 5 % instead of 1 %.
        let preset = DepthCalibConfig::default();
        let he = preset.clone().after_hand_eye(&["front".to_string()], 1.0);
        assert_eq!(
            he.camera_rotation_bounds_deg,
            vec![("front".to_string(), 1.0)]
        );
        assert_eq!(preset.clone().after_hand_eye(&[], 1.0), preset);
        assert_eq!(he.lr_camera_pose, preset.lr_camera_pose * 0.5);
        // The warm-up and ramp scale with the run, never below the preset's.
        let long = DepthCalibConfig {
            iterations: 1400,
            ..preset.clone()
        }
        .after_hand_eye(&["front".to_string()], 1.0);
        assert_eq!((long.pose_warmup, long.pose_ramp), (400, 300));
        let short = DepthCalibConfig {
            iterations: 300,
            ..preset.clone()
        }
        .after_hand_eye(&["front".to_string()], 1.0);
        assert_eq!(
            (short.pose_warmup, short.pose_ramp),
            (preset.pose_warmup, preset.pose_ramp)
        );
        assert!(
            !he.alignment_release_rotates,
            "its rotations stay during a release"
        );
        assert_eq!(he.camera_release(), HAND_EYE_RELEASE);
        assert!(he.camera_release() < he.pose_warmup);
        let release = he.pose_warmup;
        let translation_at = |c: &DepthCalibConfig, it: usize| {
            c.pose_rate(c.lr_camera_pose, c.camera_pose_final_fraction, it) as f64
                * c.camera_translation_scale(it)
        };
        // Against the preset's rates on the same warm-up and ramp.
        let preset = DepthCalibConfig {
            pose_warmup: he.pose_warmup,
            pose_ramp: he.pose_ramp,
            ..preset
        };
        assert!(translation_at(&he, release) > 0.0);
        assert!(
            (translation_at(&he, release) / translation_at(&preset, release) - 1.0).abs() < 1e-6
        );
        let last = he.iterations - 1;
        let ratio = translation_at(&he, last) / translation_at(&preset, last);
        assert!((ratio - 5.0).abs() < 0.1, "{ratio}");
    }

    #[test]
    fn an_alignment_release_starts_only_the_cameras_early() {
        let config = DepthCalibConfig {
            pose_warmup: 10,
            pose_ramp: 4,
            iterations: 110,
            alignment_release: Some(4),
            alignment_release_rate: 0.5,
            ..DepthCalibConfig::default()
        };
        assert_eq!(config.camera_release(), 4);
        assert_eq!(config.camera_pose_rate(1.0, 0.01, 3), 0.0);
        let first = 0.25 * 0.5;
        assert!((config.camera_pose_rate(1.0, 0.01, 4) - first).abs() < 1e-6);
        assert_eq!(config.camera_pose_rate(1.0, 0.01, 7), 0.5, "ramped up by 7");
        assert_eq!(config.pose_rate(1.0, 0.01, 9), 0.0, "LiDARs wait");
        // From the warm-up's end the cameras' schedule is the LiDARs' (ramped again).
        for it in [10, 11, 30, 109] {
            assert_eq!(
                config.camera_pose_rate(1.0, 0.01, it),
                config.pose_rate(1.0, 0.01, it)
            );
        }
        let late = DepthCalibConfig {
            alignment_release: Some(50),
            ..config.clone()
        };
        assert_eq!(late.camera_release(), 10);
        for it in [0, 9, 10, 30, 109] {
            assert_eq!(
                late.camera_pose_rate(1.0, 0.01, it),
                late.pose_rate(1.0, 0.01, it)
            );
        }
    }

    #[test]
    fn the_shared_translation_follows_the_sum_of_the_cameras_gradients() {
        let mut g = [[0.0f32; 9]; 3];
        // Two cameras pulled up (negative gradient in z) and sideways in opposite directions;
        // the third, frozen, pulled hard down.
        g[0][6..].copy_from_slice(&[0.5, 0.0, -1.0]);
        g[1][6..].copy_from_slice(&[-0.5, 0.0, -0.2]);
        g[2][6..].copy_from_slice(&[0.0, 0.0, 100.0]);
        let mut opt = DenseAdam::new(3, AdamConfig::STANDARD);
        let shift = shared_translation_step(&mut opt, &g, &[0, 1], 0.01);
        // Adam's first step is the rate along the sign of each summed component.
        assert!((shift.z - 0.01).abs() < 1e-6, "{shift}");
        assert!(shift.x.abs() < 1e-6 && shift.y.abs() < 1e-6, "{shift}");
        let mut opt = DenseAdam::new(3, AdamConfig::STANDARD);
        let shift = shared_translation_step(&mut opt, &g, &[0, 1, 2], 0.01);
        assert!((shift.z + 0.01).abs() < 1e-6, "{shift}");
    }

    fn small_config() -> DepthCalibConfig {
        DepthCalibConfig {
            field: FieldConfig {
                grid: HashGridConfig {
                    levels: 6,
                    log2_table_size: 14,
                    base_resolution: 8.0,
                    max_resolution: 256.0,
                },
                hidden: 32,
                feature_dim: 3,
                initial_sdf_m: 0.5,
                cubic_box: false,
            },
            rays_per_sensor: 128,
            rays_per_camera: 128,
            iterations: 40,
            geometry_init_steps: 0,
            pose_warmup: 0,
            pose_ramp: 0,
            ..DepthCalibConfig::default()
        }
    }

    /// A forward camera 1.5 m up, pitched down, imaging the ground's colour pattern (blocks of
    /// 1 m) seen through its true pose, 64×48 pixels.
    fn ground_camera(trajectory: &Trajectory) -> CameraData {
        let intrinsics = CameraIntrinsics::pinhole(64, 48, 40.0, 40.0, 31.5, 23.5);
        // Optical frame: z forward (vehicle +x), x right (−y), y down (−z), pitched 25° down.
        let level = glam::DMat3::from_cols(-DVec3::Y, -DVec3::Z, DVec3::X);
        let pitch = glam::DMat3::from_rotation_y(25f64.to_radians());
        let vehicle_from_camera = Rigid::new(
            glam::DQuat::from_mat3(&(pitch * level)),
            DVec3::new(1.0, 0.0, 1.5),
        );
        let frames = (2..9)
            .map(|k| {
                let stamp_nanos = k * 100_000_000;
                let wc = trajectory.world_from_vehicle(stamp_nanos).unwrap() * vehicle_from_camera;
                let mut rgb = Vec::new();
                for y in 0..48 {
                    for x in 0..64 {
                        let u = intrinsics
                            .unproject(DVec2::new(x as f64, y as f64))
                            .unwrap();
                        let (o, d) = (wc.translation, wc.rotation * u);
                        let c = if d.z < -1e-3 {
                            let p = o + d * (-o.z / d.z);
                            let cell = (p.x.floor() as i64 + p.y.floor() as i64).rem_euclid(3);
                            [[200u8, 60, 40], [40, 160, 70], [60, 70, 200]][cell as usize]
                        } else {
                            [150, 190, 230]
                        };
                        rgb.extend_from_slice(&c);
                    }
                }
                CameraFrame {
                    stamp_nanos,
                    rgb,
                    keypoints: Vec::new(),
                    masked: Vec::new(),
                }
            })
            .collect();
        CameraData {
            name: "camera".into(),
            initial: vehicle_from_camera,
            intrinsics,
            frames,
            readout: RowTimes::GLOBAL,
        }
    }

    /// Coarse-to-fine sampling (§10): uniform before the start, then σ shrinks geometrically
    /// from 40 to 5 px (at 1920 wide), and heat-map draws land near the keypoints.
    #[test]
    fn camera_pixels_follow_the_keypoint_heat_maps() {
        let (trajectory, mount, sweeps) = flat_drive();
        let mut camera = ground_camera(&trajectory);
        let keypoint = crate::features::orb::Keypoint {
            x: 20.0,
            y: 30.0,
            angle_rad: 0.0,
            response: 1.0,
            descriptor: [0; 4],
        };
        for f in &mut camera.frames {
            f.keypoints = vec![keypoint];
        }
        let config = DepthCalibConfig {
            iterations: 100,
            heatmap_start_fraction: 0.2,
            heatmap_uniform_share: 0.0,
            ..small_config()
        };
        let mut c = DepthCalibration::new(
            config,
            trajectory,
            vec![LidarData {
                name: "lidar".into(),
                initial: mount,
                sweeps,
            }],
        )
        .with_cameras(vec![camera]);
        assert_eq!(c.heatmap_sigma(1920.0), None, "uniform at first");
        c.iteration = 20;
        assert!((c.heatmap_sigma(1920.0).unwrap_or(0.0) - 40.0).abs() < 1e-9);
        assert!((c.heatmap_sigma(64.0).unwrap_or(0.0) - 40.0 * 64.0 / 1920.0).abs() < 1e-9);
        c.iteration = 100;
        assert!((c.heatmap_sigma(1920.0).unwrap_or(0.0) - 5.0).abs() < 1e-9);
        // σ = 5 px at 1920 wide is 0.17 px here: every draw is the keypoint's pixel.
        let intrinsics = c.camera_intrinsics("camera").cloned().unwrap();
        let rays = c.draw_camera_rays(0);
        assert!(!rays.is_empty());
        for r in &rays {
            let px = intrinsics.project(r.dir_in_sensor).unwrap();
            assert!(
                (px.x - 20.0).abs() < 0.51 && (px.y - 30.0).abs() < 0.51,
                "{px:?}"
            );
        }
    }

    /// With `camera_rays_below_lidar_top` no camera ray looks higher than the LiDAR's highest
    /// return (the test LiDAR's returns lie 11.5° to 28.6° below its horizon; the camera, pitched
    /// 25° down, sees from 56° below to 6° above), and without it some do.
    #[test]
    fn camera_rays_stay_below_the_lidars_highest_beam() {
        let (trajectory, mount, sweeps) = flat_drive();
        let lidars = vec![LidarData {
            name: "lidar".into(),
            initial: mount,
            sweeps,
        }];
        let top = super::super::coverage::lidar_top_elevation_rad(&lidars).unwrap();
        assert!(
            (top.to_degrees() + 11.46).abs() < 0.1,
            "{}",
            top.to_degrees()
        );
        let highest = |below: bool| {
            let config = DepthCalibConfig {
                camera_rays_below_lidar_top: below,
                ..small_config()
            };
            let mut c = DepthCalibration::new(config, trajectory.clone(), lidars.clone())
                .with_cameras(vec![ground_camera(&trajectory)]);
            let rays = c.draw_camera_rays(0);
            assert!(rays.len() > 50, "{}", rays.len());
            rays.iter()
                .map(|r| {
                    let pose = c.camera.as_ref().unwrap().poses[0];
                    let (_, d) = pose.ray(r.world_from_vehicle, r.dir_in_sensor);
                    super::super::coverage::ray_elevation_rad(r.world_from_vehicle, d)
                })
                .fold(f64::MIN, f64::max)
        };
        assert!(highest(true) <= top, "{} > {}", highest(true), top);
        assert!(highest(false) > top + 0.1, "{}", highest(false));
    }

    /// Silhouette-guided sampling: a pole in front of the car is a depth discontinuity of the
    /// sweeps; projected into the frames it is where the silhouette draws land.
    #[test]
    fn silhouette_draws_land_on_the_lidars_depth_edges() {
        let (trajectory, mount, mut sweeps) = flat_drive();
        // A ring 20° below the horizon: a pole 5 m ahead between far returns at 20 m.
        let el = -0.35f32;
        for s in &mut sweeps {
            for j in -30i32..=30 {
                let az = j as f32 * 0.01;
                let r = if j.abs() <= 2 { 5.0 } else { 20.0 };
                s.points_in_sensor.push([
                    r * el.cos() * az.cos(),
                    r * el.cos() * az.sin(),
                    r * el.sin(),
                ]);
                s.intensity.push(40.0);
            }
        }
        let camera = ground_camera(&trajectory);
        let intrinsics = camera.intrinsics.clone();
        let vehicle_from_camera = camera.initial;
        let stamps: Vec<i64> = camera.frames.iter().map(|f| f.stamp_nanos).collect();
        let config = DepthCalibConfig {
            iterations: 100,
            heatmap_start_fraction: 0.2,
            heatmap_uniform_share: 0.0,
            silhouette_share: 1.0,
            ..small_config()
        };
        let mut c = one_lidar(config, &trajectory, mount, sweeps).with_cameras(vec![camera]);
        c.iteration = 100;
        c.refresh_silhouettes();
        // Each frame's silhouette pixels are the pole's two edge returns (its outermost, beside
        // the far ones) in the sweep at the frame's own stamp, seen by the camera.
        for f in 0..stamps.len() {
            let pixels = &c.silhouette_pixels.0[0][f];
            assert_eq!(pixels.len(), 2, "frame {f}: {pixels:?}");
            let camera_from_vehicle = vehicle_from_camera.inverse();
            for j in [-2, 2] {
                let az = j as f64 * 0.01;
                let p = DVec3::new(
                    5.0 * (el as f64).cos() * az.cos(),
                    5.0 * (el as f64).cos() * az.sin(),
                    5.0 * (el as f64).sin(),
                );
                let in_camera = camera_from_vehicle.transform_point(mount.transform_point(p));
                let px = intrinsics.project(in_camera).unwrap();
                assert!(
                    pixels
                        .iter()
                        .any(|q| (q.0 as f64 - px.x).abs() < 0.05
                            && (q.1 as f64 - px.y).abs() < 0.05),
                    "frame {f}: {px:?} not in {pixels:?}"
                );
            }
        }
        // σ = 5 px at 1920 wide is 0.17 px here: every draw is at a silhouette pixel.
        let rays = c.draw_camera_rays(0);
        assert!(!rays.is_empty());
        let all: Vec<(f32, f32)> = c.silhouette_pixels.0[0].concat();
        for r in &rays {
            let px = intrinsics.project(r.dir_in_sensor).unwrap();
            assert!(
                all.iter()
                    .any(|q| (px.x - q.0 as f64).abs() < 1.2 && (px.y - q.1 as f64).abs() < 1.2),
                "{px:?}"
            );
        }
    }

    /// A rolling shutter: every colour ray and every matched pixel's ray leaves from where the
    /// vehicle was when its row was exposed (the test drive moves 8 m/s along x, so a ray's
    /// origin tells its time), and a world point seen on a row projects back to that pixel.
    #[test]
    fn rolling_shutter_rays_leave_from_their_rows_time() {
        let (trajectory, mount, sweeps) = flat_drive();
        let readout = RowTimes::from_millis(-30.0, 10.0);
        let camera = CameraData {
            readout,
            ..ground_camera(&trajectory)
        };
        let (h, frame_stamps) = (
            camera.intrinsics.height,
            camera
                .frames
                .iter()
                .map(|f| f.stamp_nanos)
                .collect::<Vec<_>>(),
        );
        let mut c = one_lidar(small_config(), &trajectory, mount, sweeps)
            .with_cameras(vec![camera.clone()]);
        // The ray's time from the vehicle's position, and the frame stamp it implies.
        let check = |wv: Rigid, y: f64| {
            let t_nanos = (wv.translation.x / 8.0 * 1e9).round() as i64;
            let stamp = t_nanos - readout.offset_nanos(y, h);
            assert!(
                frame_stamps.iter().any(|s| (s - stamp).abs() < 1_000),
                "row {y}: ray at {t_nanos} ns, stamp {stamp} not a frame's"
            );
        };
        let rays = c.draw_camera_rays(0);
        assert!(rays.len() > 50, "{}", rays.len());
        let mut rows = std::collections::BTreeSet::new();
        for r in &rays {
            let y = camera.intrinsics.project(r.dir_in_sensor).unwrap().y;
            check(r.world_from_vehicle, y);
            rows.insert(y.round() as i64);
        }
        // Rays from rows far apart leave from places far apart: 40 ms is 32 cm here.
        assert!(rows.len() > 20, "{rows:?}");
        for (frame, y) in [(0, 0.0), (3, 23.5), (6, 47.0)] {
            let ray = c.align_ray((0, frame), DVec2::new(30.0, y)).unwrap();
            check(ray.world_from_vehicle, y);
            assert!(
                ray.world_from_vehicle.translation.distance(
                    trajectory
                        .world_from_vehicle(frame_stamps[frame] + readout.offset_nanos(y, h))
                        .unwrap()
                        .translation
                ) < 1e-9
            );
        }
        // A point 6 m out along pixel (x, y)'s ray at its row's time projects back onto it.
        for (x, y) in [(5.0, 2.0), (31.5, 23.5), (60.0, 45.0)] {
            let stamp = frame_stamps[2];
            let wv = trajectory
                .world_from_vehicle(camera.row_stamp_nanos(stamp, y))
                .unwrap();
            let u = camera.intrinsics.unproject(DVec2::new(x, y)).unwrap();
            let world_from_camera = wv * camera.initial;
            let p = world_from_camera.transform_point(u * 6.0 / u.z);
            let px = camera
                .project_world(&trajectory, camera.initial, stamp, p)
                .unwrap();
            assert!(px.distance(DVec2::new(x, y)) < 0.01, "({x}, {y}) -> {px:?}");
            // Projected as if the whole image were exposed at the stamp, it lands elsewhere.
            let global = CameraData {
                readout: RowTimes::GLOBAL,
                ..camera.clone()
            };
            let px_global = global
                .project_world(&trajectory, camera.initial, stamp, p)
                .unwrap();
            assert!(px_global.distance(DVec2::new(x, y)) > 0.05, "{px_global:?}");
        }
        // Matches found with one readout are not read back from the cache for another: the
        // overlap check places each frame at its middle row's pose.
        let global = CameraData {
            readout: RowTimes::GLOBAL,
            ..camera.clone()
        };
        let key = |c: &CameraData| {
            crate::unical::correspondences::cache_key(
                std::slice::from_ref(c),
                &[c.initial],
                &trajectory,
            )
        };
        assert_ne!(key(&camera), key(&global));
        assert_eq!(
            camera.middle_stamp_nanos(frame_stamps[0]),
            frame_stamps[0] - 10_000_000
        );
    }

    /// Cameras join: the colour loss falls, the camera's pose is
    /// reported with the LiDAR's, and the run stays deterministic.
    #[test]
    fn the_colour_term_learns_the_cameras_view_deterministically() {
        let (trajectory, mount, sweeps) = flat_drive();
        let camera = ground_camera(&trajectory);
        let run = || {
            let mut c = DepthCalibration::new(
                small_config(),
                trajectory.clone(),
                vec![LidarData {
                    name: "lidar".into(),
                    initial: mount,
                    sweeps: sweeps.clone(),
                }],
            )
            .with_cameras(vec![camera.clone()]);
            let reports: Vec<DepthReport> = (0..40).map(|_| c.step()).collect();
            (reports, c.extrinsics())
        };
        let (a, ea) = run();
        let first = a[0].colour_loss;
        let last: f64 = a[35..].iter().map(|r| r.colour_loss).sum::<f64>() / 5.0;
        // 40 steps learn the view's mean colour and exposure (0.26 -> ~0.17); the blocks'
        // texture follows once the surface has formed (~150 steps: 0.12 at 190 in a release run).
        assert!(
            first > 0.0 && last < 0.75 * first,
            "colour loss {first} -> {last}"
        );
        assert_eq!(ea.len(), 2);
        assert_eq!(ea[1].0, "camera");
        assert!(ea[1].1.translation.is_finite());
        let (b, eb) = run();
        assert_eq!(
            a.last().map(|r| r.colour_loss),
            b.last().map(|r| r.colour_loss)
        );
        assert_eq!(ea, eb);
    }

    /// A calibration of one LiDAR, named `lidar`, mounted at `mount`.
    fn one_lidar(
        config: DepthCalibConfig,
        trajectory: &Trajectory,
        mount: Rigid,
        sweeps: Vec<LidarSweep>,
    ) -> DepthCalibration {
        DepthCalibration::new(
            config,
            trajectory.clone(),
            vec![LidarData {
                name: "lidar".into(),
                initial: mount,
                sweeps,
            }],
        )
    }

    /// The shared translation changes where the free cameras go and leaves a held one alone.
    #[test]
    fn a_shared_translation_moves_only_the_free_cameras() {
        let (trajectory, mount, sweeps) = flat_drive();
        let camera = ground_camera(&trajectory);
        let run = |shared: bool| {
            let config = DepthCalibConfig {
                shared_camera_translation: shared,
                held_sensors: vec!["held".into()],
                ..small_config()
            };
            let cameras = ["camera", "second", "held"].map(|name| CameraData {
                name: name.into(),
                ..camera.clone()
            });
            let mut c = one_lidar(config, &trajectory, mount, sweeps.clone())
                .with_cameras(cameras.to_vec());
            for _ in 0..12 {
                c.step();
            }
            c.extrinsics()
        };
        let (with, without) = (run(true), run(false));
        for extrinsics in [&with, &without] {
            assert_eq!(extrinsics[3].0, "held");
            let held = extrinsics[3].1;
            assert_eq!(
                held.translation, camera.initial.translation,
                "a held camera stays"
            );
            assert!(held.rotation.angle_between(camera.initial.rotation) < 1e-9);
            assert_ne!(extrinsics[1].1, camera.initial, "a free camera moves");
        }
        for k in [1, 2] {
            let gap = (with[k].1.translation - without[k].1.translation).length();
            assert!(gap > 1e-9, "camera {k}: the shared step moved it ({gap} m)");
        }
    }

    /// A restart keeps every sensor where it got to and the data, and starts the scene and the
    /// schedule afresh: the next step renders exactly what a new calibration started at those
    /// extrinsics renders.
    #[test]
    fn a_restart_keeps_the_extrinsics_and_starts_a_fresh_scene() {
        let (trajectory, mount, sweeps) = flat_drive();
        let camera = ground_camera(&trajectory);
        let lidar = LidarData {
            name: "lidar".into(),
            initial: mount,
            sweeps,
        };
        let mut c = DepthCalibration::new(small_config(), trajectory.clone(), vec![lidar.clone()])
            .with_cameras(vec![camera.clone()]);
        for _ in 0..10 {
            c.step();
        }
        let reached = c.extrinsics();
        assert_ne!(
            reached[1].1, camera.initial,
            "the camera moved in the first round"
        );
        c.restart();
        for ((_, now), (_, before)) in c.extrinsics().iter().zip(&reached) {
            let (rot, trans) = now.difference(*before);
            assert!(rot < 1e-12 && trans < 1e-12, "{rot} {trans}");
        }
        assert_eq!(c.iteration, 0);
        let mut fresh = DepthCalibration::new(
            small_config(),
            trajectory,
            vec![LidarData {
                initial: reached[0].1,
                ..lidar
            }],
        )
        .with_cameras(vec![CameraData {
            initial: reached[1].1,
            ..camera
        }]);
        assert_eq!(c.field.grid.params, fresh.field.grid.params);
        let (a, b) = (c.step(), fresh.step());
        assert_eq!(a, b);
        assert_eq!(c.extrinsics(), fresh.extrinsics());
    }

    /// A LiDAR 2 m above flat ground on a straight drive: the depth loss falls, the pose stays
    /// finite and the run is deterministic for a seed.
    #[test]
    fn steps_reduce_the_depth_loss_deterministically() {
        let (trajectory, mount, sweeps) = flat_drive();
        let config = small_config();
        let run = || {
            let mut c = DepthCalibration::new(
                config.clone(),
                trajectory.clone(),
                vec![LidarData {
                    name: "lidar".into(),
                    initial: mount,
                    sweeps: sweeps.clone(),
                }],
            );
            let reports: Vec<DepthReport> = (0..40).map(|_| c.step()).collect();
            (reports, c.extrinsics())
        };
        let (a, ea) = run();
        let first: f64 = a[..5].iter().map(|r| r.mean_abs_error_m).sum::<f64>() / 5.0;
        let last: f64 = a[35..].iter().map(|r| r.mean_abs_error_m).sum::<f64>() / 5.0;
        assert!(last < 0.5 * first, "range error {first} -> {last}");
        assert!(ea[0].1.translation.is_finite());
        // Same thread count, same seed: same result.
        let (b, eb) = run();
        assert_eq!(a.last().map(|r| r.loss), b.last().map(|r| r.loss));
        assert_eq!(ea, eb);
    }

    /// Two LiDARs with intensity: the intensity loss falls, the regulariser is reported, and a
    /// frozen root keeps its extrinsic exactly while the other sensor moves.
    #[test]
    fn intensity_and_regulariser_join_and_a_frozen_root_stays_put() {
        let (trajectory, mount, sweeps) = flat_drive();
        let config = DepthCalibConfig {
            frozen_sensor: Some("lidar".into()),
            intensity_weight: 1.0,
            ..small_config()
        };
        // The second LiDAR sees the same returns from the same mount, but starts 5 cm off.
        let second_initial =
            Rigid::from_translation(mount.translation + DVec3::new(0.05, 0.0, 0.0));
        let mut c = DepthCalibration::new(
            config,
            trajectory,
            vec![
                LidarData {
                    name: "lidar".into(),
                    initial: mount,
                    sweeps: sweeps.clone(),
                },
                LidarData {
                    name: "second".into(),
                    initial: second_initial,
                    sweeps,
                },
            ],
        );
        assert!(c.has_intensity());
        let reports: Vec<DepthReport> = (0..40).map(|_| c.step()).collect();
        let first: f64 = reports[..5].iter().map(|r| r.intensity_loss).sum::<f64>() / 5.0;
        let last: f64 = reports[35..].iter().map(|r| r.intensity_loss).sum::<f64>() / 5.0;
        assert!(last < 0.5 * first, "intensity loss {first} -> {last}");
        assert!(reports.iter().all(|r| r.regulariser_loss.is_finite()));
        assert!(reports.iter().any(|r| r.regulariser_loss > 0.0));
        let e = c.extrinsics();
        assert_eq!(e[0].1.translation, mount.translation);
        assert_eq!(
            e[0].1.rotation,
            PoseParams::from_rigid(mount).to_rigid().rotation
        );
        assert_ne!(e[1].1.translation, second_initial.translation);
        assert_eq!(c.intensity_maps().len(), 2);
    }

    /// The geometry initialisation puts the surface where the returns are: the first rendered
    /// depth after it is far closer than from the empty initial scene, and poses stay fixed.
    #[test]
    fn geometry_initialisation_places_the_surface_before_rendering() {
        let (trajectory, mount, sweeps) = flat_drive();
        let lidar = LidarData {
            name: "lidar".into(),
            initial: mount,
            sweeps,
        };
        let first_render_error = |init_steps: usize| {
            let config = DepthCalibConfig {
                geometry_init_steps: init_steps,
                geometry_init_rays: 1024,
                ..small_config()
            };
            let mut c = DepthCalibration::new(config, trajectory.clone(), vec![lidar.clone()]);
            for _ in 0..init_steps {
                let r = c.step();
                assert!(r.geometry_init_loss.is_some_and(f64::is_finite));
            }
            assert!(!c.initialising_geometry());
            assert_eq!(
                c.extrinsics()[0].1,
                PoseParams::from_rigid(mount).to_rigid()
            );
            let r = c.step();
            assert!(r.geometry_init_loss.is_none());
            r.mean_abs_error_m
        };
        let (cold, warm) = (first_render_error(0), first_render_error(30));
        assert!(warm < 0.15 * cold && warm < 1.0, "{cold} m -> {warm} m");
    }
}
