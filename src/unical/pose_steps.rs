//! How a pose steps in a UniCal run: one Adam step applied as a delta (so the f64 pose keeps
//! its precision), and the constraints on a camera's step, each undoing part of it: the
//! directions its information does not observe, its optical axis, a bound on its rotation; and
//! the translation the free cameras share.

use glam::DVec3;

use super::adam::DenseAdam;
use super::observability::PoseInformation;
use super::pose::PoseParams;

/// One Adam step of a pose from its 9 gradients, applied as a delta so the f64 pose keeps its
/// precision.
/// `translation_scale` multiplies the translation's step (its rate relative to the rotation's).
pub(super) fn pose_step(
    opt: &mut DenseAdam,
    p: &mut PoseParams,
    grad: &[f32; 9],
    lr: f32,
    translation_scale: f64,
) {
    if lr == 0.0 {
        return;
    }
    let mut flat: Vec<f32> =
        p.r6.iter()
            .map(|v| *v as f32)
            .chain(p.translation_m.to_array().iter().map(|v| *v as f32))
            .collect();
    let before = flat.clone();
    opt.step(&mut flat, grad, lr);
    for k in 0..6 {
        p.r6[k] += (flat[k] - before[k]) as f64;
    }
    for k in 0..3 {
        p.translation_m[k] += (flat[6 + k] - before[6 + k]) as f64 * translation_scale;
    }
}

/// Reprojections a camera's information must hold before its poorly observed directions are
/// held ([`DepthCalibConfig::camera_hold_unobserved`]).
pub(super) const INFORMATION_MIN_COUNT: f64 = 200.0;
/// Per step, what the information keeps of what it held (about 30 steps' memory).
pub(super) const INFORMATION_FORGETTING: f64 = 0.97;

/// Undo the part of the step from `before` to `pose` along the directions the correspondence
/// term observes less than `ratio` times its best ([`super::observability`]).
pub(super) fn hold_unobserved(
    pose: &mut PoseParams,
    before: &PoseParams,
    info: &PoseInformation,
    ratio: f64,
) {
    let (r0, r1) = (before.rotation(), pose.rotation());
    let omega =
        crate::geometry::so3::log(glam::DQuat::from_mat3(&(r1 * r0.transpose())).normalize());
    let v = pose.translation_m - before.translation_m;
    let (omega, v) = info.observed_step((omega, v), ratio, INFORMATION_MIN_COUNT);
    let rotation = crate::geometry::so3::exp_mat(omega) * r0;
    pose.r6 = crate::geometry::rot6d::from_matrix(rotation);
    pose.translation_m = before.translation_m + v;
}

/// Undo the part of the translation step from `before` to `pose` along the camera's optical
/// axis (its frame's z in the vehicle frame, after the step)
/// ([`DepthCalibConfig::camera_hold_axial`]).
pub(super) fn hold_axial(pose: &mut PoseParams, before: &PoseParams) {
    let axis = pose.rotation().col(2).normalize_or_zero();
    let step = pose.translation_m - before.translation_m;
    pose.translation_m -= axis * step.dot(axis);
}

/// Keep `pose`'s rotation within `bound_rad` of `start`: a rotation further off is turned back
/// along the geodesic to the bound (its translation is left as it is).
pub(super) fn bound_rotation(pose: &mut PoseParams, start: glam::DQuat, bound_rad: f64) {
    let now = glam::DQuat::from_mat3(&pose.rotation()).normalize();
    let offset = crate::geometry::so3::log(start.inverse() * now);
    let angle = offset.length();
    if angle <= bound_rad {
        return;
    }
    let held = start * crate::geometry::so3::exp(offset * (bound_rad / angle));
    pose.r6 = crate::geometry::rot6d::from_matrix(glam::DMat3::from_quat(held));
}

/// The step of the translation the `free` cameras share: Adam on the sum of their translation
/// gradients (the last three of each `grads[k]`).
pub(super) fn shared_translation_step(
    opt: &mut DenseAdam,
    grads: &[[f32; 9]],
    free: &[usize],
    lr: f32,
) -> DVec3 {
    let mut sum = [0.0f32; 3];
    for &k in free {
        sum.iter_mut()
            .zip(&grads[k][6..])
            .for_each(|(a, b)| *a += b);
    }
    let mut shift = [0.0f32; 3];
    opt.step(&mut shift, &sum, lr);
    DVec3::new(shift[0] as f64, shift[1] as f64, shift[2] as f64)
}

