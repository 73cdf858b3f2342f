//! `rigcal synth`: a whole synthetic drive — trajectory, world, every sensor's stream — written
//! as a ROS 2 MCAP, with the ground truth as a native calibration file.
//!
//! The /tf_static of the MCAP carries the *initial guess*: the ground truth with every sensor
//! perturbed by exactly `perturb_deg` about a random axis and `perturb_cm` in a random direction
//! (seeded). Sweeps are stamped when the spinning LiDAR faces forward; each camera triggers when
//! the LiDAR sweeps past its heading. Frames are simulated in parallel and written in time order.

use std::path::Path;

use glam::DVec3;
use rayon::prelude::*;
use thiserror::Error;

use super::camera_sim::{self, Exposure, RayTable};
use super::lidar_sim;
use super::rigs::SimRig;
use super::trajectories::{self, TrajectoryConfig, TrajectoryKind};
use super::world::{SceneKind, World};
use super::writer::{Ros2McapWriter, WriterError};
use crate::calib::{CalibFileError, CalibrationFile, Rig};
use crate::geometry::{Rigid, Trajectory, TrajectoryError, so3};

/// Epoch of simulated drives (2023-11-14T22:13:20Z), so stamps look like real ones.
pub const EPOCH_NANOS: i64 = 1_700_000_000_000_000_000;

