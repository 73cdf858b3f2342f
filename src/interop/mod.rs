//! Export to, and import from, the formats calibration consumers use (docs/users.md §4).
//!
//! How it works: [`export`] turns a native calibration document into the files of one
//! [`ExportFormat`] in memory (text, or an MCAP written to memory), each file
//! naming the direction of every transform it holds in a key or a comment (`p_parent =
//! parent_from_child · p_child`). [`write`](fn@write) puts them on disk atomically: one file, or one file
//! per camera in a directory for the per-camera formats. [`import::load_initial_guess`] reads
//! the native file, URDF, ROS camera_info YAML or the `/tf_static` of any MCAP *onto* a base
//! rig (the log's sensors), matching sensors by frame id or name, so another tool's file becomes
//! the initial guess of a calibration.
//!
//! Cameras are OpenCV optical frames throughout rigcal; formats that expect a camera's body
//! frame (URDF's `camera_link`, Autoware) get it through REP-103 ([`frames`]).

pub mod autoware;
pub mod camera_info;
pub mod frames;
pub mod import;
pub mod kalibr;
pub mod kitti;
pub mod mcap_tf;
pub mod numbers;
pub mod nuscenes;
pub mod opencv;
pub mod ros_tf;
pub mod text;
pub mod urdf;

pub use import::ImportError;

use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::calib::{CalibrationFile, Rig, Sensor, SensorKind};
use crate::geometry::Rigid;

/// Why one format cannot hold the rig as asked (a camera model it has no name for, a sensor
/// it has no slot for, two names that collide); [`export`] says it of the format.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
#[error("{0}")]
pub struct NotExportable(String);

impl From<String> for NotExportable {
    fn from(what: String) -> Self {
        Self(what)
    }
}

impl From<&str> for NotExportable {
    fn from(what: &str) -> Self {
        Self(what.to_owned())
    }
}

#[derive(Debug, Error)]
pub enum ExportError {
    #[error("unknown export format '{0}' (expected one of: {list})", list = ExportFormat::names().join(", "))]
    UnknownFormat(String),
    #[error("{format}: {what}")]
    Unsupported { format: &'static str, what: String },
    #[error("{path}: cannot write: {what}")]
    Write { path: PathBuf, what: String },
}

/// The formats `rigcal export --format` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ExportFormat {
    /// The native `rigcal_calibration: 1` YAML.
    Native,
    /// ROS `camera_info` YAML, one file per camera (directory).
    CameraInfo,
    /// `/tf_static` + `CameraInfo` as a ROS 2 MCAP (Foxglove, Rerun, ros2 bag play).
    Mcap,
    /// URDF fixed joints with REP-103 optical frames for cameras.
    Urdf,
    /// ROS 2 `static_transform_publisher` commands (a shell script).
    Ros2StaticTf,
    /// A ROS 2 XML launch file with one static_transform_publisher per sensor.
    Ros2Launch,
    /// Autoware `sensor_kit_calibration.yaml`.
    Autoware,
    /// OpenCV FileStorage YAML (Autoware.AI layout), one file per camera (directory).
    OpenCv,
    /// Kalibr camchain YAML.
    Kalibr,
    /// KITTI object calib (`P0..`, `R0_rect`, `Tr_velo_to_cam`, `Tr_imu_to_velo`).
    Kitti,
    /// nuScenes `calibrated_sensor.json`.
    Nuscenes,
}

impl ExportFormat {
    pub const ALL: [ExportFormat; 11] = [
        Self::Native,
        Self::CameraInfo,
        Self::Mcap,
        Self::Urdf,
        Self::Ros2StaticTf,
        Self::Ros2Launch,
        Self::Autoware,
        Self::OpenCv,
        Self::Kalibr,
        Self::Kitti,
        Self::Nuscenes,
    ];

