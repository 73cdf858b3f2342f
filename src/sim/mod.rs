//! The ground-truth simulator: a seeded procedural world, a rig, a trajectory, and the sensor
//! streams a real drive would record, written as a ROS 2 MCAP with the ground truth beside it.

pub mod bvh;
pub mod camera_sim;
pub mod damage;
pub mod demo;
mod layout;
pub mod lidar_sim;
pub mod noise;
pub mod raster;
pub mod rigs;
pub mod silhouettes;
pub mod synth;
pub mod trajectories;
pub mod wide;
pub mod world;
pub mod writer;
