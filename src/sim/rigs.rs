//! Simulated rigs: every sensor's mounting (`vehicle_from_sensor`, the ground truth of a
//! synthetic drive), LiDAR scan patterns and camera intrinsics, exposure and trigger timing.
//!
//! The vehicle frame is `base_link`: on the ground, x forward, y left, z up. Cameras use the
//! OpenCV optical frame (x right, y down, z forward). A LiDAR ray at azimuth `a` and elevation `e`
//! (degrees, in the LiDAR's own frame, azimuth counter-clockwise about +z from +x) points along
//! `(cos e cos a, cos e sin a, sin e)`, see [`SimLidar::ray_direction`].
//!
//! Presets:
//! - `pandaset`: the PandaSet platform with its real extrinsics and intrinsics (pandaset-devkit
//!   `docs/static_extrinsic_calibration.yaml`, as in `../shared/data/pandaset-002`), moved from the
//!   dataset's Pandar64-centred vehicle frame onto a `base_link` on the ground; a Pandar64 with
//!   the real elevation table and a forward PandarGT.
//! - `truck`: the paper's MS-Cal Class-8 truck (method.md §13, supplementary §A2): two long-range
//!   and three medium-range spinning LiDARs, three wide, three medium and two narrow stereo
//!   cameras on a tall cab.
//! - `kitti`: the KITTI 2011-09-26 rig (rectified colour stereo pair and an HDL-64E), from the
//!   dataset's published calibration.

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use glam::{DMat3, DQuat, DVec3};
use thiserror::Error;

use crate::calib::{CalibFileError, CalibrationFile, Rig, Sensor, SensorKind};
use crate::geometry::Rigid;
use crate::geometry::camera::{CameraIntrinsics, CameraModel};

/// A LiDAR and its scan pattern.
#[derive(Clone, Debug, PartialEq)]
pub struct SimLidar {
    pub name: String,
    pub vehicle_from_lidar: Rigid,
    /// Elevation of every beam (degrees above the LiDAR's xy plane), top beam first.
    pub beam_elevations_deg: Vec<f64>,
    /// Azimuths scanned (degrees, in the LiDAR frame): (-180, 180) for a spinning LiDAR, a
    /// window around the LiDAR's forward direction for a solid-state one.
    pub azimuth_range_deg: (f64, f64),
    pub azimuth_resolution_deg: f64,
    /// Sweeps per second.
    pub rotation_hz: f64,
    pub max_range_m: f64,
    /// Standard deviation of the range noise.
    pub range_noise_m: f64,
    pub spinning: bool,
}

/// A camera, its exposure and when it fires.
#[derive(Clone, Debug, PartialEq)]
pub struct SimCamera {
    pub name: String,
    /// Into the OpenCV optical frame (x right, y down, z forward).
    pub vehicle_from_camera: Rigid,
    pub intrinsics: CameraIntrinsics,
    /// Brightness factor of this camera's images (1 = neutral).
    pub exposure_gain: f64,
    /// Per-channel colour factors (1 = neutral).
    pub tint_rgb: [f64; 3],
    /// When the camera fires relative to the sweep stamp (s). As on PandaSet, cameras fire as
    /// the spinning LiDAR, turning clockwise seen from above, sweeps past their heading; the
    /// sweep stamp is the front camera's trigger, so the back camera fires ~50 ms earlier.
    pub trigger_offset_secs: f64,
}

/// A vehicle frame and the sensors mounted on it.
#[derive(Clone, Debug, PartialEq)]
pub struct SimRig {
    pub name: String,
    /// `base_link` for the presets.
    pub vehicle_frame: String,
    pub lidars: Vec<SimLidar>,
    pub cameras: Vec<SimCamera>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RigPreset {
    Pandaset,
    Truck,
    Kitti,
}

impl RigPreset {
    pub const ALL: [RigPreset; 3] = [RigPreset::Pandaset, RigPreset::Truck, RigPreset::Kitti];

    pub fn as_str(self) -> &'static str {
        match self {
            RigPreset::Pandaset => "pandaset",
            RigPreset::Truck => "truck",
            RigPreset::Kitti => "kitti",
        }
    }
}