    /// The `--format` value.
    pub fn name(self) -> &'static str {
        match self {
            Self::Native => "native",
            Self::CameraInfo => "camera-info",
            Self::Mcap => "mcap",
            Self::Urdf => "urdf",
            Self::Ros2StaticTf => "ros2-static-tf",
            Self::Ros2Launch => "ros2-launch",
            Self::Autoware => "autoware",
            Self::OpenCv => "opencv",
            Self::Kalibr => "kalibr",
            Self::Kitti => "kitti",
            Self::Nuscenes => "nuscenes",
        }
    }

    /// What a person picks from a list.
    pub fn label(self) -> &'static str {
        match self {
            Self::Native => "rigcal native (YAML)",
            Self::CameraInfo => "ROS camera_info YAML (one per camera)",
            Self::Mcap => "MCAP: /tf_static + CameraInfo (ROS 2)",
            Self::Urdf => "URDF fixed joints (REP-103 optical frames)",
            Self::Ros2StaticTf => "ROS 2 static_transform_publisher commands",
            Self::Ros2Launch => "ROS 2 launch file (static TF)",
            Self::Autoware => "Autoware sensor_kit_calibration.yaml",
            Self::OpenCv => "OpenCV FileStorage YAML (one per camera)",
            Self::Kalibr => "Kalibr camchain",
            Self::Kitti => "KITTI calib.txt",
            Self::Nuscenes => "nuScenes calibrated_sensor.json",
        }
    }

    /// What the file holds and which way its transforms go, in one or two sentences.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Native => {
                "vehicle_from_sensor for every sensor: p_vehicle = R · p_sensor + t (t = the sensor's origin in the vehicle frame); cameras are OpenCV optical frames (x right, y down, z forward)."
            }
            Self::CameraInfo => {
                "Intrinsics only, one file per camera: K, distortion in the ROS model's order, R = I, P = [K | 0]."
            }
            Self::Mcap => {
                "One /tf_static message: parent = the vehicle frame, child = each sensor's frame, transform = the child's pose in the parent (vehicle_from_sensor); plus a CameraInfo per camera."
            }
            Self::Urdf => {
                "Fixed joints whose origin is parent_from_child (p_parent = R(rpy) p_child + xyz); cameras get a body link (x forward) and an optical link (REP-103, rpy -π/2 0 -π/2)."
            }
            Self::Ros2StaticTf => {
                "One static_transform_publisher per sensor: --frame-id = the vehicle frame (parent), --child-frame-id = the sensor frame; the transform is vehicle_from_sensor, quaternion x y z w."
            }
            Self::Ros2Launch => {
                "The same publishers as a ROS 2 XML launch file: parent = the vehicle frame, child = the sensor frame, transform = vehicle_from_sensor."
            }
            Self::Autoware => {
                "Each sensor's pose under sensor_kit_base_link (= the vehicle frame; parent_from_child) as x y z roll pitch yaw (URDF fixed-axis); LiDARs as <frame>_base_link, cameras by their body frame <camera>/camera_link, as Autoware expects."
            }
            Self::OpenCv => {
                "One file per camera: CameraExtrinsicMat = lidar_from_camera (the camera's pose in the reference LiDAR's frame), CameraMat, DistCoeff, ImageSize."
            }
            Self::Kalibr => {
                "cam0 = the reference camera; T_cn_cnm1 maps points from the previous camera into camera n (p_cn = T p_cn-1); radtan / equidistant / none."
            }
            Self::Kitti => {
                "Tr_velo_to_cam = cam0_from_lidar, Tr_imu_to_velo = lidar_from_vehicle, P_i = K_i [cami_from_cam0], R0_rect = I; undistorted cameras only."
            }
            Self::Nuscenes => {
                "ego_from_sensor per sensor: translation (m) and rotation as w, x, y, z; camera_intrinsic for cameras."
            }
        }
    }

    /// Whether the format holds one LiDAR chosen by [`ExportOptions::lidar`].
    pub fn takes_lidar(self) -> bool {
        matches!(self, Self::OpenCv | Self::Kitti)
    }

    /// Whether the format holds one reference camera chosen by [`ExportOptions::camera`].
    pub fn takes_camera(self) -> bool {
        matches!(self, Self::Kalibr | Self::Kitti)
    }

    /// Default file name, or directory name for the per-camera formats.
    pub fn default_file_name(self) -> &'static str {
        match self {
            Self::Native => "calibration.yaml",
            Self::CameraInfo => "camera_info",
            Self::Mcap => "calibration.mcap",
            Self::Urdf => "rig.urdf",
            Self::Ros2StaticTf => "static_tf.sh",
            Self::Ros2Launch => "static_tf.launch.xml",
            Self::Autoware => "sensor_kit_calibration.yaml",
            Self::OpenCv => "opencv",
            Self::Kalibr => "camchain.yaml",
            Self::Kitti => "calib.txt",
            Self::Nuscenes => "calibrated_sensor.json",
        }
    }

    /// Per-camera formats write a directory with one file per camera.
    pub fn is_directory(self) -> bool {
        matches!(self, Self::CameraInfo | Self::OpenCv)
    }

    pub fn names() -> Vec<&'static str> {
        Self::ALL.iter().map(|f| f.name()).collect()
    }
}

