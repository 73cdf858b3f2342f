//! KITTI object calib (`calib/XXXXXX.txt`): exactly the seven lines `P0`, `P1`, `P2`, `P3`,
//! `R0_rect`, `Tr_velo_to_cam`, `Tr_imu_to_velo`, in that order, each a row-major list of
//! numbers (readers such as OpenPCDet pick lines by index, so there are no comment lines).
//!
//! Directions are in the keys: `Tr_velo_to_cam` = `cam0_from_lidar`, `Tr_imu_to_velo` =
//! `lidar_from_vehicle` (the vehicle frame stands in for KITTI's IMU). The chosen camera is
//! KITTI's reference: its optical frame is cam0, and it is both `P0` and `P2` (the left colour
//! camera every KITTI consumer projects into) as `K [I | 0]`. Up to two more cameras take `P3`
//! and then `P1` as `K_i [R | t]` with `[R | t]` = `cami_from_cam0`; slots left free repeat the
//! reference (`P1 = P0`, `P3 = P2`). So `y = P_i · R0_rect · Tr_velo_to_cam · x` projects a
//! LiDAR point into camera i exactly, with `R0_rect = I`. KITTI's rectified pairs have `R = I`;
//! for cameras that are not rectified to the reference `R` is their real rotation. The format
//! has no distortion: a camera with non-zero distortion coefficients or a fisheye model is
//! refused by name (its images would have to be rectified first), and so is a fourth camera.

use super::numbers::{rows_3x4, spaced};
use super::{NotExportable, pick};
use crate::calib::{Rig, Sensor, SensorKind};
use crate::geometry::Rigid;

fn projection(cam: &Sensor, cam0: &Sensor) -> Result<[f64; 12], NotExportable> {
    let Some(c) = &cam.camera else {
        return Err(format!("camera '{}' has no intrinsics", cam.name).into());
    };
    if c.has_lens_distortion() {
        return Err(format!(
            "camera '{}' has {} distortion; KITTI calib files have none (rectify its images, or leave it out with --sensors)",
            cam.name,
            c.model.as_str()
        ).into());
    }
    // The reference camera gets an exact identity, not a product that rounds.
    let cam_from_cam0 = if cam.name == cam0.name {
        Rigid::IDENTITY
    } else {
        cam.vehicle_from_sensor.inverse() * cam0.vehicle_from_sensor
    };
    let rt = rows_3x4(cam_from_cam0);
    let k = [[c.fx, 0.0, c.cx], [0.0, c.fy, c.cy], [0.0, 0.0, 1.0]];
    let mut p = [0.0; 12];
    for r in 0..3 {
        for col in 0..4 {
            p[r * 4 + col] = (0..3).map(|i| k[r][i] * rt[i * 4 + col]).sum();
        }
    }
    Ok(p)
}

/// The camera in each of the slots P0..P3: the reference in P0 and P2, the next camera in P3,
/// the one after in P1.
pub fn slots<'a>(rig: &'a Rig, camera: Option<&str>) -> Result<[&'a Sensor; 4], NotExportable> {
    let cam0 = pick(rig, SensorKind::Camera, camera)?;
    let others: Vec<&Sensor> = rig.cameras().filter(|c| c.name != cam0.name).collect();
    if others.len() > 2 {
        let names: Vec<&str> = rig.cameras().map(|c| c.name.as_str()).collect();
        return Err(format!(
            "a KITTI calib file holds at most three cameras (P0/P2, P3, P1); the calibration has {} ({}): choose with --sensors",
            names.len(),
            names.join(", ")
        ).into());
    }
    let p3 = others.first().copied().unwrap_or(cam0);
    let p1 = others.get(1).copied().unwrap_or(cam0);
    Ok([cam0, p1, cam0, p3])
}