impl fmt::Display for RigPreset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[error("unknown rig preset '{0}'; expected one of: pandaset, truck, kitti")]
pub struct UnknownRigPreset(pub String);

impl FromStr for RigPreset {
    type Err = UnknownRigPreset;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "pandaset" => Ok(RigPreset::Pandaset),
            "truck" | "ms-cal" | "mscal" => Ok(RigPreset::Truck),
            "kitti" => Ok(RigPreset::Kitti),
            _ => Err(UnknownRigPreset(s.to_string())),
        }
    }
}

impl SimLidar {
    /// Unit ray in the LiDAR frame at `azimuth_deg` (counter-clockwise about +z from +x) and
    /// `elevation_deg` (up from the xy plane).
    pub fn ray_direction(azimuth_deg: f64, elevation_deg: f64) -> DVec3 {
        let (a, e) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
        DVec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin())
    }

    pub fn beam_count(&self) -> usize {
        self.beam_elevations_deg.len()
    }

    /// Azimuth columns of one sweep.
    pub fn azimuth_steps(&self) -> usize {
        let span = (self.azimuth_range_deg.1 - self.azimuth_range_deg.0).abs();
        let res = self.azimuth_resolution_deg.abs().max(1e-6);
        ((span / res).round() as usize).max(1)
    }

    /// Rays fired per sweep (before dropouts and misses).
    pub fn rays_per_sweep(&self) -> usize {
        self.beam_count() * self.azimuth_steps()
    }

    /// Azimuth (degrees, in the LiDAR frame) of the vehicle's forward direction (`base_link` +x).
    pub fn forward_azimuth_deg(&self) -> f64 {
        let forward = self.vehicle_from_lidar.inverse().transform_vector(DVec3::X);
        forward.y.atan2(forward.x).to_degrees()
    }

    /// A 64-beam spinning LiDAR with the Pandar64 elevation table: 0.2°, 10 Hz, 200 m.
    pub fn spinning_64(name: &str, vehicle_from_lidar: Rigid) -> Self {
        Self {
            name: name.to_string(),
            vehicle_from_lidar,
            beam_elevations_deg: PANDAR64_ELEVATIONS_DEG.to_vec(),
            azimuth_range_deg: (-180.0, 180.0),
            azimuth_resolution_deg: 0.2,
            rotation_hz: 10.0,
            max_range_m: 200.0,
            range_noise_m: 0.02,
            spinning: true,
        }
    }

    /// A 32-beam spinning LiDAR like an HDL-32E (+10.67° to −30.67°): 0.2°, 10 Hz, 100 m.
    pub fn spinning_32(name: &str, vehicle_from_lidar: Rigid) -> Self {
        Self {
            name: name.to_string(),
            vehicle_from_lidar,
            beam_elevations_deg: linspace(10.67, -30.67, 32),
            azimuth_range_deg: (-180.0, 180.0),
            azimuth_resolution_deg: 0.2,
            rotation_hz: 10.0,
            max_range_m: 100.0,
            range_noise_m: 0.02,
            spinning: true,
        }
    }
}

impl SimCamera {
    /// Heading of the optical axis in the vehicle's ground plane (degrees, 0 = forward, 90 =
    /// left).
    pub fn heading_deg(&self) -> f64 {
        let axis = self.vehicle_from_camera.transform_vector(DVec3::Z);
        axis.y.atan2(axis.x).to_degrees()
    }

    fn neutral(name: &str, vehicle_from_camera: Rigid, intrinsics: CameraIntrinsics) -> Self {
        Self {
            name: name.to_string(),
            vehicle_from_camera,
            intrinsics,
            exposure_gain: 1.0,
            tint_rgb: [1.0; 3],
            trigger_offset_secs: 0.0,
        }
    }

    fn with_exposure(mut self, gain: f64, tint_rgb: [f64; 3]) -> Self {
        self.exposure_gain = gain;
        self.tint_rgb = tint_rgb;
        self
    }

    fn with_trigger(mut self, offset_secs: f64) -> Self {
        self.trigger_offset_secs = offset_secs;
        self
    }
}

