//! The simulator's alignment self-check: do LiDAR depth discontinuities, projected with the
//! ground-truth extrinsics, land on the rendered image's edges?
//!
//! How it works: the stationary `checkerboard` scene seen by the pandaset rig's front camera
//! (one image at 1 s) and its Pandar64 (16 sweeps accumulated: the vehicle stands still and the
//! firing azimuths drift between sweeps, so the outermost return of all of them marks each
//! silhouette; one sweep alone lands up to one azimuth step, ~7 px, inside it). Silhouette
//! points are found by [`crate::eval::edges::depth_discontinuities`], image edges by
//! [`crate::eval::edges::image_edges`]; each point's distance to the nearest edge comes from an
//! exact distance transform. Rotating the camera's extrinsic by a known error moves the points
//! off the edges: `tests/sim_acceptance.rs` bounds the mean with the truth and with 1° off, and
//! `examples/silhouette_check.rs` prints the whole distribution.

use glam::DVec3;
use image::RgbImage;

use super::camera_sim::{self, Exposure, RayTable};
use super::lidar_sim;
use super::rigs::{RigPreset, SimCamera, SimLidar, SimRig};
use super::trajectories::{self, TrajectoryConfig, TrajectoryKind};
use super::world::{SceneKind, World};
use crate::eval::edges;
use crate::geometry::projection::{SweepView, project_sweep};
use crate::geometry::{Rigid, Trajectory, TrajectoryError, so3};

/// When the image is taken and the sweeps start (ns).
const IMAGE_STAMP_NANOS: i64 = 1_000_000_000;
const FIRST_SWEEP_NANOS: i64 = 500_000_000;
const SWEEPS: i64 = 16;

/// The rendered image, its edges and the silhouette points of the stationary scene.
pub struct SilhouetteCheck {
    pub image: RgbImage,
    /// Edge map of `image` (true = edge).
    pub edges: Vec<bool>,
    /// Distance (px) from every pixel to the nearest edge.
    distance: Vec<f32>,
    /// Silhouette points in the LiDAR frame.
    pub silhouettes: Vec<[f32; 3]>,
    trajectory: Trajectory,
    lidar: SimLidar,
    camera: SimCamera,
}

impl SilhouetteCheck {
    /// The stationary checkerboard scene built with `seed`, its image and silhouettes.
    pub fn stationary(seed: u64) -> Result<Self, TrajectoryError> {
        let rig = SimRig::preset(RigPreset::Pandaset);
        let tcfg = TrajectoryConfig {
            kind: TrajectoryKind::Stationary,
            duration_secs: 3.0,
            rate_hz: 100.0,
            speed_mps: 0.0,
            seed,
        };
        let trajectory = Trajectory::new(trajectories::generate(&tcfg));
        let world = World::build(
            SceneKind::Checkerboard,
            &trajectories::path_polyline(&tcfg, 1.0),
            seed,
        );
        let lidar = rig.lidars[0].clone();
        let camera = rig
            .cameras
            .iter()
            .find(|c| c.name == "front_camera")
            .unwrap_or(&rig.cameras[0])
            .clone();
        let image = camera_sim::render(
            &world,
            &RayTable::new(&camera.intrinsics),
            &camera.intrinsics,
            trajectory.world_from_vehicle(IMAGE_STAMP_NANOS)? * camera.vehicle_from_camera,
            Exposure {
                gain: 1.0,
                tint: [1.0; 3],
                noise_sigma: 2.0,
                seed: 1,
            },
        );
        let (w, h) = (image.width() as usize, image.height() as usize);
        let edges = edges::image_edges(&image);
        let distance = edges::distance_transform(&edges, w, h);
        let mut accumulated: Vec<[f32; 3]> = Vec::new();
        for k in 0..SWEEPS {
            let stamp = FIRST_SWEEP_NANOS + k * 100_000_000;
            let sweep = lidar_sim::simulate_sweep(&world, &lidar, &trajectory, stamp, 5)?;
            accumulated.extend_from_slice(&sweep.points_in_sensor);
        }
        let silhouettes = edges::depth_discontinuities(&accumulated, 0.05)
            .into_iter()
            .map(|i| accumulated[i])
            .collect();
        Ok(Self {
            image,
            edges,
            distance,
            silhouettes,
            trajectory,
            lidar,
            camera,
        })
    }

    /// The silhouette points' pixels with the camera's extrinsic rotated by `error_deg` about
    /// its y axis (those in front of the camera and inside its model).
    pub fn pixels(&self, error_deg: f64) -> Result<Vec<[f32; 2]>, TrajectoryError> {
        let wrong = self.camera.vehicle_from_camera
            * Rigid::new(so3::exp(DVec3::Y * error_deg.to_radians()), DVec3::ZERO);
        let intensity = vec![0.0; self.silhouettes.len()];
        let view = SweepView {
            points_in_lidar: &self.silhouettes,
            intensity: &intensity,
            time_offset_secs: None,
            stamp_nanos: IMAGE_STAMP_NANOS,
        };
        Ok(project_sweep(
            &view,
            &self.trajectory,
            self.lidar.vehicle_from_lidar,
            wrong,
            &self.camera.intrinsics,
            IMAGE_STAMP_NANOS,
            1,
        )?
        .iter()
        .map(|p| p.pixel)
        .collect())
    }

    /// The in-image pixels of `pixels`, each with its distance (px) to the nearest image edge
    /// ([`edges::edge_distances`], what the mean counts).
    pub fn distances(&self, pixels: &[[f32; 2]]) -> Vec<([f32; 2], f32)> {
        let (w, h) = (self.image.width() as usize, self.image.height() as usize);
        edges::edge_distances(pixels, &self.distance, w, h).collect()
    }

    /// Mean distance (px) of `pixels` to the nearest edge (`None`: none in the image).
    pub fn mean_distance(&self, pixels: &[[f32; 2]]) -> Option<f64> {
        let (w, h) = (self.image.width() as usize, self.image.height() as usize);
        edges::mean_edge_distance(pixels, &self.distance, w, h)
    }
}
