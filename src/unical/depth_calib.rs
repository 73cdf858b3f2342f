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
use super::background::Background;
use super::camera_rgb::{
    Appearance, CameraModel, ColourRay, ExposureMap, colour_step, render_colour,
};
use super::composite::Opacity;
use super::correspondences::Correspondences;
use super::field::SceneField;
use super::hash_grid::{GradAccumulator, Scaled};
use super::hash_load::{LevelLoad, level_loads};
use super::intensity::{IntensityDecoder, IntensityMap, normaliser};
use super::lidar_terms::{DepthRay, LidarModel, LidarWeights, lidar_step};
use super::observability::PoseInformation;
use super::occupancy::OccupancyGrid;
use super::pose::PoseParams;
use super::pose_newton::{NewtonConfig, NewtonState, PoseUpdate, TangentSystem, robust_system};
use super::pose_steps::{
    INFORMATION_FORGETTING, bound_rotation, hold_axial, hold_unobserved, pose_grad_flat, pose_step,
    shared_translation_step,
};
use super::sdf_init::{PointIndex, SdfRay, sdf_fit_step};
use super::surface_align::{
    AlignCamera, AlignRay, AlignSettings, AlignStep, AlignmentLoss, projected_ray_step,
    surface_alignment_step,
};
use crate::features::orb::Keypoint;
use crate::geometry::camera::CameraIntrinsics;
use crate::geometry::projection::world_points;
use crate::geometry::{Rigid, RowTimes, Trajectory};
use crate::log::LidarSweep;

mod alignment;
mod lidar_fit;
mod sampling;
mod step;

pub use super::depth_config::*;

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

mod flat;
use flat::{add_scaled, gaussian_pair, grad_flat, mlp_flat, mlp_set, next, unit};

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
        let shift = shared_translation_step(&mut self.shared_translation_opt, grads, &free, lr);
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

    /// Whether the next step is still part of the geometry initialisation.
    pub fn initialising_geometry(&self) -> bool {
        self.iteration < self.config.geometry_init_steps
    }
}

#[cfg(test)]
mod tests;