/// Trigger offset (s) of a camera whose optical axis has heading `heading_deg`, for a LiDAR
/// turning clockwise (seen from above) at `rotation_hz` whose sweep is stamped facing forward.
/// The sweep's seam is at −170° (just right of straight back), so a camera looking straight back
/// fires half a period early rather than late.
pub fn sweep_trigger_offset_secs(heading_deg: f64, rotation_hz: f64) -> f64 {
    let seam = -170.0;
    let heading = (heading_deg - seam).rem_euclid(360.0) + seam;
    -heading / 360.0 / rotation_hz.max(1e-3)
}

impl SimRig {
    pub fn preset(p: RigPreset) -> Self {
        match p {
            RigPreset::Pandaset => pandaset(),
            RigPreset::Truck => truck(),
            RigPreset::Kitti => kitti(),
        }
    }

    pub fn lidar(&self, name: &str) -> Option<&SimLidar> {
        self.lidars.iter().find(|l| l.name == name)
    }

    pub fn camera(&self, name: &str) -> Option<&SimCamera> {
        self.cameras.iter().find(|c| c.name == name)
    }

    /// The rig as the calibration model sees it: LiDARs then cameras, frame ids equal to the
    /// names, the topics `rigcal synth` writes.
    pub fn to_rig(&self) -> Rig {
        let lidars = self.lidars.iter().map(|l| Sensor {
            name: l.name.clone(),
            kind: SensorKind::Lidar,
            frame_id: l.name.clone(),
            topics: vec![format!("/{}/points", l.name)],
            vehicle_from_sensor: l.vehicle_from_lidar,
            camera: None,
        });
        let cameras = self.cameras.iter().map(|c| Sensor {
            name: c.name.clone(),
            kind: SensorKind::Camera,
            frame_id: c.name.clone(),
            topics: vec![
                format!("/{}/image/compressed", c.name),
                format!("/{}/camera_info", c.name),
            ],
            vehicle_from_sensor: c.vehicle_from_camera,
            camera: Some(c.intrinsics.clone()),
        });
        Rig {
            vehicle_frame: self.vehicle_frame.clone(),
            sensors: lidars.chain(cameras).collect(),
        }
    }

    /// A rig from a native calibration file: extrinsics and intrinsics from the file; LiDAR scan
    /// patterns default to a 64-beam spinning LiDAR (32-beam if the name contains "32"), cameras
    /// with neutral exposure, firing at the sweep stamp.
    pub fn from_calibration_file(path: &Path) -> Result<Self, CalibFileError> {
        let rig = CalibrationFile::load_rig(path)?;
        let mut out = SimRig {
            name: path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "calibration".to_string()),
            vehicle_frame: rig.vehicle_frame.clone(),
            lidars: Vec::new(),
            cameras: Vec::new(),
        };
        for sensor in &rig.sensors {
            match (sensor.kind, &sensor.camera) {
                (SensorKind::Lidar, _) if sensor.name.contains("32") => out.lidars.push(
                    SimLidar::spinning_32(&sensor.name, sensor.vehicle_from_sensor),
                ),
                (SensorKind::Lidar, _) => out.lidars.push(SimLidar::spinning_64(
                    &sensor.name,
                    sensor.vehicle_from_sensor,
                )),
                (SensorKind::Camera, Some(intrinsics)) => out.cameras.push(SimCamera::neutral(
                    &sensor.name,
                    sensor.vehicle_from_sensor,
                    intrinsics.clone(),
                )),
                (SensorKind::Camera, None) => {
                    return Err(CalibFileError::Invalid {
                        path: path.to_path_buf(),
                        what: format!("camera '{}' has no camera: block", sensor.name),
                    });
                }
            }
        }
        Ok(out)
    }

    /// The same rig with every camera's image scaled by `image_scale` (intrinsics scaled with
    /// [`CameraIntrinsics::scaled`]); a non-positive or non-finite scale changes nothing.
    pub fn scaled(&self, image_scale: f64) -> Self {
        let mut out = self.clone();
        if image_scale.is_finite() && image_scale > 0.0 {
            for camera in &mut out.cameras {
                camera.intrinsics = camera.intrinsics.scaled(image_scale);
            }
        }
        out
    }
}

