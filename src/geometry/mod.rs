//! Geometry on the CPU, in f64: rigid transforms, rotations, trajectories, camera models.
//!
//! Transforms are `glam::DAffine3` values named by what they map: `world_from_vehicle *
//! vehicle_from_lidar` is `world_from_lidar`. Rotations are kept orthonormal by construction
//! (built from unit quaternions) so `inverse()` of a rigid transform is exact up to rounding.

pub mod camera;
pub(crate) mod distortion;
pub mod motion;
pub mod pnp;
pub mod projection;
pub mod rigid;
pub mod rolling_shutter;
pub mod rot6d;
pub mod so3;
pub mod spd;
pub mod trajectory;

pub use rigid::{RigError, Rigid, rig_errors};
pub use rolling_shutter::{RowTimes, SAMPLED_ROWS};
pub use trajectory::{StampConflict, Trajectory, TrajectoryError, conflicting_stamps};
