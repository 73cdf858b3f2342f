//! Kalibr camchain YAML.
//!
//! `cam0` is the reference camera; each `camN` (N ≥ 1) carries `T_cn_cnm1`, the transform from
//! the previous camera's optical frame into its own (`p_cn = T_cn_cnm1 · p_cn-1`), as Kalibr
//! writes it. Models: `pinhole` with `radtan` (plumb_bob without k3), `equidistant` or `none`;
//! rational_polynomial cameras, and plumb_bob ones with a non-zero k3, have no Kalibr model and
//! are refused by name. `cam_overlaps` lists the cameras whose fields of view intersect.

use super::numbers::{list, num};
use super::text::{comment, yaml_str};
use super::{NotExportable, pick};
use crate::calib::{Rig, Sensor, SensorKind};
use crate::geometry::Rigid;
use crate::geometry::camera::{CameraIntrinsics, CameraModel};

fn distortion(s: &Sensor, c: &CameraIntrinsics) -> Result<(&'static str, Vec<f64>), NotExportable> {
    let coeff = |i: usize| c.distortion.get(i).copied().unwrap_or(0.0);
    match c.model {
        CameraModel::Pinhole => Ok(("none", Vec::new())),
        CameraModel::PlumbBob if coeff(4) == 0.0 => {
            Ok(("radtan", vec![coeff(0), coeff(1), coeff(2), coeff(3)]))
        }
        CameraModel::PlumbBob => Err(format!(
            "camera '{}' has k3 = {} (plumb_bob with five coefficients); Kalibr's radtan has four",
            s.name,
            coeff(4)
        ).into()),
        CameraModel::Equidistant => {
            Ok(("equidistant", vec![coeff(0), coeff(1), coeff(2), coeff(3)]))
        }
        CameraModel::RationalPolynomial => Err(format!(
            "camera '{}' uses rational_polynomial, which Kalibr has no model for (export the other cameras with --sensors)",
            s.name
        ).into()),
    }
}

/// Half the diagonal field of view (rad) of a pinhole approximation.
fn half_fov(c: &CameraIntrinsics) -> f64 {
    let w = (c.width as f64 / 2.0) / c.fx;
    let h = (c.height as f64 / 2.0) / c.fy;
    (w * w + h * h).sqrt().atan().min(1.5)
}

fn overlaps(a: &Sensor, b: &Sensor) -> bool {
    let (Some(ca), Some(cb)) = (&a.camera, &b.camera) else {
        return false;
    };
    let axis = |s: &Sensor| s.vehicle_from_sensor.transform_vector(glam::DVec3::Z);
    axis(a).angle_between(axis(b)) < half_fov(ca) + half_fov(cb)
}

fn matrix(t: Rigid) -> String {
    t.to_rows()
        .iter()
        .map(|r| format!("  - {}\n", list(r)))
        .collect()
}

pub fn export(rig: &Rig, reference: Option<&str>) -> Result<String, NotExportable> {
    let first = pick(rig, SensorKind::Camera, reference)?;
    let mut cams: Vec<&Sensor> = vec![first];
    cams.extend(rig.cameras().filter(|c| c.name != first.name));
    let cams: Vec<&Sensor> = cams.into_iter().filter(|c| c.camera.is_some()).collect();
    let v0 = first.vehicle_from_sensor;
    let [x, y, z] = v0.translation.to_array();
    let q = v0.rotation;
    let mut out = format!(
        "# Kalibr camchain, written by rigcal {}. Camera frames are optical (x right, y down, z forward).\n\
         # T_cn_cnm1 maps points from the previous camera's frame into this camera's: p_cn = T_cn_cnm1 p_cnm1\n\
         # (4x4, row-major, metres). cam0 is '{}'; its pose in the vehicle frame '{}',\n\
         # vehicle_from_cam0: translation [{}, {}, {}], rotation xyzw [{}, {}, {}, {}].\n",
        env!("CARGO_PKG_VERSION"),
        comment(&first.name),
        comment(&rig.vehicle_frame),
        num(x),
        num(y),
        num(z),
        num(q.x),
        num(q.y),
        num(q.z),
        num(q.w)
    );
    for (i, s) in cams.iter().enumerate() {
        let Some(c) = &s.camera else { continue };
        let (model, coeffs) = distortion(s, c)?;
        let overlap: Vec<String> = cams
            .iter()
            .enumerate()
            .filter(|(j, o)| *j != i && overlaps(s, o))
            .map(|(j, _)| j.to_string())
            .collect();
        out.push_str(&format!("cam{i}:\n"));
        if i > 0 {
            let t = s.vehicle_from_sensor.inverse() * cams[i - 1].vehicle_from_sensor;
            out.push_str(&format!(
                "  # {}_from_{}\n  T_cn_cnm1:\n{}",
                comment(&s.name),
                comment(&cams[i - 1].name),
                matrix(t)
            ));
        }
        out.push_str(&format!(
            "  camera_model: pinhole\n  intrinsics: {}\n  distortion_model: {model}\n  distortion_coeffs: {}\n  resolution: [{}, {}]\n  rostopic: {}\n  cam_overlaps: [{}]\n",
            list(&[c.fx, c.fy, c.cx, c.cy]),
            list(&coeffs),
            c.width,
            c.height,
            yaml_str(
                &s.topics
                    .first()
                    .cloned()
                    .unwrap_or_else(|| format!("/{}/image_raw", s.name))
            ),
            overlap.join(", ")
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::super::test_rig;
    use super::*;

    #[test]
    fn chain_composes_back_to_the_rig() {
        let rig = test_rig::rig();
        let e = export(&rig, None).unwrap_err();
        assert!(
            e.to_string().contains("right_camera") && e.to_string().contains("rational_polynomial"),
            "{e}"
        );
        let mut rig = rig;
        rig.sensors.retain(|s| s.name != "right_camera");
        let text = export(&rig, Some("left_camera")).unwrap();
        let y: serde_yaml::Value = serde_yaml::from_str(&text).unwrap();
        let cams: Vec<&Sensor> = rig.cameras().collect();
        // cam0 is the reference; walking the chain gives every camera relative to it.
        let order = ["left_camera", "front_camera", "back_camera"];
        let mut cn_from_c0 = Rigid::IDENTITY;
        let v0 = rig.sensor("left_camera").unwrap().vehicle_from_sensor;
        for (i, name) in order.iter().enumerate() {
            let cam = &y[format!("cam{i}").as_str()];
            if i > 0 {
                let rows: Vec<[f64; 4]> = cam["T_cn_cnm1"]
                    .as_sequence()
                    .unwrap()
                    .iter()
                    .map(|r| {
                        let v: Vec<f64> = r
                            .as_sequence()
                            .unwrap()
                            .iter()
                            .map(|x| x.as_f64().unwrap())
                            .collect();
                        [v[0], v[1], v[2], v[3]]
                    })
                    .collect();
                cn_from_c0 = Rigid::from_rows([rows[0], rows[1], rows[2], rows[3]]) * cn_from_c0;
            }
            let s = rig.sensor(name).unwrap();
            let expected = s.vehicle_from_sensor.inverse() * v0;
            let (r, d) = cn_from_c0.difference(expected);
            assert!(r < 1e-9 && d < 1e-9, "{name}");
        }
        assert_eq!(y["cam0"]["distortion_model"].as_str(), Some("radtan"));
        assert_eq!(y["cam1"]["distortion_model"].as_str(), Some("none"));
        assert_eq!(y["cam2"]["distortion_model"].as_str(), Some("equidistant"));
        assert_eq!(cams.len(), 3);
    }
}
