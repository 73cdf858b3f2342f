//! Optimisers and the machinery that runs them in the background.
//!
//! - [`runner`]: the [`runner::Calibrator`] trait and [`runner::Run`], a worker thread that
//!   publishes extrinsics and losses on a channel, with pause / resume / stop.
//! - [`divergence`]: [`divergence::Guarded`], which ends a run at its first non-finite loss
//!   or pose and keeps the best result before it.
//! - [`edge_align`]: the target-free edge-alignment cost (LiDAR depth discontinuities against
//!   image edges) and a compass search over one camera's extrinsic.
//! - [`edge_refine`]: that search as a calibrator over several cameras.
//! - [`photo_consistency`]: the images of one camera agreeing about the colour of the LiDAR
//!   points, and a compass search over its extrinsic.

pub mod divergence;
pub mod edge_align;
pub mod edge_refine;
pub mod photo_consistency;
pub mod runner;
