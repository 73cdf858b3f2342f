//! An initial guess from another tool's file, applied onto a base rig (the log's sensors).
//!
//! The format is told by the file: a directory (of camera_info YAMLs), `.mcap` (its
//! `/tf_static` and CameraInfo), `.urdf`/`.xml` (joints composed from the vehicle link), or
//! YAML — the native file if it has `rigcal_calibration`, ROS camera_info if it has
//! `camera_matrix`. Sensors are matched by frame id (URDF, MCAP) or by name (native; camera_info
//! by `camera_name` or the file's stem). Sensors the file does not mention keep the base's
//! values; the result says which were matched, and a file that matches none is an error.

use std::path::{Path, PathBuf};

use thiserror::Error;

use super::{camera_info, mcap_tf, urdf};
use crate::calib::{CalibrationFile, Rig, SensorKind};

#[derive(Debug, Error)]
pub enum ImportError {
    #[error("{path}: cannot read: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Log(#[from] crate::log::LogError),
    #[error("{0}")]
    Invalid(String),
    #[error("{path}: matches none of the rig's sensors ({sensors}); {hint}")]
    NoMatch {
        path: PathBuf,
        sensors: String,
        hint: String,
    },
}

impl From<String> for ImportError {
    fn from(what: String) -> Self {
        Self::Invalid(what)
    }
}

/// What [`load_initial_guess`] found.
#[derive(Clone, Debug)]
pub struct Imported {
    /// The base rig with what the file gives applied.
    pub rig: Rig,
    /// Names of the base's sensors the file gave values for.
    pub matched: Vec<String>,
    /// The format read, for messages ("URDF", "MCAP /tf_static", …).
    pub format: &'static str,
}

fn read(path: &Path) -> Result<String, ImportError> {
    std::fs::read_to_string(path).map_err(|source| ImportError::Read {
        path: path.to_path_buf(),
        source,
    })
}

/// Read `path` in whichever supported format it is and apply it onto `base`.
pub fn load_initial_guess(path: &Path, base: &Rig) -> Result<Imported, ImportError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let (rig, matched, format) = if path.is_dir() {
        let (r, m) = camera_info_dir(path, base)?;
        (r, m, "camera_info YAML directory")
    } else if ext == "mcap" {
        let (r, m) = mcap_tf::import(path, base)?;
        (r, m, "MCAP /tf_static")
    } else if ext == "urdf" || ext == "xml" {
        let (r, m) = from_urdf(&read(path)?, path, base)?;
        (r, m, "URDF")
    } else {
        let text = read(path)?;
        let value: serde_yaml::Value = crate::calib::yaml::from_str(&text).map_err(|e| {
            ImportError::Invalid(format!(
                "{}: neither MCAP, URDF nor YAML ({e})",
                path.display()
            ))
        })?;
        if value.get("rigcal_calibration").is_some() {
            let (r, m) = from_native(&text, path, base)?;
            (r, m, "rigcal native")
        } else if value.get("camera_matrix").is_some() {
            let (r, m) = from_camera_info(&[(path.to_path_buf(), text)], base)?;
            (r, m, "ROS camera_info YAML")
        } else {
            return Err(ImportError::Invalid(format!(
                "{}: not a calibration rigcal reads (expected a rigcal calibration file, a ROS camera_info YAML, a URDF or an MCAP with /tf_static)",
                path.display()
            )));
        }
    };
    if matched.is_empty() {
        let sensors: Vec<String> = base
            .sensors
            .iter()
            .map(|s| format!("{} [{}]", s.name, s.frame_id))
            .collect();
        return Err(ImportError::NoMatch {
            path: path.to_path_buf(),
            sensors: sensors.join(", "),
            hint: match format {
                "URDF" | "MCAP /tf_static" => format!(
                    "sensors are matched by frame id below the vehicle frame '{}'",
                    base.vehicle_frame
                ),
                "rigcal native" => "sensors are matched by name or frame id".into(),
                _ => "sensors are matched by name".into(),
            },
        });
    }
    Ok(Imported {
        rig,
        matched,
        format,
    })
}

