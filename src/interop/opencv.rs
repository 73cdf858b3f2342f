//! OpenCV FileStorage YAML in the Autoware.AI layout, one file per camera.
//!
//! `CameraExtrinsicMat` is the camera's pose in the reference LiDAR's frame,
//! `lidar_from_camera` (p_lidar = M · p_camera, camera = OpenCV optical frame); a rig without a
//! LiDAR gets `vehicle_from_camera` and says so. `CameraMat`, `DistCoeff` (in the ROS model's
//! order), `ImageSize`, `ReprojectionError` and `DistModel` follow. Two extra matrices name
//! their direction in their keys: `VehicleFromCamera` and `VehicleFromLidar`.

use super::camera_info::{file_stem, k_matrix};
use super::numbers::{list, rows_4x4};
use super::text::comment;
use super::{ExportedFile, NotExportable, pick};
use crate::calib::{Rig, SensorKind};
use crate::geometry::Rigid;

fn matrix(name: &str, rows: usize, cols: usize, data: &[f64]) -> String {
    format!(
        "{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: {}\n",
        list(data)
    )
}

pub fn export(rig: &Rig, lidar: Option<&str>) -> Result<Vec<ExportedFile>, NotExportable> {
    let reference = match lidar {
        Some(_) => Some(pick(rig, SensorKind::Lidar, lidar)?),
        None => rig.lidars().next(),
    };
    let (ref_name, vehicle_from_ref) = match reference {
        Some(l) => (l.name.clone(), l.vehicle_from_sensor),
        None => (rig.vehicle_frame.clone(), Rigid::IDENTITY),
    };
    let mut files = Vec::new();
    for cam in rig.cameras() {
        let Some(c) = &cam.camera else { continue };
        let ref_from_camera = vehicle_from_ref.inverse() * cam.vehicle_from_sensor;
        let (model, d) = c.ros_distortion();
        let mut text = format!(
            "%YAML:1.0\n---\n\
             # Camera '{cam}' written by rigcal {version} (OpenCV FileStorage, Autoware.AI layout).\n\
             # CameraExtrinsicMat is {reference}_from_camera: the camera's pose in the frame of '{reference}',\n\
             # p_{reference} = M p_camera (4x4 row-major, metres; camera frame = OpenCV optical frame:\n\
             # x right, y down, z forward). Its inverse maps {reference} points into the camera.\n",
            cam = comment(&cam.name),
            version = env!("CARGO_PKG_VERSION"),
            reference = comment(&ref_name),
        );
        text.push_str(&matrix(
            "CameraExtrinsicMat",
            4,
            4,
            &rows_4x4(ref_from_camera),
        ));
        text.push_str(&matrix("CameraMat", 3, 3, &k_matrix(c)));
        text.push_str(&matrix("DistCoeff", 1, d.len(), &d));
        text.push_str(&format!(
            "ImageSize: [ {}, {} ]\nReprojectionError: 0.\nDistModel: {model}\n",
            c.width, c.height
        ));
        text.push_str("# VehicleFromCamera: p_vehicle = M p_camera.\n");
        text.push_str(&matrix(
            "VehicleFromCamera",
            4,
            4,
            &rows_4x4(cam.vehicle_from_sensor),
        ));
        if reference.is_some() {
            text.push_str(&format!(
                "# VehicleFromLidar ('{}'): p_vehicle = M p_lidar.\n",
                comment(&ref_name)
            ));
            text.push_str(&matrix(
                "VehicleFromLidar",
                4,
                4,
                &rows_4x4(vehicle_from_ref),
            ));
        }
        files.push(ExportedFile {
            name: format!("{}.yaml", file_stem(&cam.name)),
            bytes: text.into_bytes(),
        });
    }
    if files.is_empty() {
        return Err("the calibration has no camera with intrinsics".into());
    }
    Ok(files)
}

/// `(key, rows, cols, data)` of every `!!opencv-matrix` in a file this module wrote.
#[cfg(test)]
pub(crate) fn read_matrices(text: &str) -> Vec<(String, usize, usize, Vec<f64>)> {
    let body = text.split_once("---\n").map_or(text, |(_, b)| b);
    let y: serde_yaml::Value = serde_yaml::from_str(&body.replace("!!opencv-matrix", "")).unwrap();
    let mut out = Vec::new();
    if let serde_yaml::Value::Mapping(m) = y {
        for (k, v) in m {
            if let (Some(k), Some(rows)) = (k.as_str(), v.get("rows").and_then(|r| r.as_u64())) {
                let data = v["data"]
                    .as_sequence()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect();
                out.push((
                    k.to_string(),
                    rows as usize,
                    v["cols"].as_u64().unwrap() as usize,
                    data,
                ));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::test_rig;
    use super::*;

    #[test]
    fn extrinsic_is_lidar_from_camera() {
        let rig = test_rig::rig();
        let files = export(&rig, Some("lidar_front")).unwrap();
        assert_eq!(files.len(), 4);
        let lidar = rig.sensor("lidar_front").unwrap().vehicle_from_sensor;
        for (f, cam) in files.iter().zip(rig.cameras()) {
            let text = String::from_utf8(f.bytes.clone()).unwrap();
            assert!(text.starts_with("%YAML:1.0\n---\n"));
            let m = read_matrices(&text);
            let (_, r, c, data) = m.iter().find(|m| m.0 == "CameraExtrinsicMat").unwrap();
            assert_eq!((*r, *c), (4, 4));
            let rows: Vec<[f64; 4]> = data.chunks(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
            let got = Rigid::from_rows([rows[0], rows[1], rows[2], rows[3]]);
            let expected = lidar.inverse() * cam.vehicle_from_sensor;
            let (dr, dt) = got.difference(expected);
            assert!(dr < 1e-9 && dt < 1e-12);
            let (_, _, nd, _) = m.iter().find(|m| m.0 == "DistCoeff").unwrap();
            assert_eq!(*nd, cam.camera.as_ref().unwrap().model.ros_distortion_len());
        }
        assert!(
            export(&rig, Some("front_camera"))
                .unwrap_err()
                .to_string()
                .contains("not a lidar")
        );
    }
}
