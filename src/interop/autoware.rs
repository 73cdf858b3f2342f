//! Autoware `sensor_kit_calibration.yaml` (the tier4 calibration manager's layout).
//!
//! One root key, `sensor_kit_base_link`, whose children are the sensors' poses in it:
//! `parent_from_child` as `x y z` (m) and URDF fixed-axis `roll pitch yaw` (rad). rigcal's
//! sensor kit frame is the rig's vehicle frame (the comment at the top says so). Children are
//! named as Autoware's sensor kits name them: a LiDAR `<frame>_base_link`, a camera by its
//! body frame `<camera>/camera_link` (x forward), not its optical frame, so a camera's entry is
//! `vehicle_from_body` (REP-103).

use super::frames;
use super::numbers::num;
use super::text::{comment, yaml_str};
use crate::calib::{Rig, SensorKind};
use crate::geometry::Rigid;

/// The root key of the file.
pub const ROOT: &str = "sensor_kit_base_link";

/// Autoware's name for a LiDAR's frame: `<frame>_base_link`.
pub fn lidar_key(frame_id: &str) -> String {
    if frame_id.ends_with("_base_link") {
        frame_id.to_string()
    } else {
        format!("{frame_id}_base_link")
    }
}

/// Autoware's name for a camera's body frame: `<camera>/camera_link`.
pub fn camera_key(frame_id: &str) -> String {
    let body = frames::body_link(frame_id);
    if body.ends_with("/camera_link") {
        return body;
    }
    let stem = body.strip_suffix("_link").unwrap_or(&body);
    format!("{stem}/camera_link")
}

fn entry(out: &mut String, child: &str, t: Rigid) {
    let [r, p, y] = t.roll_pitch_yaw_rad();
    let v = t.translation;
    out.push_str(&format!(
        "  {}:\n    x: {}\n    y: {}\n    z: {}\n    roll: {}\n    pitch: {}\n    yaw: {}\n",
        yaml_str(child),
        num(v.x),
        num(v.y),
        num(v.z),
        num(r),
        num(p),
        num(y)
    ));
}

pub fn export(rig: &Rig) -> String {
    let mut out = format!(
        "# Autoware sensor_kit_calibration.yaml, written by rigcal {}.\n\
         # Each entry is the child frame's pose in the root frame, parent_from_child:\n\
         # p_root = R p_child + (x, y, z); metres; radians; URDF fixed-axis roll-pitch-yaw,\n\
         # R = Rz(yaw) Ry(pitch) Rx(roll). Root: {ROOT}, which here is the rig's\n\
         # vehicle frame '{}': sensor_kit_base_link_from_child = {}_from_child. If your sensor\n\
         # kit frame is not the vehicle frame, compose with sensor_kit_from_vehicle first.\n\
         # LiDARs are <frame>_base_link; cameras are given by their body frame\n\
         # <camera>/camera_link (x forward, y left, z up), not the optical frame, as Autoware\n\
         # expects.\n{ROOT}:\n",
        env!("CARGO_PKG_VERSION"),
        comment(&rig.vehicle_frame),
        comment(&rig.vehicle_frame)
    );
    for (key, t) in entries(rig) {
        entry(&mut out, &key, t);
    }
    out
}

/// Every sensor's key under the root and its pose there, in the rig's order.
pub fn entries(rig: &Rig) -> Vec<(String, Rigid)> {
    rig.sensors
        .iter()
        .map(|s| match s.kind {
            SensorKind::Lidar => (lidar_key(&s.frame_id), s.vehicle_from_sensor),
            SensorKind::Camera => (camera_key(&s.frame_id), frames::vehicle_from_body(s)),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::test_rig;
    use super::*;
    use glam::{DQuat, DVec3};

    #[test]
    fn entries_are_vehicle_from_lidar_and_vehicle_from_camera_body() {
        let rig = test_rig::rig();
        let text = export(&rig);
        let y: serde_yaml::Value = serde_yaml::from_str(&text).unwrap();
        let root = &y["sensor_kit_base_link"];
        for s in &rig.sensors {
            let (key, expected) = match s.kind {
                SensorKind::Lidar => (lidar_key(&s.frame_id), s.vehicle_from_sensor),
                SensorKind::Camera => (camera_key(&s.frame_id), frames::vehicle_from_body(s)),
            };
            let e = &root[key.as_str()];
            let f = |k: &str| e[k].as_f64().unwrap();
            let t = Rigid::new(
                DQuat::from_euler(glam::EulerRot::ZYX, f("yaw"), f("pitch"), f("roll")),
                DVec3::new(f("x"), f("y"), f("z")),
            );
            let (r, d) = t.difference(expected);
            assert!(r < 1e-12 && d < 1e-12, "{key}");
        }
    }

    #[test]
    fn keys_follow_autoware_sensor_kits() {
        assert_eq!(lidar_key("velodyne_top"), "velodyne_top_base_link");
        assert_eq!(
            lidar_key("velodyne_top_base_link"),
            "velodyne_top_base_link"
        );
        assert_eq!(
            camera_key("camera0/camera_optical_link"),
            "camera0/camera_link"
        );
        assert_eq!(camera_key("front_camera"), "front_camera/camera_link");
        assert_eq!(camera_key("front_optical_frame"), "front/camera_link");
    }
}