/// Hesai Pandar64 channel elevations (degrees), channel 1 to 64: dense (~1/6°) from +3° to −6°.
pub const PANDAR64_ELEVATIONS_DEG: [f64; 64] = [
    14.882, 11.032, 8.059, 5.057, 3.04, 2.028, 1.86, 1.688, 1.522, 1.351, 1.184, 1.013, 0.846,
    0.675, 0.508, 0.337, 0.169, 0.0, -0.169, -0.337, -0.508, -0.675, -0.845, -1.013, -1.184,
    -1.351, -1.522, -1.688, -1.86, -2.028, -2.198, -2.365, -2.536, -2.7, -2.873, -3.04, -3.21,
    -3.375, -3.548, -3.712, -3.884, -4.05, -4.221, -4.385, -4.558, -4.72, -4.892, -5.057, -5.229,
    -5.391, -5.565, -5.726, -5.898, -6.061, -7.063, -8.059, -9.06, -9.885, -11.032, -12.006,
    -12.974, -13.93, -18.889, -24.897,
];

/// `count` values from `first` to `last` inclusive.
fn linspace(first: f64, last: f64, count: usize) -> Vec<f64> {
    let steps = count.saturating_sub(1).max(1) as f64;
    (0..count)
        .map(|i| first + (last - first) * i as f64 / steps)
        .collect()
}

/// R = Rz(yaw) · Ry(pitch) · Rx(roll) (URDF rpy), angles in degrees. Positive pitch tips +x down.
fn rpy_deg(roll: f64, pitch: f64, yaw: f64) -> DQuat {
    DQuat::from_rotation_z(yaw.to_radians())
        * DQuat::from_rotation_y(pitch.to_radians())
        * DQuat::from_rotation_x(roll.to_radians())
}

/// A camera's `vehicle_from_camera` rotation: optical axis at `yaw_deg` (0 forward, 90 left),
/// tipped down by `pitch_down_deg`, rolled by `roll_deg` about the optical axis.
fn optical_deg(yaw_deg: f64, pitch_down_deg: f64, roll_deg: f64) -> DQuat {
    // Optical x right, y down, z forward -> vehicle -y, -z, +x.
    let forward_from_optical =
        DQuat::from_mat3(&DMat3::from_cols(DVec3::NEG_Y, DVec3::NEG_Z, DVec3::X));
    rpy_deg(roll_deg, pitch_down_deg, yaw_deg) * forward_from_optical
}

fn mount(rotation: DQuat, x: f64, y: f64, z: f64) -> Rigid {
    Rigid::new(rotation, DVec3::new(x, y, z))
}

fn rigid_from_rows(rows: [[f64; 4]; 3]) -> Rigid {
    Rigid::from_rows([rows[0], rows[1], rows[2], [0.0, 0.0, 0.0, 1.0]])
}

// ---------------------------------------------------------------------------------------------
// PandaSet

/// PandaSet's `pandar64_from_sensor` (rows of the 3×4 matrix) and pinhole intrinsics
/// `[fx, fy, cx, cy]` of its 1920×1080 cameras, with each camera's measured trigger offset (s)
/// relative to the front camera, which is also the sweep stamp.
struct PandasetCamera {
    name: &'static str,
    pandar64_from_camera: [[f64; 4]; 3],
    fx_fy_cx_cy: [f64; 4],
    trigger_offset_secs: f64,
    exposure_gain: f64,
    tint_rgb: [f64; 3],
}

