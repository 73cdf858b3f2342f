//! Image keypoints and matches without learned weights (method.md §15.6), for UniCal's
//! surface-alignment correspondences and keypoint heat maps (§9, §10): `orb` (oriented FAST +
//! steered BRIEF), `matching` (mutual nearest neighbours + ratio test), `epipolar` (RANSAC on
//! the essential matrix of two calibrated views).

pub mod epipolar;
pub mod matching;
pub mod orb;