fn from_native(text: &str, path: &Path, base: &Rig) -> Result<(Rig, Vec<String>), ImportError> {
    let other = CalibrationFile::parse(text, path)
        .and_then(|f| f.to_rig(path))
        .map_err(|e| ImportError::Invalid(e.to_string()))?;
    // Extrinsics are relative to the vehicle frame: another frame's numbers would be wrong here.
    let frame = |f: &str| f.trim_start_matches('/').to_string();
    if frame(&other.vehicle_frame) != frame(&base.vehicle_frame) {
        return Err(ImportError::Invalid(format!(
            "{}: its extrinsics are in the vehicle frame '{}', the rig's are in '{}' (convert it, or set vehicle_frame if they are the same frame)",
            path.display(),
            other.vehicle_frame,
            base.vehicle_frame
        )));
    }
    let mut rig = base.clone();
    let mut matched = Vec::new();
    for s in &other.sensors {
        // By name, else by frame id (a file whose sensors were renamed), never twice.
        let target = match rig.sensor(&s.name) {
            Some(t) => Some(t.name.clone()),
            None => rig
                .sensors
                .iter()
                .find(|t| !t.frame_id.is_empty() && frame(&t.frame_id) == frame(&s.frame_id))
                .map(|t| t.name.clone()),
        }
        .filter(|name| !matched.contains(name));
        if let Some(t) = target.as_deref().and_then(|name| rig.sensor_mut(name)) {
            t.vehicle_from_sensor = s.vehicle_from_sensor;
            if s.camera.is_some() {
                t.camera = s.camera.clone();
            }
            matched.push(t.name.clone());
        }
    }
    Ok((rig, matched))
}

fn from_urdf(text: &str, path: &Path, base: &Rig) -> Result<(Rig, Vec<String>), ImportError> {
    let edges = urdf::parse_joints(text, path)?;
    let has_vehicle = edges
        .values()
        .any(|(parent, _)| *parent == base.vehicle_frame);
    if !has_vehicle {
        return Err(ImportError::Invalid(format!(
            "{}: no joint has the vehicle frame '{}' as its parent",
            path.display(),
            base.vehicle_frame
        )));
    }
    let mut rig = base.clone();
    let mut matched = Vec::new();
    for s in &mut rig.sensors {
        let found = urdf::resolve(&edges, &base.vehicle_frame, &s.frame_id)
            .or_else(|| urdf::resolve(&edges, &base.vehicle_frame, &s.name));
        if let Some(t) = found {
            s.vehicle_from_sensor = t;
            matched.push(s.name.clone());
        }
    }
    Ok((rig, matched))
}

fn from_camera_info(
    files: &[(PathBuf, String)],
    base: &Rig,
) -> Result<(Rig, Vec<String>), ImportError> {
    let mut rig = base.clone();
    let mut matched = Vec::new();
    for (path, text) in files {
        let (name, intrinsics) = camera_info::parse(text, path)?;
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .map(str::to_string);
        let target = rig.sensors.iter_mut().find(|s| {
            s.kind == SensorKind::Camera
                && [name.as_deref(), stem.as_deref()]
                    .into_iter()
                    .flatten()
                    .any(|n| n == s.name || n == s.frame_id)
        });
        if let Some(s) = target {
            s.camera = Some(intrinsics);
            matched.push(s.name.clone());
        }
    }
    Ok((rig, matched))
}

fn camera_info_dir(dir: &Path, base: &Rig) -> Result<(Rig, Vec<String>), ImportError> {
    let io = |source| ImportError::Read {
        path: dir.to_path_buf(),
        source,
    };
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(io)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("yaml") || e.eq_ignore_ascii_case("yml"))
        })
        .collect();
    paths.sort();
    let files = paths
        .into_iter()
        .map(|p| read(&p).map(|t| (p, t)))
        .collect::<Result<Vec<_>, _>>()?;
    from_camera_info(&files, base)
}

