//! The continuous 6D rotation representation (Zhou et al., CVPR 2019), method.md §11.
//!
//! Convention (Zhou's): the 6D vector is the first two **columns** of R, `[a1 | a2]`, and
//! Gram–Schmidt recovers `R = [b1 b2 b3]` as columns. Any 6D vector with non-parallel halves maps
//! to a rotation, which is what makes it a smooth parameterisation for gradient descent.

use glam::{DMat3, DVec3};

/// First two columns of a rotation matrix (method.md §11: init from the initial extrinsic).
pub fn from_matrix(rotation: DMat3) -> [f64; 6] {
    let (a1, a2) = (rotation.x_axis, rotation.y_axis);
    [a1.x, a1.y, a1.z, a2.x, a2.y, a2.z]
}

/// Gram–Schmidt map, method.md §11: b1 = a1/‖a1‖, b2 = normalise(a2 − (b1·a2) b1), b3 = b1 × b2.
/// Returns `None` when the halves are (near) zero or parallel.
pub fn to_matrix(v: [f64; 6]) -> Option<DMat3> {
    let a1 = DVec3::new(v[0], v[1], v[2]);
    let a2 = DVec3::new(v[3], v[4], v[5]);
    let b1 = a1.try_normalize()?;
    let b2 = (a2 - b1.dot(a2) * b1).try_normalize()?;
    let b3 = b1.cross(b2);
    Some(DMat3::from_cols(b1, b2, b3))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::so3;

    #[test]
    fn round_trip_rotation() {
        let r = so3::exp_mat(DVec3::new(0.4, -1.1, 2.0));
        let back = to_matrix(from_matrix(r)).unwrap();
        assert!((back - r).to_cols_array().iter().all(|d| d.abs() < 1e-12));
    }

    #[test]
    fn any_generic_vector_gives_a_rotation() {
        let r = to_matrix([1.0, 0.2, -0.3, 0.5, 2.0, 0.1]).unwrap();
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        assert!(
            (r.transpose() * r - DMat3::IDENTITY)
                .to_cols_array()
                .iter()
                .all(|d| d.abs() < 1e-12)
        );
    }

    #[test]
    fn degenerate_is_none() {
        assert!(to_matrix([1.0, 0.0, 0.0, 2.0, 0.0, 0.0]).is_none());
        assert!(to_matrix([0.0; 6]).is_none());
    }
}
