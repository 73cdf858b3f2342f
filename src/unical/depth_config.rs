//! UniCal's configuration: [`DepthCalibConfig`], one serde type with every setting of a run
//! and its default stated once (the CPU preset; [`DepthCalibConfig::paper`] for the paper's
//! values), and the coarse-to-fine schedule of the hash grid's levels ([`CoarseToFine`]).
//! The pipeline's configuration nests it as `unical` (docs/configuration.md).

use super::adam::decayed_lr;
use super::background::BackgroundConfig;
use super::composite::OpacityModel;
use super::field::FieldConfig;
use super::hash_grid::HashGridConfig;
use super::lidar_terms::LidarWeights;
use super::pose_newton::PoseUpdate;
use super::surface_align::{AlignSettings, AlignmentLoss};
use super::transient::TransientSettings;

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
    /// current poses (refreshed every [`super::depth_calib::SILHOUETTE_REFRESH`] iterations). The rest are drawn
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
    /// [`super::camera_rgb::Appearance::view_dependent`]).
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

/// The cameras' rate after a hand-eye start, as a fraction of the preset's
/// ([`DepthCalibConfig::after_hand_eye`]). Adam's step has the rate's size whatever the
/// gradient's, so a camera started close wanders by about its rate each step until the rate
/// decays, and stops wherever that walk leaves it: at half the preset's rate (0.005 per step on
/// the 6-D rotation's entries, about 0.3°) every camera of a figure-8 drive jumped 0.1–0.25° in
/// its first 25 steps from starts within 0.02°, and side cameras ended turned up by up to 0.22°;
/// at a tenth they move to the truth without it (docs/experiments/pipeline.md, "Where the
/// cameras' upward tilt comes from").
pub const HAND_EYE_RATE: f32 = 0.1;

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
    pub fn parse_setting(text: &str) -> Result<Option<Self>, crate::error::ParseError> {
        if text.trim() == "off" {
            return Ok(None);
        }
        let bad = || {
            crate::error::ParseError::new(format!(
                "expected LEVELS,FRACTION (e.g. 4,0.6) or off, got '{text}'"
            ))
        };
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
    /// tenths of a degree, so they move at [`HAND_EYE_RATE`] of the CPU preset's rate and at most
    /// `rotation_bound_deg` from the fit ([`Self::camera_rotation_bounds_deg`]); their
    /// translations may start further off in the directions the drive did not observe (height,
    /// mostly sideways; the LiDAR map measures them in the pipeline), so they step twice as far
    /// as the rotations and decay only to 5 % of that, moving late in the run when the
    /// rotations have settled (docs/experiments/hand-eye-start.md, "A hand-eye start"). Their translations
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
            lr_camera_pose: self.lr_camera_pose * HAND_EYE_RATE,
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

    pub(crate) fn lidar_weights(&self) -> LidarWeights {
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