#[rustfmt::skip]
const PANDASET_CAMERAS: [PandasetCamera; 6] = [
    PandasetCamera {
        name: "front_camera",
        pandar64_from_camera: [
            [-0.999455562908, -0.018429005057, -0.027366942566, -0.001666215228],
            [0.02713141954, 0.012911061658, -0.999548493351, -0.043495184383],
            [0.018774020521, -0.999746806076, -0.012404027329, -0.039618665202],
        ],
        fx_fy_cx_cy: [1970.0131, 1970.0091, 970.0002, 483.2988],
        trigger_offset_secs: 0.0,
        exposure_gain: 1.02,
        tint_rgb: [1.01, 1.0, 0.98],
    },
    PandasetCamera {
        name: "front_left_camera",
        pandar64_from_camera: [
            [-0.560174370037, 0.004482552461, 0.828362590825, 0.622373557627],
            [-0.828245508447, 0.014630713283, -0.560174365682, -0.727383559343],
            [-0.014630546542, -0.999882917622, -0.004483096654, -0.314954622268],
        ],
        fx_fy_cx_cy: [929.8429, 930.0592, 972.1794, 508.0057],
        trigger_offset_secs: -0.0108,
        exposure_gain: 0.93,
        tint_rgb: [0.97, 1.0, 1.04],
    },
    PandasetCamera {
        name: "left_camera",
        pandar64_from_camera: [
            [-0.004697786493, 0.017009803011, 0.999844286578, 0.543482199366],
            [-0.999956437823, 0.007984575312, -0.004834150643, 0.238275570641],
            [-0.008065559957, -0.999823440993, 0.016971552197, -0.269045276378],
        ],
        fx_fy_cx_cy: [930.4514, 930.0891, 991.6883, 541.6057],
        trigger_offset_secs: -0.0314,
        exposure_gain: 1.10,
        tint_rgb: [1.03, 0.99, 0.96],
    },
    PandasetCamera {
        name: "back_camera",
        pandar64_from_camera: [
            [0.999994338864, -0.002996150297, 0.00153144489, 0.001388303417],
            [-0.001474262708, 0.018995225691, 0.999818487502, 1.059271129525],
            [-0.003024696599, -0.999815085145, 0.018990701044, -0.196750897052],
        ],
        fx_fy_cx_cy: [933.4667, 934.6754, 896.4692, 507.3557],
        trigger_offset_secs: -0.0501,
        exposure_gain: 0.88,
        tint_rgb: [0.98, 1.01, 1.05],
    },
    PandasetCamera {
        name: "right_camera",
        pandar64_from_camera: [
            [0.007201902154, -0.014771357109, -0.999864960689, -0.687844181657],
            [0.999888082545, 0.013218445711, 0.007006787945, 0.239822774162],
            [0.013113160934, -0.999803520549, 0.014864901889, -0.295162487589],
        ],
        fx_fy_cx_cy: [922.5465, 922.4229, 945.057, 517.575],
        trigger_offset_secs: 0.0313,
        exposure_gain: 1.06,
        tint_rgb: [1.04, 1.0, 0.97],
    },
    PandasetCamera {
        name: "front_right_camera",
        pandar64_from_camera: [
            [-0.505656858362, -0.007553835324, -0.862701617689, -0.622489731753],
            [0.86272816171, -0.000537904543, -0.505667706752, -0.659118584754],
            [0.003355679466, -0.999971324704, 0.006788901584, -0.244244773163],
        ],
        fx_fy_cx_cy: [930.0407, 930.0324, 965.0525, 463.4161],
        trigger_offset_secs: 0.0108,
        exposure_gain: 0.96,
        tint_rgb: [0.99, 1.02, 1.01],
    },
];

/// PandaSet's `pandar64_from_pandar_gt`. The PandarGT's own frame has +y forward (Hesai's
/// convention), so its ±30° window is centred on azimuth 90°.
#[rustfmt::skip]
const PANDAR64_FROM_PANDAR_GT: [[f64; 4]; 3] = [
    [-0.99906908922, 0.042891977694, -0.004607951188, 0.024137261859],
    [-0.042985516355, -0.998820084983, 0.022598301236, -0.598137253561],
    [-0.003633228364, 0.022775339395, 0.999734006407, 0.315237195411],
];

/// Height of the Pandar64 above the ground (m); the paper's FLU reference puts it at 1.86 m.
const PANDAR64_HEIGHT_M: f64 = 1.9;

