//! The classical calibrators of the paper's comparison (supplementary A2.1): `icp`
//! (point-to-plane ICP for LiDAR–LiDAR pairs) and `icp_calibrator` (it as a runner
//! `Calibrator`: every LiDAR against a reference LiDAR); `mutual_info` (LiDAR reflectivity
//! against image grey level, Pandey et al.) and `mi_calibrator` (every camera against a
//! reference LiDAR). The checkerboard edge-and-plane method and pose-graph unification are to
//! come (issue 8).

pub mod icp;
pub mod icp_calibrator;
pub mod mi_calibrator;
pub mod mutual_info;
