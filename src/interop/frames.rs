//! REP-103 camera frames: the optical frame (x right, y down, z forward), in which rigcal keeps
//! every camera, and the body frame (x forward, y left, z up) that URDF's `camera_link` and
//! Autoware's calibration files name.

use glam::DQuat;

use crate::calib::Sensor;
use crate::geometry::Rigid;

/// `body_from_optical`: the fixed joint `rpy="-π/2 0 -π/2"` from a camera's body link to its
/// optical link (optical z forward → body x, optical x right → body −y, optical y down → body −z).
pub fn body_from_optical() -> Rigid {
    use std::f64::consts::FRAC_PI_2;
    Rigid::new(
        DQuat::from_euler(glam::EulerRot::ZYX, -FRAC_PI_2, 0.0, -FRAC_PI_2),
        glam::DVec3::ZERO,
    )
}

/// The body link of a camera whose optical frame is `frame_id`: a trailing `_optical_frame`,
/// `_optical_link` or `_optical` becomes `_link`; otherwise `_link` is appended.
pub fn body_link(frame_id: &str) -> String {
    for suffix in ["_optical_frame", "_optical_link", "_optical"] {
        if let Some(stem) = frame_id.strip_suffix(suffix) {
            return format!("{stem}_link");
        }
    }
    format!("{frame_id}_link")
}

/// `vehicle_from_body` of a camera (`vehicle_from_optical · optical_from_body`).
pub fn vehicle_from_body(camera: &Sensor) -> Rigid {
    camera.vehicle_from_sensor * body_from_optical().inverse()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn optical_axes_map_to_body_axes() {
        let b = body_from_optical();
        let close = |a: DVec3, e: DVec3| (a - e).length() < 1e-12;
        assert!(close(b.transform_vector(DVec3::Z), DVec3::X)); // forward
        assert!(close(b.transform_vector(DVec3::X), -DVec3::Y)); // right
        assert!(close(b.transform_vector(DVec3::Y), -DVec3::Z)); // down
        assert_eq!(body_link("cam0/camera_optical_link"), "cam0/camera_link");
        assert_eq!(body_link("front_optical_frame"), "front_link");
        assert_eq!(body_link("front_camera"), "front_camera_link");
    }
}