/// `base_link_from_pandar64`: the Pandar64 frame is level with the ground but turned ~92° (its
/// −y is forward). Forward is the front camera's optical axis, projected on the ground.
pub fn pandaset_base_link_from_pandar64() -> Rigid {
    let front = rigid_from_rows(PANDASET_CAMERAS[0].pandar64_from_camera);
    let forward = front.transform_vector(DVec3::Z);
    let yaw = -forward.y.atan2(forward.x);
    Rigid::new(
        DQuat::from_rotation_z(yaw),
        DVec3::new(0.0, 0.0, PANDAR64_HEIGHT_M),
    )
}

fn pandaset() -> SimRig {
    let base_from_p64 = pandaset_base_link_from_pandar64();
    let pandar64 = SimLidar::spinning_64("pandar64", base_from_p64);
    // ~60k rays like the real PandarGT sweeps: 150 beams × 400 columns over ±30°.
    let pandar_gt = SimLidar {
        name: "pandar_gt".to_string(),
        vehicle_from_lidar: base_from_p64 * rigid_from_rows(PANDAR64_FROM_PANDAR_GT),
        beam_elevations_deg: linspace(12.5, -12.5, 150),
        azimuth_range_deg: (60.0, 120.0),
        azimuth_resolution_deg: 0.15,
        rotation_hz: 10.0,
        max_range_m: 200.0,
        range_noise_m: 0.02,
        spinning: false,
    };
    let cameras = PANDASET_CAMERAS
        .iter()
        .map(|c| {
            let [fx, fy, cx, cy] = c.fx_fy_cx_cy;
            SimCamera::neutral(
                c.name,
                base_from_p64 * rigid_from_rows(c.pandar64_from_camera),
                CameraIntrinsics::pinhole(1920, 1080, fx, fy, cx, cy),
            )
            .with_exposure(c.exposure_gain, c.tint_rgb)
            .with_trigger(c.trigger_offset_secs)
        })
        .collect();
    SimRig {
        name: "pandaset".to_string(),
        vehicle_frame: "base_link".to_string(),
        lidars: vec![pandar64, pandar_gt],
        cameras,
    }
}

// ---------------------------------------------------------------------------------------------
// MS-Cal truck

