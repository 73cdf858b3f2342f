//! Reading drives: MCAP ingestion (ROS 2 CDR and Foxglove protobuf/JSON), TF resolution and the
//! indexed, lazily decoded [`Drive`].
//!
//! Data flow: [`container`] finds channels and chunks → [`Drive::open`] scans every message once
//! (in parallel), fully decoding only the small ones (TF, poses, camera info) and keeping a
//! [`container::MessageRef`] plus header stamp for sweeps and images → [`tf`] builds the TF tree,
//! the trajectory and the initial rig → sweeps and images are decoded on demand
//! ([`Drive::load_sweep`], [`Drive::load_image`]) through bounded caches.

mod byte_lru;
pub mod cdr;
pub mod container;
pub mod decode;
pub mod drive;
pub mod error;
pub mod foxglove;
pub mod frames;
pub mod image;
pub mod pointcloud;
pub mod protobuf;
mod resync;
pub mod ros2;
pub mod tf;
pub mod types;

pub use drive::{
    Drive, DriveOptions, SensorStream, StampSource, TopicStats, in_segments, spread_evenly,
};
pub use error::{LogError, MAX_PROBLEMS, Problem, Problems};
pub use pointcloud::LidarSweep;