impl std::str::FromStr for ExportFormat {
    type Err = ExportError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| ExportError::UnknownFormat(s.to_string()))
    }
}

/// Choices some formats need.
#[derive(Clone, Debug, Default)]
pub struct ExportOptions {
    /// Only these sensors (by name); empty: every sensor.
    pub sensors: Vec<String>,
    /// The LiDAR that OpenCV's `CameraExtrinsicMat` and KITTI's `Tr_velo_to_cam` refer to
    /// (default: the first LiDAR).
    pub lidar: Option<String>,
    /// KITTI's and Kalibr's reference camera, cam0 (default: the first camera).
    pub camera: Option<String>,
}

/// One written file: its name (inside the output directory for per-camera formats) and bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportedFile {
    pub name: String,
    pub bytes: Vec<u8>,
}

/// The files of one export.
#[derive(Clone, Debug)]
pub struct Export {
    pub format: ExportFormat,
    pub files: Vec<ExportedFile>,
}

impl Export {
    /// The text of every file, for a preview (binary files summarised).
    pub fn preview(&self) -> String {
        let mut out = String::new();
        for f in &self.files {
            if self.files.len() > 1 {
                out.push_str(&format!("==> {} <==\n", f.name));
            }
            match std::str::from_utf8(&f.bytes) {
                Ok(text) => out.push_str(text),
                Err(_) => out.push_str(&format!("({} bytes of binary data)\n", f.bytes.len())),
            }
            if self.files.len() > 1 {
                out.push('\n');
            }
        }
        out
    }
}