/// `base_link` is on the ground under the front axle; the cab roof is ~3.6 m up.
fn truck() -> SimRig {
    let long_range = |name: &str, y: f64, yaw: f64| SimLidar {
        max_range_m: 200.0,
        ..SimLidar::spinning_64(name, mount(rpy_deg(0.4, 1.5, yaw), 0.9, y, 3.35))
    };
    let medium_range = |name: &str, rotation: DQuat, x: f64, y: f64, z: f64| SimLidar {
        max_range_m: 50.0,
        ..SimLidar::spinning_32(name, mount(rotation, x, y, z))
    };
    let lidars = vec![
        long_range("long_range_left", 1.25, 28.0),
        long_range("long_range_right", -1.25, -31.0),
        medium_range(
            "medium_range_front",
            rpy_deg(0.0, 8.0, 0.0),
            1.75,
            0.0,
            2.55,
        ),
        medium_range(
            "medium_range_left",
            rpy_deg(0.0, 14.0, 90.0),
            0.4,
            1.35,
            2.6,
        ),
        medium_range(
            "medium_range_right",
            rpy_deg(0.0, 14.0, -90.0),
            0.4,
            -1.35,
            2.6,
        ),
    ];

    let wide = |cx: f64, cy: f64, k: [f64; 5]| CameraIntrinsics {
        model: CameraModel::PlumbBob,
        distortion: k.to_vec(),
        ..CameraIntrinsics::pinhole(1920, 1080, 600.0, 600.4, cx, cy)
    };
    let medium = |fx: f64, cx: f64, cy: f64, k: [f64; 5]| CameraIntrinsics {
        model: CameraModel::PlumbBob,
        distortion: k.to_vec(),
        ..CameraIntrinsics::pinhole(1920, 1080, fx, fx * 1.0004, cx, cy)
    };
    let narrow = |fx: f64, cx: f64, cy: f64| CameraIntrinsics {
        model: CameraModel::PlumbBob,
        distortion: vec![-0.04, 0.1, 0.0, 0.0, 0.0],
        ..CameraIntrinsics::pinhole(1920, 1080, fx, fx, cx, cy)
    };
    // Wide lenses: strong barrel (k1 ≈ −0.3) that stays one-to-one out to the image corners.
    let cameras = [
        (
            "stereo_left",
            mount(optical_deg(0.0, 1.0, 0.0), 1.65, 0.25, 3.05),
            narrow(3010.0, 961.2, 541.5),
            1.03,
            [1.0, 1.0, 1.02],
        ),
        (
            "stereo_right",
            mount(optical_deg(-0.3, 1.1, 0.2), 1.65, -0.25, 3.05),
            narrow(2995.0, 957.9, 538.1),
            0.97,
            [1.02, 1.0, 0.99],
        ),
        (
            "front_medium",
            mount(optical_deg(0.5, 4.0, 0.0), 1.7, 0.45, 2.95),
            medium(1400.0, 955.4, 543.0, [-0.11, 0.08, 0.0003, -0.0002, 0.0]),
            1.0,
            [1.0, 1.0, 1.0],
        ),
        (
            "rear_left_medium",
            mount(optical_deg(152.0, 5.0, 0.0), 0.6, 1.45, 3.1),
            medium(1405.0, 963.8, 536.2, [-0.1, 0.07, 0.0, 0.0002, 0.0]),
            0.9,
            [0.97, 1.0, 1.04],
        ),
        (
            "rear_right_medium",
            mount(optical_deg(-152.0, 5.0, 0.0), 0.6, -1.45, 3.1),
            medium(1398.0, 958.1, 540.7, [-0.1, 0.07, -0.0002, 0.0, 0.0]),
            1.12,
            [1.04, 0.99, 0.97],
        ),
        (
            "front_wide",
            mount(optical_deg(0.0, 8.0, 0.0), 1.75, -0.2, 2.85),
            wide(962.5, 538.9, [-0.3, 0.1, 0.0004, -0.0003, 0.0]),
            1.07,
            [1.0, 0.98, 1.03],
        ),
        (
            "left_wide",
            mount(optical_deg(90.0, 15.0, 0.0), 0.8, 1.3, 3.0),
            wide(957.3, 542.6, [-0.29, 0.095, -0.0003, 0.0002, 0.0]),
            0.86,
            [0.96, 1.01, 1.03],
        ),
        (
            "right_wide",
            mount(optical_deg(-90.0, 15.0, 0.0), 0.8, -1.3, 3.0),
            wide(964.0, 535.8, [-0.31, 0.105, 0.0002, 0.0004, 0.0]),
            1.14,
            [1.05, 1.0, 0.96],
        ),
    ]
    .into_iter()
    .map(|(name, vehicle_from_camera, intrinsics, gain, tint)| {
        let camera = SimCamera::neutral(name, vehicle_from_camera, intrinsics);
        let trigger = sweep_trigger_offset_secs(camera.heading_deg(), 10.0);
        camera.with_exposure(gain, tint).with_trigger(trigger)
    })
    .collect();
    SimRig {
        name: "truck".to_string(),
        vehicle_frame: "base_link".to_string(),
        lidars,
        cameras,
    }
}

// ---------------------------------------------------------------------------------------------
// KITTI

