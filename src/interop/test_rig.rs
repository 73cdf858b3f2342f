//! A rig for the format tests: two LiDARs and cameras of every distortion model, at poses
//! with no special angles.

use glam::{DQuat, DVec3};

use crate::calib::{Rig, Sensor, SensorKind};
use crate::geometry::Rigid;
use crate::geometry::camera::{CameraIntrinsics, CameraModel};

fn pose(rx: f64, ry: f64, rz: f64, t: [f64; 3]) -> Rigid {
    Rigid::new(
        DQuat::from_euler(glam::EulerRot::ZYX, rz, ry, rx),
        DVec3::from_array(t),
    )
}

fn camera(name: &str, model: CameraModel, distortion: Vec<f64>, t: Rigid) -> Sensor {
    Sensor {
        name: name.into(),
        kind: SensorKind::Camera,
        frame_id: name.into(),
        topics: vec![
            format!("/{name}/image/compressed"),
            format!("/{name}/camera_info"),
        ],
        vehicle_from_sensor: t,
        camera: Some(CameraIntrinsics {
            width: 1920,
            height: 1080,
            model,
            fx: 1970.25,
            fy: 1969.5,
            cx: 962.125,
            cy: 541.75,
            distortion,
        }),
    }
}

/// Optical frame looking along the vehicle's `yaw` direction, slightly tilted.
fn looking(yaw: f64, t: [f64; 3]) -> Rigid {
    let body = pose(0.011, -0.023, yaw, t);
    body * super::frames::body_from_optical()
}

pub fn rig() -> Rig {
    Rig {
        vehicle_frame: "base_link".into(),
        sensors: vec![
            Sensor {
                name: "lidar_top".into(),
                kind: SensorKind::Lidar,
                frame_id: "lidar_top".into(),
                topics: vec!["/lidar_top/points".into()],
                vehicle_from_sensor: pose(0.01, -0.02, 1.5, [1.0, 0.02, 1.8]),
                camera: None,
            },
            Sensor {
                name: "lidar_front".into(),
                kind: SensorKind::Lidar,
                frame_id: "lidar_front".into(),
                topics: vec!["/lidar_front/points".into()],
                vehicle_from_sensor: pose(-0.03, 0.2, -0.05, [2.1, -0.1, 0.9]),
                camera: None,
            },
            camera(
                "front_camera",
                CameraModel::Pinhole,
                vec![],
                looking(0.02, [1.6, 0.05, 1.5]),
            ),
            camera(
                "left_camera",
                CameraModel::PlumbBob,
                vec![-0.31, 0.12, 0.0011, -0.0007, 0.0],
                looking(1.3, [1.2, 0.6, 1.5]),
            ),
            camera(
                "back_camera",
                CameraModel::Equidistant,
                vec![0.05, -0.01, 0.002, -0.0003],
                looking(3.1, [-0.4, 0.0, 1.6]),
            ),
            camera(
                "right_camera",
                CameraModel::RationalPolynomial,
                vec![0.4, -0.1, 0.001, 0.0005, 0.01, 0.7, -0.05, 0.02],
                looking(-1.4, [1.2, -0.6, 1.5]),
            ),
        ],
    }
}

/// The largest rotation (rad) and translation (m) difference between two rigs' sensors of the
/// same name, and that every sensor of `a` is in `b`.
pub fn max_difference(a: &Rig, b: &Rig) -> (f64, f64) {
    let mut worst = (0.0f64, 0.0f64);
    for s in &a.sensors {
        let Some(o) = b.sensor(&s.name) else {
            return (f64::INFINITY, f64::INFINITY);
        };
        let (r, t) = s.vehicle_from_sensor.difference(o.vehicle_from_sensor);
        worst = (worst.0.max(r), worst.1.max(t));
    }
    worst
}
