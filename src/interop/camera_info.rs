//! ROS `camera_info` YAML (camera_calibration_parsers; ROS 1 and 2), one file per camera.
//!
//! Intrinsics only: the file has no extrinsic. `P = [K | 0]` (images not rectified, as ROS
//! drivers publish), `R = I`. A pinhole camera is written as `plumb_bob` with five zeros, as
//! ROS drivers do. Reading accepts any of the four models rigcal knows.

use std::path::Path;

use serde::Deserialize;

use super::numbers::list;
use super::text::{comment, yaml_str};
use super::{ExportedFile, ImportError, NotExportable};
use crate::calib::{Rig, Sensor};
use crate::geometry::camera::{CameraIntrinsics, CameraModel};

/// `K` row-major.
pub fn k_matrix(c: &CameraIntrinsics) -> [f64; 9] {
    [c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0]
}

/// One camera's file text.
pub fn text(camera: &Sensor, c: &CameraIntrinsics) -> String {
    let (model, d) = c.ros_distortion();
    let p = [
        c.fx, 0.0, c.cx, 0.0, 0.0, c.fy, c.cy, 0.0, 0.0, 0.0, 1.0, 0.0,
    ];
    format!(
        "# ROS camera_info for camera '{name}' (images stamped in frame '{frame}', the OpenCV optical\n\
         # frame: x right, y down, z forward). Intrinsics only; written by rigcal {version}.\n\
         # camera_matrix K = [fx 0 cx; 0 fy cy; 0 0 1]; projection_matrix P = [K | 0] (unrectified).\n\
         image_width: {w}\nimage_height: {h}\ncamera_name: {yaml_name}\n\
         camera_matrix:\n  rows: 3\n  cols: 3\n  data: {k}\n\
         distortion_model: {model}\n\
         distortion_coefficients:\n  rows: 1\n  cols: {nd}\n  data: {d}\n\
         rectification_matrix:\n  rows: 3\n  cols: 3\n  data: {r}\n\
         projection_matrix:\n  rows: 3\n  cols: 4\n  data: {p}\n",
        name = comment(&camera.name),
        yaml_name = yaml_str(&camera.name),
        frame = comment(&camera.frame_id),
        version = env!("CARGO_PKG_VERSION"),
        w = c.width,
        h = c.height,
        k = list(&k_matrix(c)),
        nd = d.len(),
        d = list(&d),
        r = list(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
        p = list(&p),
    )
}

/// `<camera>.yaml` for every camera with intrinsics.
pub fn export(rig: &Rig) -> Result<Vec<ExportedFile>, NotExportable> {
    let files: Vec<ExportedFile> = rig
        .cameras()
        .filter_map(|s| s.camera.as_ref().map(|c| (s, c)))
        .map(|(s, c)| ExportedFile {
            name: format!("{}.yaml", file_stem(&s.name)),
            bytes: text(s, c).into_bytes(),
        })
        .collect();
    if files.is_empty() {
        return Err("the calibration has no camera with intrinsics".into());
    }
    Ok(files)
}

/// A sensor name as a file name (path separators and odd characters become `_`).
pub fn file_stem(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

#[derive(Deserialize)]
struct Matrix {
    #[serde(default)]
    data: Vec<f64>,
}

#[derive(Deserialize)]
struct CameraInfoYaml {
    image_width: u32,
    image_height: u32,
    #[serde(default)]
    camera_name: Option<String>,
    camera_matrix: Matrix,
    #[serde(default)]
    distortion_model: Option<String>,
    #[serde(default)]
    distortion_coefficients: Option<Matrix>,
}

/// A parsed file: the camera it names (if any) and its intrinsics.
pub fn parse(text: &str, path: &Path) -> Result<(Option<String>, CameraIntrinsics), ImportError> {
    let file = path.display();
    let y: CameraInfoYaml = crate::calib::yaml::from_str(text)
        .map_err(|e| format!("{file}: not a ROS camera_info YAML: {e}"))?;
    let k = &y.camera_matrix.data;
    if k.len() != 9 || k.iter().any(|v| !v.is_finite()) {
        return Err(format!(
            "{file}: camera_matrix.data needs 9 finite numbers, has {}",
            k.len()
        )
        .into());
    }
    let model_name = y.distortion_model.unwrap_or_default();
    let model = CameraModel::parse(&model_name)
        .ok_or_else(|| format!("{file}: unknown distortion_model '{model_name}'"))?;
    let distortion = y
        .distortion_coefficients
        .map(|m| m.data)
        .unwrap_or_default();
    if distortion.iter().any(|v| !v.is_finite()) {
        return Err(format!("{file}: distortion_coefficients must be finite").into());
    }
    let (fx, fy) = (k[0], k[4]);
    if !(fx > 0.0 && fy > 0.0) || y.image_width == 0 || y.image_height == 0 {
        return Err(
            format!("{file}: fx, fy, image_width and image_height must be positive").into(),
        );
    }
    // A pinhole written as plumb_bob with zeros reads back as pinhole.
    let (model, distortion) = model
        .normalized(distortion)
        .map_err(|e| format!("{file}: {e}"))?;
    let intrinsics = CameraIntrinsics {
        width: y.image_width,
        height: y.image_height,
        model,
        fx,
        fy,
        cx: k[2],
        cy: k[5],
        distortion,
    };
    intrinsics.validate().map_err(|e| format!("{file}: {e}"))?;
    Ok((y.camera_name.filter(|n| !n.is_empty()), intrinsics))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_model_round_trips() {
        let rig = super::super::test_rig::rig();
        let files = export(&rig).unwrap();
        assert_eq!(files.len(), 4);
        for (f, cam) in files.iter().zip(rig.cameras()) {
            let text = String::from_utf8(f.bytes.clone()).unwrap();
            let (name, c) = parse(&text, Path::new(&f.name)).unwrap();
            assert_eq!(name.as_deref(), Some(cam.name.as_str()));
            let mut expected = cam.camera.clone().unwrap();
            let n = expected.model.ros_distortion_len();
            if expected.model != CameraModel::Pinhole {
                expected.distortion.resize(n, 0.0);
            }
            assert_eq!(c, expected, "{text}");
        }
    }

    #[test]
    fn bad_files_are_named() {
        let p = Path::new("cam.yaml");
        let e = parse(
            "image_width: 10\nimage_height: 10\ncamera_matrix: {data: [1, 2]}",
            p,
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("cam.yaml") && e.to_string().contains("9"),
            "{e}"
        );
        let e = parse("image_width: 10\nimage_height: 10\ncamera_matrix: {data: [1,0,1,0,1,1,0,0,1]}\ndistortion_model: weird", p).unwrap_err();
        assert!(e.to_string().contains("weird"), "{e}");
        // No model named but coefficients given: refused, naming the file.
        let e = parse("image_width: 10\nimage_height: 10\ncamera_matrix: {data: [1,0,1,0,1,1,0,0,1]}\ndistortion_coefficients: {data: [-0.2, 0.1, 0, 0, 0]}", p).unwrap_err();
        assert!(
            e.to_string().contains("cam.yaml") && e.to_string().contains("takes no coefficients"),
            "{e}"
        );
        assert!(parse("[", p).unwrap_err().to_string().contains("cam.yaml"));
    }
}