#[cfg(test)]
mod tests {
    use super::super::{ExportFormat, ExportOptions, export, test_rig, write};
    use super::*;
    use crate::geometry::Rigid;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("rigcal-import-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// The test rig with every extrinsic and intrinsic spoiled.
    fn spoiled() -> Rig {
        let mut r = test_rig::rig();
        for s in &mut r.sensors {
            s.vehicle_from_sensor = s.vehicle_from_sensor
                * Rigid::new(
                    glam::DQuat::from_rotation_z(0.2),
                    glam::DVec3::new(0.3, 0.0, 0.0),
                );
            if let Some(c) = &mut s.camera {
                c.fx += 50.0;
                c.distortion.clear();
            }
        }
        r
    }

    #[test]
    fn a_native_file_with_renamed_sensors_matches_by_frame_id() {
        let rig = test_rig::rig();
        let mut renamed = rig.clone();
        for s in &mut renamed.sensors {
            s.name = format!("my_{}", s.name);
        }
        let dir = scratch("renamed");
        let path = dir.join("renamed.yaml");
        CalibrationFile::from_rig(&renamed).save(&path).unwrap();
        let got = load_initial_guess(&path, &spoiled()).unwrap();
        assert_eq!(got.matched.len(), rig.sensors.len(), "{:?}", got.matched);
        let (r, t) = test_rig::max_difference(&rig, &got.rig);
        assert!(r < 1e-12 && t < 1e-12, "{r} {t}");
        // The names stay the rig's.
        assert!(got.rig.sensor(&rig.sensors[0].name).is_some());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn every_imported_format_round_trips() {
        let rig = test_rig::rig();
        let doc = CalibrationFile::from_rig(&rig);
        let dir = scratch("round-trip");
        for format in [
            ExportFormat::Native,
            ExportFormat::Urdf,
            ExportFormat::Mcap,
            ExportFormat::CameraInfo,
        ] {
            let out = dir.join(format.default_file_name());
            write(
                &export(&doc, format, &ExportOptions::default()).unwrap(),
                &out,
            )
            .unwrap();
            let got = load_initial_guess(&out, &spoiled()).unwrap();
            let extrinsics = format != ExportFormat::CameraInfo;
            let intrinsics = format != ExportFormat::Urdf;
            let expected_matches = if extrinsics { 6 } else { 4 };
            assert_eq!(got.matched.len(), expected_matches, "{}", format.name());
            let (r, t) = test_rig::max_difference(&rig, &got.rig);
            if extrinsics {
                assert!(r < 1e-12 && t < 1e-12, "{}: {r} {t}", format.name());
            }
            for (a, b) in rig.cameras().zip(got.rig.cameras()) {
                let (ca, cb) = (a.camera.as_ref().unwrap(), b.camera.as_ref().unwrap());
                if intrinsics {
                    assert_eq!((ca.fx, ca.model), (cb.fx, cb.model), "{}", format.name());
                    let n = ca.distortion.len();
                    assert_eq!(ca.distortion[..], cb.distortion[..n], "{}", format.name());
                } else {
                    assert_eq!(ca.fx + 50.0, cb.fx);
                }
            }
            // A single camera_info file imports too.
            if format == ExportFormat::CameraInfo {
                let one = out.join("left_camera.yaml");
                let got = load_initial_guess(&one, &spoiled()).unwrap();
                assert_eq!(got.matched, vec!["left_camera".to_string()]);
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_sensor_that_is_the_vehicle_frame_gets_no_transform_to_itself() {
        // PandaSet's layout: the vehicle frame is the main LiDAR's.
        let mut rig = test_rig::rig();
        rig.vehicle_frame = "lidar_top".into();
        let lidar_top = rig
            .sensor("lidar_top")
            .unwrap()
            .vehicle_from_sensor
            .inverse();
        for s in &mut rig.sensors {
            s.vehicle_from_sensor = lidar_top * s.vehicle_from_sensor;
        }
        let doc = CalibrationFile::from_rig(&rig);
        let dir = scratch("self-frame");
        for format in [ExportFormat::Urdf, ExportFormat::Mcap] {
            let out = dir.join(format.default_file_name());
            write(
                &export(&doc, format, &ExportOptions::default()).unwrap(),
                &out,
            )
            .unwrap();
            let got = load_initial_guess(&out, &spoiled_with_frame(&rig)).unwrap();
            assert_eq!(got.matched.len(), rig.sensors.len(), "{}", format.name());
            let (r, t) = test_rig::max_difference(&rig, &got.rig);
            assert!(r < 1e-12 && t < 1e-12, "{}: {r} {t}", format.name());
        }
        let urdf = String::from_utf8(
            export(&doc, ExportFormat::Urdf, &ExportOptions::default())
                .unwrap()
                .files[0]
                .bytes
                .clone(),
        )
        .unwrap();
        assert!(!urdf.contains("<child link=\"lidar_top\"/>"), "{urdf}");
        let sh = super::super::ros_tf::script(&rig);
        assert!(!sh.contains("--child-frame-id lidar_top\n") && sh.contains("identity"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    fn spoiled_with_frame(rig: &Rig) -> Rig {
        let mut s = spoiled();
        s.vehicle_frame = rig.vehicle_frame.clone();
        s
    }

    #[test]
    fn urdf_with_extra_links_between_resolves() {
        let text = r#"<robot name="r">
  <link name="base_link"/><link name="sensor_kit"/><link name="lidar_top"/>
  <joint name="kit" type="fixed"><parent link="base_link"/><child link="sensor_kit"/>
    <origin xyz="1 0 2" rpy="0 0 1.5707963267948966"/></joint>
  <joint name="lidar" type="fixed"><parent link="sensor_kit"/><child link="lidar_top"/>
    <origin xyz="0.5 0 0"/></joint>
</robot>"#;
        let dir = scratch("urdf");
        let p = dir.join("robot.urdf");
        std::fs::write(&p, text).unwrap();
        let got = load_initial_guess(&p, &test_rig::rig()).unwrap();
        assert_eq!(got.matched, vec!["lidar_top".to_string()]);
        let t = got.rig.sensor("lidar_top").unwrap().vehicle_from_sensor;
        assert!((t.translation - glam::DVec3::new(1.0, 0.5, 2.0)).length() < 1e-12);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_and_unmatched_files_are_named() {
        let dir = scratch("bad");
        let base = test_rig::rig();
        let cases = [
            ("a.yaml", "foo: 1\n", "not a calibration rigcal reads"),
            ("b.yaml", "[", "neither MCAP"),
            (
                "c.urdf",
                "<robot><joint name=\"j\"><parent link=\"x\"/><child link=\"lidar_top\"/></joint></robot>",
                "vehicle frame 'base_link'",
            ),
            (
                "d.urdf",
                "<robot><joint name=\"j\"><parent link=\"base_link\"/><child link=\"other\"/></joint></robot>",
                "matches none",
            ),
            ("e.mcap", "not an mcap", "e.mcap"),
            (
                "f.yaml",
                "rigcal_calibration: 1\nvehicle_frame: base_link\nsensors:\n  - name: nobody\n    kind: lidar\n    vehicle_from_sensor: {translation_m: [0, 0, 0], rotation_xyzw: [0, 0, 0, 1]}\n",
                "matches none",
            ),
            (
                "g.yaml",
                "rigcal_calibration: 1\nvehicle_frame: ego\nsensors:\n  - name: lidar_top\n    kind: lidar\n    vehicle_from_sensor: {translation_m: [0, 0, 0], rotation_xyzw: [0, 0, 0, 1]}\n",
                "vehicle frame 'ego', the rig's are in 'base_link'",
            ),
        ];
        for (name, text, expected) in cases {
            let p = dir.join(name);
            std::fs::write(&p, text).unwrap();
            let e = load_initial_guess(&p, &base).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains(expected), "{name}: {e}");
        }
        let e = load_initial_guess(&dir.join("missing.yaml"), &base)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("missing.yaml") && e.contains("cannot read"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