#[derive(Debug, Error)]
pub enum SimError {
    #[error(transparent)]
    Writer(#[from] WriterError),
    #[error(transparent)]
    Calibration(#[from] CalibFileError),
    #[error("trajectory: {0}")]
    Trajectory(#[from] TrajectoryError),
    #[error("{0}")]
    Config(String),
    #[error("cannot encode an image: {0}")]
    Image(String),
}

#[derive(Clone, Debug)]
pub struct SynthConfig {
    pub scene: SceneKind,
    pub rig: SimRig,
    pub trajectory: TrajectoryKind,
    pub duration_secs: f64,
    pub seed: u64,
    pub perturb_deg: f64,
    pub perturb_cm: f64,
    /// Image size factor (0.5 = half-size images, intrinsics scaled to match).
    pub scale: f64,
    pub jpeg_quality: u8,
    /// Camera frame rate; the LiDAR rate is its rotation rate.
    pub camera_rate_hz: f64,
}

impl SynthConfig {
    pub fn new(
        scene: SceneKind,
        rig: SimRig,
        trajectory: TrajectoryKind,
        duration_secs: f64,
        seed: u64,
    ) -> Self {
        Self {
            scene,
            rig,
            trajectory,
            duration_secs,
            seed,
            perturb_deg: 0.0,
            perturb_cm: 0.0,
            scale: 1.0,
            jpeg_quality: 90,
            camera_rate_hz: 10.0,
        }
    }
}

/// What a synthesis produced.
#[derive(Clone, Debug)]
pub struct SynthOutput {
    pub ground_truth: Rig,
    pub initial: Rig,
    pub sweeps: usize,
    pub images: usize,
}

/// The largest perturbation [`perturb_rig`] is asked for by the CLI: a half turn, and 10 m
/// (a sensor further off than that is not an initial guess, and a scene box that spans it
/// would not fit in memory).
pub const MAX_PERTURB_DEG: f64 = 180.0;
pub const MAX_PERTURB_CM: f64 = 1000.0;

/// Why a perturbation cannot be used, if it cannot: each value finite, ≥ 0 and at most
/// [`MAX_PERTURB_DEG`] / [`MAX_PERTURB_CM`]; the message names the option.
pub fn check_perturbation(deg: f64, cm: f64) -> Result<(), crate::error::ParseError> {
    for (name, value, most) in [
        ("--perturb-deg", deg, MAX_PERTURB_DEG),
        ("--perturb-cm", cm, MAX_PERTURB_CM),
    ] {
        if !(value.is_finite() && (0.0..=most).contains(&value)) {
            return Err(format!("{name} must be a number in [0, {most}], got {value}").into());
        }
    }
    Ok(())
}

/// Perturb every sensor by exactly `deg` about a random axis and `cm` along a random direction.
///
/// A sensor whose frame *is* the rig's vehicle frame is left alone: its extrinsic is the
/// identity by definition (PandaSet's trajectory is the Pandar64's own pose), so moving it
/// would not make a worse initial guess but a log whose trajectory and extrinsics disagree, by
/// up to the perturbation's angle times the drive's length between sweeps (docs/experiments/unical-real-pandaset.md, "Real
/// PandaSet end to end"). The other sensors' perturbations do not depend on whether it is
/// skipped.
pub fn perturb_rig(rig: &Rig, deg: f64, cm: f64, seed: u64) -> Rig {
    let mut out = rig.clone();
    for (k, s) in out.sensors.iter_mut().enumerate() {
        if !rig.vehicle_frame.is_empty() && s.frame_id == rig.vehicle_frame {
            continue;
        }
        let u =
            |j: u64| super::noise::hash3(k as i32, j as i32, 0, seed ^ 0x7E57) as f64 * 2.0 - 1.0;
        let axis = DVec3::new(u(0), u(1), u(2))
            .try_normalize()
            .unwrap_or(DVec3::X);
        let dir = DVec3::new(u(3), u(4), u(5))
            .try_normalize()
            .unwrap_or(DVec3::Y);
        let delta = Rigid::new(so3::exp(axis * deg.to_radians()), dir * (cm / 100.0));
        // Perturb in the vehicle frame: rotate about the sensor's origin, then shift.
        let t = s.vehicle_from_sensor;
        s.vehicle_from_sensor = Rigid::new(
            delta.rotation * t.rotation,
            t.translation + delta.translation,
        );
    }
    out
}

/// The longest drive `synthesize` writes (s): ten minutes of a six-camera rig already takes hours
/// to render on two cores.
pub const MAX_SECONDS: f64 = 600.0;

/// The smallest and largest image side `synthesize` renders (px, after `--scale`).
const MIN_IMAGE_SIDE_PX: f64 = 8.0;
const MAX_IMAGE_SIDE_PX: f64 = 16384.0;

/// Refuse settings that cannot make a drive, before any work, naming the option.
fn check_config(cfg: &SynthConfig) -> Result<(), SimError> {
    let bad = |what: String| Err(SimError::Config(what));
    if !(cfg.duration_secs > 0.2 && cfg.duration_secs <= MAX_SECONDS) {
        return bad(format!(
            "--seconds must be more than 0.2 and at most {MAX_SECONDS}, got {}",
            cfg.duration_secs
        ));
    }
    if !(cfg.scale > 0.0 && cfg.scale <= 4.0) {
        return bad(format!("--scale must be in (0, 4], got {}", cfg.scale));
    }
    if !(cfg.camera_rate_hz > 0.0 && cfg.camera_rate_hz <= 100.0) {
        return bad(format!(
            "--camera-hz must be in (0, 100], got {}",
            cfg.camera_rate_hz
        ));
    }
    check_perturbation(cfg.perturb_deg, cfg.perturb_cm)
        .map_err(|e| SimError::Config(e.to_string()))?;
    for camera in &cfg.rig.cameras {
        let (w, h) = (camera.intrinsics.width, camera.intrinsics.height);
        let (sw, sh) = (w as f64 * cfg.scale, h as f64 * cfg.scale);
        if sw.min(sh) < MIN_IMAGE_SIDE_PX || sw.max(sh) > MAX_IMAGE_SIDE_PX {
            return bad(format!(
                "camera '{}' ({w} × {h} px) would render at {sw:.0} × {sh:.0} px with --scale {}; each side must be {MIN_IMAGE_SIDE_PX}–{MAX_IMAGE_SIDE_PX} px",
                camera.name, cfg.scale
            ));
        }
    }
    Ok(())
}

/// Simulate and write the drive; `progress(done, total)` is called as frames complete.
pub fn synthesize(
    cfg: &SynthConfig,
    out_mcap: &Path,
    ground_truth_path: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SynthOutput, SimError> {
    check_config(cfg)?;
    // Both outputs are checked before the simulation, not after it.
    if crate::util::same_file(out_mcap, ground_truth_path) {
        return Err(SimError::Config(format!(
            "--out and --ground-truth are the same file ({}); the ground truth would overwrite the drive",
            out_mcap.display()
        )));
    }
    for (option, path) in [("--out", out_mcap), ("--ground-truth", ground_truth_path)] {
        crate::util::check_output(path)
            .map_err(|e| SimError::Config(format!("{option} {}: {e}", path.display())))?;
    }
    let rig = if (cfg.scale - 1.0).abs() > 1e-12 {
        cfg.rig.scaled(cfg.scale)
    } else {
        cfg.rig.clone()
    };
    let ground_truth = rig.to_rig();
    let initial = perturb_rig(&ground_truth, cfg.perturb_deg, cfg.perturb_cm, cfg.seed);

    // Trajectory at 100 Hz with a margin either side so every sensor time is covered.
    let margin = 0.2;
    let traj_cfg = TrajectoryConfig {
        kind: cfg.trajectory,
        duration_secs: cfg.duration_secs + 2.0 * margin,
        rate_hz: 100.0,
        speed_mps: 8.0,
        seed: cfg.seed,
    };
    let samples = trajectories::generate(&traj_cfg);
    let start = EPOCH_NANOS;
    let poses: Vec<(i64, Rigid)> = samples.iter().map(|(t, p)| (start + t, *p)).collect();
    let trajectory = Trajectory::new(poses.clone());
    let path = trajectories::path_polyline(&traj_cfg, 1.0);
    // Boards for tall rigs: how far the highest LiDAR sits above a car's (1.9 m).
    let highest_lidar_m = rig
        .lidars
        .iter()
        .map(|l| l.vehicle_from_lidar.translation.z)
        .fold(0.0, f64::max);
    let world = World::build_for_rig(cfg.scene, &path, cfg.seed, highest_lidar_m - 1.9);

    // Sweep stamps: every LiDAR period inside [margin + period/2, margin + duration - period/2].
    let lidar_hz = rig
        .lidars
        .iter()
        .map(|l| l.rotation_hz)
        .fold(10.0, f64::max);
    let period = 1.0 / lidar_hz;
    let n_sweeps = ((cfg.duration_secs / period).floor() as usize).max(1);
    let sweep_stamps: Vec<i64> = (0..n_sweeps)
        .map(|k| start + ((margin + period * (k as f64 + 0.5)) * 1e9) as i64)
        .collect();
    let camera_every = ((lidar_hz / cfg.camera_rate_hz.max(1e-3)).round() as usize).max(1);

    let mut writer = Ros2McapWriter::create(out_mcap)?;
    let vehicle = ground_truth.vehicle_frame.clone();
    let statics: Vec<(String, String, Rigid)> = initial
        .sensors
        .iter()
        .map(|s| (vehicle.clone(), s.frame_id.clone(), s.vehicle_from_sensor))
        .collect();
    writer.write_tf_static(start, &statics)?;
    for (t, p) in &poses {
        writer.write_tf(*t, "odom", &vehicle, *p)?;
    }
    let ray_tables: Vec<RayTable> = rig
        .cameras
        .iter()
        .map(|c| RayTable::new(&c.intrinsics))
        .collect();
    let total = n_sweeps;
    let (mut sweeps_written, mut images_written) = (0, 0);
    for (k, &stamp) in sweep_stamps.iter().enumerate() {
        // The frame's sweeps and (on camera frames) images are computed together, so neither
        // waits for the other's slowest part; they are written in a fixed order.
        let render_images = || -> Vec<Result<(i64, Vec<u8>), SimError>> {
            if k % camera_every != 0 {
                return Vec::new();
            }
            rig.cameras
                .par_iter()
                .zip(ray_tables.par_iter())
                .enumerate()
                .map(|(ci, (cam, rays))| {
                    let trigger = stamp + (cam.trigger_offset_secs * 1e9) as i64;
                    let world_from_camera =
                        trajectory.world_from_vehicle(trigger)? * cam.vehicle_from_camera;
                    let exposure = Exposure {
                        gain: cam.exposure_gain as f32,
                        tint: cam.tint_rgb.map(|v| v as f32),
                        noise_sigma: 2.0,
                        seed: cfg.seed ^ (trigger as u64) ^ ci as u64,
                    };
                    let img = camera_sim::render(
                        &world,
                        rays,
                        &cam.intrinsics,
                        world_from_camera,
                        exposure,
                    );
                    Ok((trigger, encode_jpeg(&img, cfg.jpeg_quality)?))
                })
                .collect()
        };
        let simulate_sweeps = || -> Vec<Result<_, _>> {
            rig.lidars
                .par_iter()
                .enumerate()
                .map(|(li, lidar)| {
                    lidar_sim::simulate_sweep(
                        &world,
                        lidar,
                        &trajectory,
                        stamp,
                        cfg.seed ^ (li as u64) << 32,
                    )
                })
                .collect()
        };
        let (sweeps, frames) = rayon::join(simulate_sweeps, render_images);
        for (lidar, sweep) in rig.lidars.iter().zip(sweeps) {
            let sweep = sweep?;
            let times = sweep.time_offset_secs.clone().unwrap_or_default();
            writer.write_pointcloud(
                &format!("/{}/points", lidar.name),
                stamp,
                &lidar.name,
                &sweep.points_in_sensor,
                &sweep.intensity,
                &times,
            )?;
            sweeps_written += 1;
        }
        for (cam, frame) in rig.cameras.iter().zip(frames) {
            let (trigger, jpeg) = frame?;
            writer.write_compressed_image(
                &format!("/{}/image/compressed", cam.name),
                trigger,
                &cam.name,
                "jpeg",
                &jpeg,
            )?;
            writer.write_camera_info(
                &format!("/{}/camera_info", cam.name),
                trigger,
                &cam.name,
                &cam.intrinsics,
            )?;
            images_written += 1;
        }
        progress(k + 1, total);
    }
    writer.finish()?;

    let mut file = CalibrationFile::from_rig(&ground_truth);
    let mut prov = std::collections::BTreeMap::new();
    prov.insert("source".into(), "rigcal synth (ground truth)".into());
    prov.insert("scene".into(), cfg.scene.as_str().into());
    prov.insert("rig".into(), cfg.rig.name.clone().into());
    prov.insert("trajectory".into(), cfg.trajectory.as_str().into());
    prov.insert("seconds".into(), cfg.duration_secs.into());
    prov.insert("seed".into(), cfg.seed.into());
    prov.insert("perturb_deg".into(), cfg.perturb_deg.into());
    prov.insert("perturb_cm".into(), cfg.perturb_cm.into());
    prov.insert("scale".into(), cfg.scale.into());
    prov.insert("mcap".into(), out_mcap.display().to_string().into());
    prov.insert("version".into(), env!("CARGO_PKG_VERSION").into());
    file.provenance = prov;
    file.save(ground_truth_path)?;
    Ok(SynthOutput {
        ground_truth,
        initial,
        sweeps: sweeps_written,
        images: images_written,
    })
}

/// Baseline JPEG, 4:2:0 chroma as camera drivers write it.
pub fn encode_jpeg(img: &image::RgbImage, quality: u8) -> Result<Vec<u8>, SimError> {
    let too_big = || {
        SimError::Image(format!(
            "{}×{} is too large for JPEG",
            img.width(),
            img.height()
        ))
    };
    let w = u16::try_from(img.width()).map_err(|_| too_big())?;
    let h = u16::try_from(img.height()).map_err(|_| too_big())?;
    let mut out = Vec::with_capacity(img.as_raw().len() / 8);
    let mut encoder = jpeg_encoder::Encoder::new(&mut out, quality);
    encoder.set_sampling_factor(jpeg_encoder::SamplingFactor::R_4_2_0);
    encoder
        .encode(img.as_raw(), w, h, jpeg_encoder::ColorType::Rgb)
        .map_err(|e| SimError::Image(e.to_string()))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::{Sensor, SensorKind};
    use crate::sim::rigs::RigPreset;

    fn sensor(name: &str, at: Rigid) -> Sensor {
        Sensor {
            name: name.into(),
            kind: SensorKind::Lidar,
            frame_id: name.into(),
            topics: Vec::new(),
            vehicle_from_sensor: at,
            camera: None,
        }
    }

    #[test]
    fn settings_that_cannot_make_a_drive_are_refused_by_name_before_any_work() {
        let dir = std::env::temp_dir().join(format!("rigcal-synth-cfg-{}", std::process::id()));
        let (mcap, gt) = (dir.join("never.mcap"), dir.join("never.yaml"));
        let base = || {
            SynthConfig::new(
                SceneKind::Urban,
                SimRig::preset(RigPreset::Pandaset),
                TrajectoryKind::Figure8,
                8.0,
                1,
            )
        };
        let cases: [(&str, Box<dyn Fn(&mut SynthConfig)>); 11] = [
            ("--seconds", Box::new(|c| c.duration_secs = 0.1)),
            ("--seconds", Box::new(|c| c.duration_secs = 1e9)),
            ("--seconds", Box::new(|c| c.duration_secs = f64::NAN)),
            ("--scale", Box::new(|c| c.scale = 0.0)),
            // Images of a pixel or less (the renderer needs rows to split).
            ("--scale", Box::new(|c| c.scale = 0.0001)),
            ("--camera-hz", Box::new(|c| c.camera_rate_hz = -5.0)),
            ("--perturb-deg", Box::new(|c| c.perturb_deg = f64::INFINITY)),
            ("--perturb-deg", Box::new(|c| c.perturb_deg = 1e160)),
            ("--perturb-cm", Box::new(|c| c.perturb_cm = -1.0)),
            ("--perturb-cm", Box::new(|c| c.perturb_cm = 1e6)),
            // A camera of a rig file larger than any made, at the default scale.
            (
                "--scale",
                Box::new(|c| {
                    c.rig.cameras[0].intrinsics.width = 200_000;
                }),
            ),
        ];
        for (name, change) in cases {
            let mut cfg = base();
            change(&mut cfg);
            let started = std::time::Instant::now();
            let err = synthesize(&cfg, &mcap, &gt, &mut |_, _| {}).unwrap_err();
            assert!(err.to_string().contains(name), "{name}: {err}");
            assert!(
                started.elapsed().as_secs_f64() < 1.0,
                "{name}: refused late"
            );
            assert!(!mcap.exists() && !gt.exists());
        }
        // The defaults pass the check.
        assert!(check_config(&base()).is_ok());
    }

    #[test]
    fn outputs_that_would_overwrite_each_other_or_cannot_be_written_are_refused_first() {
        let dir = std::env::temp_dir().join(format!("rigcal-synth-out-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cfg = SynthConfig::new(
            SceneKind::Urban,
            SimRig::preset(RigPreset::Pandaset),
            TrajectoryKind::Figure8,
            8.0,
            1,
        );
        let same = dir.join("drive.yaml");
        let missing_dir = dir.join("nope").join("gt.yaml");
        let cases = [
            (same.clone(), same.clone(), "same file"),
            (dir.join("drive.mcap"), missing_dir, "does not exist"),
            (dir.join("drive.mcap"), dir.clone(), "is a directory"),
        ];
        for (out, gt, why) in cases {
            let started = std::time::Instant::now();
            let err = synthesize(&cfg, &out, &gt, &mut |_, _| {}).unwrap_err();
            assert!(err.to_string().contains(why), "{why}: {err}");
            assert!(started.elapsed().as_secs_f64() < 1.0, "{why}: refused late");
            assert!(!out.exists() || out == dir);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn perturbation_is_exact_and_skips_the_vehicle_frames_own_sensor() {
        let offset = Rigid::new(
            so3::exp(DVec3::new(0.1, -0.2, 0.3)),
            DVec3::new(1.0, 0.5, 2.0),
        );
        let mut rig = Rig {
            vehicle_frame: "base_link".into(),
            sensors: vec![
                sensor("lidar_top", Rigid::IDENTITY),
                sensor("lidar_front", offset),
            ],
        };
        let moved = perturb_rig(&rig, 2.0, 20.0, 7);
        for (a, b) in rig.sensors.iter().zip(&moved.sensors) {
            let (rot, trans) = a.vehicle_from_sensor.difference(b.vehicle_from_sensor);
            assert!((rot.to_degrees() - 2.0).abs() < 1e-9, "{rot}");
            assert!((trans - 0.2).abs() < 1e-12, "{trans}");
        }
        // The trajectory is the top LiDAR's own pose: it stays, the other moves as before.
        rig.vehicle_frame = "lidar_top".into();
        let kept = perturb_rig(&rig, 2.0, 20.0, 7);
        assert_eq!(kept.sensors[0], rig.sensors[0]);
        assert_eq!(kept.sensors[1], moved.sensors[1]);
    }
}