/// Export `doc` (validated) in `format`.
pub fn export(
    doc: &CalibrationFile,
    format: ExportFormat,
    options: &ExportOptions,
) -> Result<Export, ExportError> {
    let unsupported = |what: String| ExportError::Unsupported {
        format: format.name(),
        what,
    };
    let cannot = |e: NotExportable| unsupported(e.0);
    // --lidar and --camera choose within the formats that hold one pair; elsewhere they would
    // be ignored, and a user who gave one expects it to matter.
    for (option, given, takes) in [
        ("--lidar", options.lidar.is_some(), format.takes_lidar()),
        ("--camera", options.camera.is_some(), format.takes_camera()),
    ] {
        if given && !takes {
            return Err(unsupported(format!(
                "{option} does not apply to it (it writes every chosen sensor; choose them with --sensors)"
            )));
        }
    }
    // The chosen sensors only: a sensor left out cannot stop the export (a camera without
    // intrinsics, a second topic on the same frame).
    let rig = {
        let mut chosen = doc.clone();
        if let Some(missing) = options
            .sensors
            .iter()
            .find(|n| !doc.sensors.iter().any(|s| s.name == **n))
        {
            let known: Vec<&str> = doc.sensors.iter().map(|s| s.name.as_str()).collect();
            return Err(unsupported(format!(
                "'{missing}' is not a sensor of the calibration (it has: {})",
                known.join(", ")
            )));
        }
        chosen
            .sensors
            .retain(|s| options.sensors.is_empty() || options.sensors.contains(&s.name));
        chosen
            .to_rig(Path::new("the calibration"))
            .map_err(|e| unsupported(e.to_string()))?
    };
    // In a transform tree (tf, URDF, MCAP /tf_static, Autoware) a sensor whose frame is the
    // vehicle frame is the tree's root: the writers leave it out as the identity (Autoware would
    // key it `base_link_base_link`). Moved off the origin (a calibrated LiDAR that is the
    // vehicle frame, as PandaSet's Pandar64 is), it cannot be written there without losing its
    // pose; the formats that write each pose as numbers keep it. `calibrate --root` keeps such
    // a sensor put.
    let tree = matches!(
        format,
        ExportFormat::Urdf
            | ExportFormat::Ros2StaticTf
            | ExportFormat::Ros2Launch
            | ExportFormat::Mcap
            | ExportFormat::Autoware
    );
    if tree
        && let Some((s, r, t)) = rig
            .sensors
            .iter()
            .filter(|s| s.frame_id == rig.vehicle_frame)
            .map(|s| {
                let (r, t) = Rigid::IDENTITY.difference(s.vehicle_from_sensor);
                (s, r, t)
            })
            .find(|&(_, r, t)| r > 1e-9 || t > 1e-9)
    {
        return Err(unsupported(format!(
            "sensor '{}' has the vehicle frame's id '{}' but lies {:.3}° / {:.2} cm off the vehicle origin, which a transform tree rooted at that frame cannot hold; calibrate with --root {} to keep it put, give it a frame of its own, or export --format native",
            s.name,
            rig.vehicle_frame,
            r.to_degrees(),
            t * 100.0,
            s.name
        )));
    }
    let one = |text: String| {
        vec![ExportedFile {
            name: format.default_file_name().to_string(),
            bytes: text.into_bytes(),
        }]
    };
    let files = match format {
        ExportFormat::Native => {
            let mut out = CalibrationFile::from_rig(&rig);
            out.provenance = doc.provenance.clone();
            out.metrics = doc.metrics.clone();
            one(out.to_yaml())
        }
        ExportFormat::CameraInfo => camera_info::export(&rig).map_err(cannot)?,
        ExportFormat::Mcap => one_binary(
            format,
            mcap_tf::export(&rig).map_err(|e| unsupported(e.to_string()))?,
        ),
        ExportFormat::Urdf => one(urdf::export(&rig)),
        ExportFormat::Ros2StaticTf => one(ros_tf::script(&rig)),
        ExportFormat::Ros2Launch => one(ros_tf::launch(&rig)),
        ExportFormat::Autoware => one(autoware::export(&rig)),
        ExportFormat::OpenCv => opencv::export(&rig, options.lidar.as_deref()).map_err(cannot)?,
        ExportFormat::Kalibr => {
            one(kalibr::export(&rig, options.camera.as_deref()).map_err(cannot)?)
        }
        ExportFormat::Kitti => {
            one(
                kitti::export(&rig, options.camera.as_deref(), options.lidar.as_deref())
                    .map_err(cannot)?,
            )
        }
        ExportFormat::Nuscenes => one(nuscenes::export(&rig)),
    };
    distinct_names(format, &rig, &files).map_err(cannot)?;
    Ok(Export { format, files })
}

/// Names derived from sensor names must not collide: two cameras written to one file, a URDF
/// link that is the child of two joints, an Autoware key given twice.
fn distinct_names(
    format: ExportFormat,
    rig: &Rig,
    files: &[ExportedFile],
) -> Result<(), NotExportable> {
    let first_repeat = |names: Vec<String>| {
        let mut seen = std::collections::HashSet::new();
        names.into_iter().find(|n| !seen.insert(n.clone()))
    };
    if let Some(name) = first_repeat(files.iter().map(|f| f.name.clone()).collect()) {
        return Err(format!(
            "two cameras would both be written to '{name}' (their names differ only in characters a file name cannot hold): rename one or export them separately with --sensors"
        ).into());
    }
    let repeated = match format {
        ExportFormat::Urdf => {
            let children = urdf::links_and_joints(rig).1.into_iter().map(|j| j.child);
            first_repeat(children.collect()).map(|link| {
                format!("link '{link}' would be the child of two joints in the URDF (two sensors map to one link): rename one")
            })
        }
        ExportFormat::Autoware => {
            let keys = autoware::entries(rig).into_iter().map(|(k, _)| k);
            first_repeat(keys.collect()).map(|key| {
                format!("two sensors map to one Autoware frame name '{key}': rename one")
            })
        }
        _ => None,
    };
    repeated.map_or(Ok(()), |what| Err(what.into()))
}

