//! UniCal (Yang et al., ECCV 2024) on the CPU: one neural scene learned jointly with every sensor
//! pose (docs: `../shared/docs/method.md`). Built bottom-up; each piece has a hand-written
//! backward pass checked against finite differences.
//!
//! - [`hash_grid`]: the multiresolution hash encoding (§15.1) with sparse gradients and the
//!   spatial gradient.
//! - [`mlp`]: small fully connected networks (ReLU hidden layers) with fused backward.
//! - [`adam`]: dense and sparse Adam, learning-rate decay (§12).
//! - [`table_memory`]: the large tables (hash grid, gradients, Adam's moments) on 2 MB pages.
//! - [`field`]: the scene field (Eq. 1): hash encoding + geometry MLP → SDF and feature.
//! - [`pose`]: extrinsics as 6D rotation + translation (§11) and the ray → pose backward pass.
//! - [`occupancy`]: the 0.5 m occupancy grid from aggregated LiDAR and 10 cm ray sampling (§7).
//! - [`scene_bounds`]: optionally, the scene box around the drive instead of the LiDARs' reach.
//! - [`scene_sweeps`]: the sweeps that shape the scene: spread over the drive, and the nearest
//!   to every training image.
//! - [`lidar_terms`]: the LiDAR terms (depth, intensity, regulariser) for a batch of rays with
//!   scene, β, decoder, intensity-mapping and pose gradients.
//! - [`intensity`]: the LiDAR intensity decoder and per-LiDAR intensity mapping.
//! - [`sdf_init`]: geometry initialisation: the SDF fitted directly to the LiDAR returns.
//! - [`regulariser`]: Eikonal near LiDAR hits (tetrahedral stencil) and weight suppression.
//! - [`camera_rgb`]: the camera colour term (feature rendering, sky, colour decoder on SH view
//!   encoding, per-camera exposure) with scene, decoder, exposure and pose gradients.
//! - [`background`]: the inverted-sphere background field beyond the scene box (16 samples per
//!   camera ray, uniform in disparity).
//! - [`depth_calib`]: one UniCal step: scene + every sensor's extrinsic (its tests in
//!   `depth_calib/tests.rs`).
//! - [`depth_config`]: its configuration, one serde type with every default stated once.
//! - [`pose_steps`]: how a pose steps (Adam as a delta) and the holds and bounds on a camera's step.
//! - [`calibrator`]: that stage prepared from a drive as an `optim::runner::Calibrator`.
//! - [`pose_newton`]: preconditioned LiDAR pose steps (the objective's gradient, the rendered
//!   depth's point-to-plane curvature).
//! - [`coverage`]: how high the LiDARs look; camera rays above their highest beam are optionally
//!   not drawn (the scene has no geometry there).
//! - [`composite`]: SDF → opacity and front-to-back compositing of depth, opacity and features
//!   (Eq. 2), with a division-free backward pass.

pub mod adam;
pub mod background;
pub mod calibrator;
pub mod camera_rgb;
pub mod composite;
pub mod correspondences;
pub mod coverage;
pub mod depth_calib;
pub mod depth_config;
pub mod field;
pub mod gemm;
pub mod grad_sink;
pub mod hash_grid;
pub mod hash_load;
pub mod intensity;
pub mod lidar_terms;
pub mod masks;
pub mod mlp;
pub mod observability;
pub mod occupancy;
pub mod pose;
pub mod pose_newton;
pub mod pose_steps;
pub mod pose_window;
pub mod regulariser;
pub mod scene_bounds;
pub mod scene_sweeps;
pub mod sdf_init;
pub mod surface_align;
pub mod table_memory;
pub mod transient;