/// KITTI raw 2011-09-26 calibration: `cam0_from_velo`, the rectifying rotation, the last
/// column of the rectified projections P2 and P3, the intrinsics, and `velo_from_imu`.
#[rustfmt::skip]
const KITTI_CAM0_FROM_VELO: [[f64; 4]; 3] = [
    [7.533744908869e-03, -9.999713897705e-01, -6.166020175442e-04, -4.069766029716e-03],
    [1.480249036103e-02, 7.280732970685e-04, -9.998902082443e-01, -7.631617784500e-02],
    [9.998620748520e-01, 7.523790001869e-03, 1.480755023658e-02, -2.717806100845e-01],
];
const KITTI_R0_RECT: [[f64; 3]; 3] = [
    [9.999238848686e-01, 9.837759658694e-03, -7.445048075169e-03],
    [-9.869795292616e-03, 9.999421238899e-01, -4.278459120542e-03],
    [7.402527146041e-03, 4.351614043117e-03, 9.999631047249e-01],
];
const KITTI_P2_LAST: [f64; 3] = [4.485728e+01, 2.163791e-01, 2.745884e-03];
const KITTI_P3_LAST: [f64; 3] = [-3.395242e+02, 2.199936e+00, 2.729905e-03];
const KITTI_FX_CX_CY: [f64; 3] = [7.215377e+02, 6.095593e+02, 1.728540e+02];
#[rustfmt::skip]
const KITTI_VELO_FROM_IMU: [[f64; 4]; 3] = [
    [9.999976158142e-01, 7.553070900030e-04, -2.035825978965e-03, -8.086758852005e-01],
    [-7.854027207941e-04, 9.998897910118e-01, -1.482298038900e-02, 3.195559084415e-01],
    [2.024406101555e-03, 1.482454035431e-02, 9.998881220818e-01, -7.997230887413e-01],
];
/// Height of the Velodyne above the ground (m), from the KITTI sensor setup.
const KITTI_VELODYNE_HEIGHT_M: f64 = 1.73;

/// `rectified_camera_from_velo` of the camera whose rectified projection ends in `last`:
/// x_cam = R0 (R x_velo + t) + K⁻¹ last.
fn kitti_camera_from_velo(last: [f64; 3]) -> Rigid {
    let [fx, cx, cy] = KITTI_FX_CX_CY;
    let bz = last[2];
    let offset = DVec3::new((last[0] - cx * bz) / fx, (last[1] - cy * bz) / fx, bz);
    let r0 = DMat3::from_cols_array_2d(&KITTI_R0_RECT).transpose();
    let cam0_from_velo = rigid_from_rows(KITTI_CAM0_FROM_VELO);
    let rotation = r0 * cam0_from_velo.rotation_matrix();
    let translation = r0 * cam0_from_velo.translation + offset;
    Rigid::from_mat4(glam::DMat4::from_cols(
        rotation.x_axis.extend(0.0),
        rotation.y_axis.extend(0.0),
        rotation.z_axis.extend(0.0),
        translation.extend(1.0),
    ))
}

/// `base_link` is on the ground under the IMU (near the rear axle), with the IMU's axes.
fn kitti() -> SimRig {
    let imu_from_velo = rigid_from_rows(KITTI_VELO_FROM_IMU).inverse();
    let imu_height = KITTI_VELODYNE_HEIGHT_M - imu_from_velo.translation.z;
    let base_from_velo = Rigid::from_translation(DVec3::new(0.0, 0.0, imu_height)) * imu_from_velo;
    let mut upper = linspace(2.0, -8.33, 32);
    upper.extend(linspace(-8.83, -24.8, 32));
    let velodyne = SimLidar {
        name: "velodyne".to_string(),
        vehicle_from_lidar: base_from_velo,
        beam_elevations_deg: upper,
        azimuth_range_deg: (-180.0, 180.0),
        azimuth_resolution_deg: 0.18,
        rotation_hz: 10.0,
        max_range_m: 120.0,
        range_noise_m: 0.02,
        spinning: true,
    };
    let [f, cx, cy] = KITTI_FX_CX_CY;
    let intrinsics = CameraIntrinsics::pinhole(1242, 375, f, f, cx, cy);
    // KITTI's cameras are triggered when the Velodyne faces forward.
    let camera = |name: &str, last: [f64; 3], gain: f64, tint: [f64; 3]| {
        SimCamera::neutral(
            name,
            base_from_velo * kitti_camera_from_velo(last).inverse(),
            intrinsics.clone(),
        )
        .with_exposure(gain, tint)
    };
    SimRig {
        name: "kitti".to_string(),
        vehicle_frame: "base_link".to_string(),
        lidars: vec![velodyne],
        cameras: vec![
            camera("stereo_left", KITTI_P2_LAST, 1.0, [1.0, 1.0, 1.0]),
            camera("stereo_right", KITTI_P3_LAST, 0.94, [1.02, 1.0, 0.97]),
        ],
    }
}

#[cfg(test)]
mod tests;