fn one_binary(format: ExportFormat, bytes: Vec<u8>) -> Vec<ExportedFile> {
    vec![ExportedFile {
        name: format.default_file_name().to_string(),
        bytes,
    }]
}

/// The sensor named `name` of `kind`, or the rig's first of that kind.
pub(crate) fn pick<'a>(
    rig: &'a Rig,
    kind: SensorKind,
    name: Option<&str>,
) -> Result<&'a Sensor, NotExportable> {
    match name {
        Some(n) => rig
            .sensor(n)
            .filter(|s| s.kind == kind)
            .ok_or_else(|| format!("'{n}' is not a {} of the calibration", kind.as_str()).into()),
        None => rig
            .sensors
            .iter()
            .find(|s| s.kind == kind)
            .ok_or_else(|| format!("the calibration has no {}", kind.as_str()).into()),
    }
}

/// Where [`write`](fn@write) puts `export`'s files for `--out` `out`: the file itself, or one file per
/// camera inside the directory.
pub fn paths(export: &Export, out: &Path) -> Vec<PathBuf> {
    if export.format.is_directory() {
        export.files.iter().map(|f| out.join(&f.name)).collect()
    } else {
        vec![out.to_path_buf()]
    }
}

/// Write an export atomically: the file at `out`, or for per-camera formats the directory `out`
/// (created if missing) holding one file per camera, each written atomically. Nothing is
/// written unless every file's directory exists or can be made and no file's name is taken by
/// a directory.
pub fn write(export: &Export, out: &Path) -> Result<Vec<PathBuf>, ExportError> {
    let err = |path: &Path, what: String| ExportError::Write {
        path: path.to_path_buf(),
        what,
    };
    if export.format.is_directory() {
        if out.is_file() {
            return Err(err(
                out,
                format!(
                    "is a file; the {} export writes a directory (one file per camera)",
                    export.format.name()
                ),
            ));
        }
        std::fs::create_dir_all(out).map_err(|e| err(out, e.to_string()))?;
        // Every file's place is checked before the first is written, so a folder in the way
        // of one camera's file does not leave the others half replaced.
        let paths = paths(export, out);
        for path in &paths {
            crate::util::check_output(path).map_err(|e| err(path, e.to_string()))?;
        }
        for (path, f) in paths.iter().zip(&export.files) {
            crate::util::write_atomic(path, &f.bytes).map_err(|e| err(path, e.to_string()))?;
        }
        Ok(paths)
    } else {
        if out.is_dir() {
            return Err(err(out, "is a directory; give a file name".into()));
        }
        let bytes = export.files.first().map_or(&[][..], |f| &f.bytes);
        crate::util::write_atomic(out, bytes).map_err(|e| err(out, e.to_string()))?;
        // The static-transform script has a shebang: make it runnable.
        #[cfg(unix)]
        if export.format == ExportFormat::Ros2StaticTf {
            use std::os::unix::fs::PermissionsExt;
            let mut p = std::fs::metadata(out)
                .map_err(|e| err(out, e.to_string()))?
                .permissions();
            p.set_mode(p.mode() | 0o111);
            std::fs::set_permissions(out, p).map_err(|e| err(out, e.to_string()))?;
        }
        Ok(vec![out.to_path_buf()])
    }
}

#[cfg(test)]
pub(crate) mod test_rig;

#[cfg(test)]
mod collision_tests {
    use super::*;