pub fn export(
    rig: &Rig,
    camera: Option<&str>,
    lidar: Option<&str>,
) -> Result<String, NotExportable> {
    let cams = slots(rig, camera)?;
    let cam0 = cams[0];
    let velo = pick(rig, SensorKind::Lidar, lidar)?;
    let mut out = String::new();
    for (i, cam) in cams.iter().enumerate() {
        out.push_str(&format!("P{i}: {}\n", spaced(&projection(cam, cam0)?)));
    }
    out.push_str(&format!(
        "R0_rect: {}\n",
        spaced(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0])
    ));
    let cam0_from_velo = cam0.vehicle_from_sensor.inverse() * velo.vehicle_from_sensor;
    out.push_str(&format!(
        "Tr_velo_to_cam: {}\n",
        spaced(&rows_3x4(cam0_from_velo))
    ));
    let velo_from_vehicle: Rigid = velo.vehicle_from_sensor.inverse();
    out.push_str(&format!(
        "Tr_imu_to_velo: {}\n",
        spaced(&rows_3x4(velo_from_vehicle))
    ));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::super::test_rig;
    use super::*;
    use glam::DVec3;

    fn read(text: &str) -> std::collections::BTreeMap<String, Vec<f64>> {
        text.lines()
            .filter_map(|l| l.split_once(':'))
            .map(|(k, v)| {
                (
                    k.to_string(),
                    v.split_whitespace().map(|x| x.parse().unwrap()).collect(),
                )
            })
            .collect()
    }

    #[test]
    fn projects_lidar_points_like_the_rig() {
        let mut rig = test_rig::rig();
        let mut two = rig.clone();
        two.sensors
            .retain(|s| ["front_camera", "left_camera", "lidar_top"].contains(&s.name.as_str()));
        let e = export(&two, None, None).unwrap_err();
        assert!(
            e.to_string().contains("left_camera") && e.to_string().contains("plumb_bob"),
            "{e}"
        );
        rig.sensors
            .retain(|s| s.camera.as_ref().is_none_or(|c| c.distortion.is_empty()));
        // A second undistorted camera.
        let mut other = rig.sensor("front_camera").unwrap().clone();
        other.name = "front_right".into();
        other.vehicle_from_sensor = other.vehicle_from_sensor
            * Rigid::new(glam::DQuat::from_rotation_y(0.3), DVec3::new(0.5, 0.0, 0.0));
        rig.sensors.push(other);
        let text = export(&rig, Some("front_camera"), Some("lidar_front")).unwrap();
        let keys: Vec<&str> = text.lines().filter_map(|l| l.split(':').next()).collect();
        assert_eq!(
            keys,
            [
                "P0",
                "P1",
                "P2",
                "P3",
                "R0_rect",
                "Tr_velo_to_cam",
                "Tr_imu_to_velo"
            ]
        );
        let m = read(&text);
        let velo = rig.sensor("lidar_front").unwrap();
        let tr = &m["Tr_velo_to_cam"];
        for (slot, name) in [
            (0, "front_camera"),
            (1, "front_camera"),
            (2, "front_camera"),
            (3, "front_right"),
        ] {
            let p = &m[&format!("P{slot}")];
            let cam = rig.sensor(name).unwrap();
            let x = DVec3::new(12.0, -1.5, 0.7); // a point in the LiDAR frame
            let in_cam0 = DVec3::new(
                tr[0] * x.x + tr[1] * x.y + tr[2] * x.z + tr[3],
                tr[4] * x.x + tr[5] * x.y + tr[6] * x.z + tr[7],
                tr[8] * x.x + tr[9] * x.y + tr[10] * x.z + tr[11],
            );
            let h = |r: usize| {
                p[r * 4] * in_cam0.x
                    + p[r * 4 + 1] * in_cam0.y
                    + p[r * 4 + 2] * in_cam0.z
                    + p[r * 4 + 3]
            };
            let pixel = glam::DVec2::new(h(0) / h(2), h(1) / h(2));
            let in_cam = cam.vehicle_from_sensor.inverse() * velo.vehicle_from_sensor;
            let expected = cam
                .camera
                .as_ref()
                .unwrap()
                .project(in_cam.transform_point(x))
                .unwrap();
            assert!(
                (pixel - expected).length() < 1e-6,
                "{name}: {pixel} vs {expected}"
            );
        }
        let imu = &m["Tr_imu_to_velo"];
        let expected = rows_3x4(velo.vehicle_from_sensor.inverse());
        assert!(imu.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-12));
    }

    #[test]
    fn a_fourth_camera_is_refused_by_name() {
        let mut rig = test_rig::rig();
        for c in rig.sensors.iter_mut() {
            if let Some(cam) = c.camera.as_mut() {
                cam.distortion.clear();
            }
        }
        let e = export(&rig, None, None).unwrap_err();
        assert!(
            e.to_string().contains("at most three cameras")
                && e.to_string().contains("back_camera"),
            "{e}"
        );
        let slots = slots(&rig, Some("left_camera"));
        assert!(slots.is_err());
    }

    #[test]
    fn a_fisheye_is_refused_even_without_coefficients() {
        use crate::geometry::camera::CameraModel;
        let mut rig = test_rig::rig();
        let names: Vec<String> = rig.cameras().skip(1).map(|c| c.name.clone()).collect();
        rig.sensors.retain(|s| !names.contains(&s.name));
        let with_model = |model| {
            let mut rig = rig.clone();
            let cam = rig
                .sensors
                .iter_mut()
                .find_map(|s| s.camera.as_mut())
                .unwrap();
            cam.model = model;
            cam.distortion = vec![0.0; 4];
            export(&rig, None, None)
        };
        let e = with_model(CameraModel::Equidistant).unwrap_err();
        assert!(e.to_string().contains("equidistant"), "{e}");
        assert!(with_model(CameraModel::PlumbBob).is_ok());
    }
}
