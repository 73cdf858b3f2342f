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
mod sampling;

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
mod tests;
