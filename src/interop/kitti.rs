//! KITTI object calib (`calib/XXXXXX.txt`): `P0 … Pn`, `R0_rect`, `Tr_velo_to_cam`,
//! `Tr_imu_to_velo`, each a row-major list of numbers.
//!
//! Directions are in the keys: `Tr_velo_to_cam` = `cam0_from_lidar`, `Tr_imu_to_velo` =
//! `lidar_from_vehicle` (the vehicle frame stands in for KITTI's IMU). `P_i = K_i [R | t]` with
//! `[R | t]` = `cami_from_cam0`, so `y = P_i · R0_rect · Tr_velo_to_cam · x` projects a LiDAR
//! point into camera i exactly as in KITTI (`R0_rect = I`). The format has no distortion: a
//! camera with non-zero distortion coefficients is refused by name (its images would have to be
//! rectified first).

use super::numbers::{rows_3x4, spaced};
use super::pick;
use crate::calib::{Rig, Sensor, SensorKind};
use crate::geometry::Rigid;

fn projection(cam: &Sensor, cam0: &Sensor) -> Result<[f64; 12], String> {
    let Some(c) = &cam.camera else {
        return Err(format!("camera '{}' has no intrinsics", cam.name));
    };
    if c.distortion.iter().any(|&v| v != 0.0) {
        return Err(format!(
            "camera '{}' has {} distortion; KITTI calib files have none (rectify its images, or leave it out with --sensors)",
            cam.name,
            c.model.as_str()
        ));
    }
    let rt = rows_3x4(cam.vehicle_from_sensor.inverse() * cam0.vehicle_from_sensor);
    let k = [[c.fx, 0.0, c.cx], [0.0, c.fy, c.cy], [0.0, 0.0, 1.0]];
    let mut p = [0.0; 12];
    for r in 0..3 {
        for col in 0..4 {
            p[r * 4 + col] = (0..3).map(|i| k[r][i] * rt[i * 4 + col]).sum();
        }
    }
    Ok(p)
}

pub fn export(rig: &Rig, camera: Option<&str>, lidar: Option<&str>) -> Result<String, String> {
    let cam0 = pick(rig, SensorKind::Camera, camera)?;
    let velo = pick(rig, SensorKind::Lidar, lidar)?;
    let mut cams = vec![cam0];
    cams.extend(rig.cameras().filter(|c| c.name != cam0.name));
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
        let e = export(&rig, None, None).unwrap_err();
        assert!(e.contains("left_camera") && e.contains("plumb_bob"), "{e}");
        rig.sensors
            .retain(|s| s.camera.as_ref().is_none_or(|c| c.distortion.is_empty()));
        // A second undistorted camera.
        let mut other = rig.sensor("front_camera").unwrap().clone();
        other.name = "front_right".into();
        other.vehicle_from_sensor = other.vehicle_from_sensor
            * Rigid::new(glam::DQuat::from_rotation_y(0.3), DVec3::new(0.5, 0.0, 0.0));
        rig.sensors.push(other);
        let text = export(&rig, Some("front_camera"), Some("lidar_front")).unwrap();
        let m = read(&text);
        let velo = rig.sensor("lidar_front").unwrap();
        let tr = &m["Tr_velo_to_cam"];
        for (i, name) in ["front_camera", "front_right"].iter().enumerate() {
            let p = &m[&format!("P{i}")];
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
}
