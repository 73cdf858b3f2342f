//! Image keypoints and matches without learned weights (method.md §15.6), for UniCal's
//! surface-alignment correspondences and keypoint heat maps (§9, §10): `orb` (oriented FAST +
//! steered BRIEF), `matching` (mutual nearest neighbours + ratio test), `epipolar` (RANSAC on
//! the essential matrix of two calibrated views); `chessboard` (checkerboard corners of a known
//! pattern, ordered and sub-pixel, for target-based calibration); `grey` (the one grey-level
//! conversion every image method uses).

pub mod chessboard;
pub mod epipolar;
pub mod grey;
pub mod matching;
pub mod orb;