pub(super) fn pose_grad_flat(g: &super::pose::PoseGrad, w: f64) -> [f32; 9] {
    let mut out = [0.0f32; 9];
    for k in 0..6 {
        out[k] = (g.r6[k] * w) as f32;
    }
    for k in 0..3 {
        out[6 + k] = (g.translation_m[k] * w) as f32;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::adam::AdamConfig;
    use super::*;
    use crate::geometry::Rigid;

    #[test]
    fn a_bounded_rotation_is_turned_back_to_its_bound_along_the_geodesic() {
        use crate::geometry::so3;
        let start = so3::exp(DVec3::new(0.2, -0.4, 1.0));
        let axis = DVec3::new(1.0, 2.0, -0.5).normalize_or_zero();
        let bound = 1f64.to_radians();
        // Inside the bound nothing changes.
        let inside = Rigid::new(start * so3::exp(axis * 0.5f64.to_radians()), DVec3::X);
        let mut p = PoseParams::from_rigid(inside);
        let before = p;
        bound_rotation(&mut p, start, bound);
        assert_eq!(p, before);
        // Outside it, back to the bound about the same axis; the translation stays.
        let outside = Rigid::new(start * so3::exp(axis * 3f64.to_radians()), DVec3::X);
        let mut p = PoseParams::from_rigid(outside);
        bound_rotation(&mut p, start, bound);
        let got = p.to_rigid();
        let offset = so3::log(start.inverse() * got.rotation);
        assert!(
            (offset.length() - bound).abs() < 1e-9,
            "{}",
            offset.length()
        );
        assert!(offset.normalize_or_zero().dot(axis) > 1.0 - 1e-9);
        assert_eq!(got.translation, DVec3::X);
    }

    /// A camera looking at a far wall: a step along the turn-and-shift it cannot tell apart is
    /// undone, the step's observed part is applied, and a pose with nothing held moves freely.
    #[test]
    fn holding_unobserved_directions_undoes_only_their_part_of_a_step() {
        use crate::geometry::so3;
        use crate::unical::observability::fixtures::{camera_rotation, information_of, wall};
        let rotation = camera_rotation();
        let camera = Rigid::new(glam::DQuat::from_mat3(&rotation), DVec3::new(1.0, 0.0, 1.5));
        let info = information_of(&wall(40.0, 4.0, 10));
        let before = PoseParams::from_rigid(camera);
        // Shift 10 cm sideways (+y) while turning so the wall's centre stays put.
        let turn = so3::exp(DVec3::new(0.0, 0.0, -0.1 / 40.0));
        let moved = Rigid::new(turn * camera.rotation, camera.translation + DVec3::Y * 0.1);
        let mut p = PoseParams::from_rigid(moved);
        hold_unobserved(&mut p, &before, &info, 0.05);
        let got = p.to_rigid();
        assert!(
            (got.translation - camera.translation).length() < 0.02,
            "{got:?}"
        );
        assert!(so3::log(camera.rotation.inverse() * got.rotation).length() < 0.02 / 40.0);
        // A pan alone is observed: most of it is kept.
        let pan = so3::exp(DVec3::new(0.0, 0.0, 0.01));
        let mut p = PoseParams::from_rigid(Rigid::new(pan * camera.rotation, camera.translation));
        hold_unobserved(&mut p, &before, &info, 0.05);
        let kept = so3::log(p.to_rigid().rotation * camera.rotation.inverse());
        assert!(kept.z > 0.009, "{kept:?}");
        // Nothing held yet: the step passes whole.
        let mut p = PoseParams::from_rigid(moved);
        hold_unobserved(&mut p, &before, &PoseInformation::default(), 0.05);
        assert!((p.to_rigid().translation - moved.translation).length() < 1e-12);
    }

    #[test]
    fn the_axial_hold_keeps_only_the_step_square_to_the_optical_axis() {
        // A camera looking along the vehicle's +x (its z axis), stepping 3 cm forward, 2 cm
        // left and 1 cm up: the forward part is undone, the rest and the rotation stay.
        let looking_forward =
            glam::DMat3::from_cols(glam::DVec3::NEG_Y, glam::DVec3::NEG_Z, glam::DVec3::X);
        let before = PoseParams {
            r6: crate::geometry::rot6d::from_matrix(looking_forward),
            translation_m: glam::DVec3::new(1.0, 0.0, 1.5),
        };
        let mut p = before;
        p.translation_m += glam::DVec3::new(0.03, 0.02, 0.01);
        hold_axial(&mut p, &before);
        assert!((p.translation_m - glam::DVec3::new(1.0, 0.02, 1.51)).length() < 1e-12);
        assert_eq!(p.r6, before.r6);
    }

    #[test]
    fn the_shared_translation_follows_the_sum_of_the_cameras_gradients() {
        let mut g = [[0.0f32; 9]; 3];
        // Two cameras pulled up (negative gradient in z) and sideways in opposite directions;
        // the third, frozen, pulled hard down.
        g[0][6..].copy_from_slice(&[0.5, 0.0, -1.0]);
        g[1][6..].copy_from_slice(&[-0.5, 0.0, -0.2]);
        g[2][6..].copy_from_slice(&[0.0, 0.0, 100.0]);
        let mut opt = DenseAdam::new(3, AdamConfig::STANDARD);
        let shift = shared_translation_step(&mut opt, &g, &[0, 1], 0.01);
        // Adam's first step is the rate along the sign of each summed component.
        assert!((shift.z - 0.01).abs() < 1e-6, "{shift}");
        assert!(shift.x.abs() < 1e-6 && shift.y.abs() < 1e-6, "{shift}");
        let mut opt = DenseAdam::new(3, AdamConfig::STANDARD);
        let shift = shared_translation_step(&mut opt, &g, &[0, 1, 2], 0.01);
        assert!((shift.z + 0.01).abs() < 1e-6, "{shift}");
    }
}
