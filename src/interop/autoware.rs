//! Autoware `sensor_kit_calibration.yaml` (the tier4 calibration manager's layout).
//!
//! One root key, the vehicle frame, whose children are the sensors' poses in it:
//! `parent_from_child` as `x y z` (m) and URDF fixed-axis `roll pitch yaw` (rad). Autoware
//! names a camera by its body frame (`<camera>_link`, x forward), not its optical frame, so a
//! camera's entry is `vehicle_from_body` (REP-103).

use super::frames;
use super::numbers::num;
use crate::calib::{Rig, SensorKind};
use crate::geometry::Rigid;

fn entry(out: &mut String, child: &str, t: Rigid) {
    let [r, p, y] = t.roll_pitch_yaw_rad();
    let v = t.translation;
    out.push_str(&format!(
        "  {child}:\n    x: {}\n    y: {}\n    z: {}\n    roll: {}\n    pitch: {}\n    yaw: {}\n",
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
         # R = Rz(yaw) Ry(pitch) Rx(roll). Root: the rig's vehicle frame '{}' (rename it to\n\
         # sensor_kit_base_link only if that is the same frame on your vehicle).\n\
         # Cameras are given by their body frame <camera>_link (x forward, y left, z up), not the\n\
         # optical frame, as Autoware expects.\n{}:\n",
        env!("CARGO_PKG_VERSION"),
        rig.vehicle_frame,
        rig.vehicle_frame
    );
    for s in &rig.sensors {
        match s.kind {
            SensorKind::Lidar => entry(&mut out, &s.frame_id, s.vehicle_from_sensor),
            SensorKind::Camera => entry(
                &mut out,
                &frames::body_link(&s.frame_id),
                frames::vehicle_from_body(s),
            ),
        }
    }
    out
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
        let root = &y["base_link"];
        for s in &rig.sensors {
            let (key, expected) = match s.kind {
                SensorKind::Lidar => (s.frame_id.clone(), s.vehicle_from_sensor),
                SensorKind::Camera => {
                    (frames::body_link(&s.frame_id), frames::vehicle_from_body(s))
                }
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
}