    #[test]
    fn left_out_sensors_cannot_stop_an_export_and_colliding_names_are_refused() {
        let mut rig = test_rig::rig();
        // A camera without intrinsics and a LiDAR on another sensor's frame.
        let mut bare = rig.sensor("front_camera").unwrap().clone();
        bare.name = "bare_camera".into();
        bare.frame_id = "bare_camera".into();
        bare.camera = None;
        let mut twin = rig.sensor("lidar_top").unwrap().clone();
        twin.name = "lidar_twin".into();
        rig.sensors.push(bare);
        rig.sensors.push(twin);
        let doc = CalibrationFile::from_rig(&rig);
        let all = export(&doc, ExportFormat::Urdf, &ExportOptions::default());
        assert!(all.is_err());
        let chosen: Vec<String> = test_rig::rig()
            .sensors
            .iter()
            .map(|s| s.name.clone())
            .collect();
        let options = ExportOptions {
            sensors: chosen,
            ..Default::default()
        };
        for format in [
            ExportFormat::Urdf,
            ExportFormat::Ros2StaticTf,
            ExportFormat::Native,
        ] {
            assert!(export(&doc, format, &options).is_ok(), "{}", format.name());
        }
        // Two camera names that become one file name; a LiDAR named like a camera's body link.
        let mut collide = test_rig::rig();
        let mut c2 = collide.sensor("front_camera").unwrap().clone();
        c2.name = "front camera".into();
        c2.frame_id = "front_camera_b".into();
        collide.sensors.push(c2);
        let doc = CalibrationFile::from_rig(&collide);
        let e = export(&doc, ExportFormat::CameraInfo, &ExportOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("front_camera.yaml"), "{e}");
        // A sensor on the vehicle frame off the origin cannot be written as a tf tree.
        let mut on_vehicle = test_rig::rig();
        let vehicle = on_vehicle.vehicle_frame.clone();
        on_vehicle.sensors[0].frame_id = vehicle;
        let doc = CalibrationFile::from_rig(&on_vehicle);
        for format in [
            ExportFormat::Ros2StaticTf,
            ExportFormat::Urdf,
            ExportFormat::Autoware,
        ] {
            let e = export(&doc, format, &ExportOptions::default()).unwrap_err();
            assert!(e.to_string().contains("vehicle origin"), "{e}");
        }
        // The formats that write each pose as numbers keep it.
        for format in [ExportFormat::Native, ExportFormat::Nuscenes] {
            assert!(export(&doc, format, &ExportOptions::default()).is_ok());
        }
        let mut links = test_rig::rig();
        let mut lidar = links.sensor("lidar_top").unwrap().clone();
        lidar.name = "lidar_link_clash".into();
        lidar.frame_id = "front_camera_link".into();
        links.sensors.push(lidar);
        let doc = CalibrationFile::from_rig(&links);
        let e = export(&doc, ExportFormat::Urdf, &ExportOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("front_camera_link"), "{e}");
        let mut keys = test_rig::rig();
        let mut lidar = keys.sensor("lidar_top").unwrap().clone();
        lidar.name = "lidar_top_again".into();
        lidar.frame_id = "lidar_top_base_link".into();
        keys.sensors.push(lidar);
        let doc = CalibrationFile::from_rig(&keys);
        let e = export(&doc, ExportFormat::Autoware, &ExportOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("Autoware"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn the_static_tf_script_is_executable() {
        use std::os::unix::fs::PermissionsExt;
        let dir = std::env::temp_dir().join(format!("rigcal-tf-exec-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let doc = CalibrationFile::from_rig(&test_rig::rig());
        let e = export(&doc, ExportFormat::Ros2StaticTf, &ExportOptions::default()).unwrap();
        let out = dir.join("static_tf.sh");
        write(&e, &out).unwrap();
        assert_ne!(
            std::fs::metadata(&out).unwrap().permissions().mode() & 0o100,
            0
        );
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn a_per_camera_export_with_one_name_taken_by_a_folder_writes_nothing() {
        let dir = std::env::temp_dir().join(format!("rigcal-export-taken-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let doc = CalibrationFile::from_rig(&test_rig::rig());
        let e = export(&doc, ExportFormat::CameraInfo, &ExportOptions::default()).unwrap();
        assert!(e.files.len() >= 2);
        // The last camera's file name is a folder: nothing may be written before that shows.
        let taken = dir.join(&e.files[e.files.len() - 1].name);
        std::fs::create_dir_all(&taken).unwrap();
        let err = write(&e, &dir).unwrap_err().to_string();
        assert!(err.contains("is a directory"), "{err}");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        let _ = std::fs::remove_dir_all(dir);
    }
}
