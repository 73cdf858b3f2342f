//! The pipeline's whole configuration: one serde type with nested sections, each default
//! stated once (the UniCal section is [`DepthCalibConfig::default`]).
//!
//! `rigcal calibrate --print-config` prints it as YAML, `--config FILE` reads it back (a key
//! not named here is an error naming the key), and every run records the configuration it
//! resolved in its output's provenance, so `--config previous-output.yaml` repeats the run.
//! The few values a quality preset and the time budget choose (images per camera, their scale,
//! the number of steps) are `None` until the plan resolves them ([`super::plan::Plan`]).

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::error::ParseError;
use crate::unical::depth_calib::DepthCalibConfig;

/// How hard the pipeline works: the images, their scale, the steps and the time budget it
/// plans for when they are not given.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Quality {
    /// A quick look: a few minutes.
    Fast,
    /// What the default drive needs to come within a few centimetres: at most 10 minutes on
    /// two cores.
    #[default]
    Default,
    /// The paper's longer schedule, without a time budget.
    Paper,
}

/// What a [`Quality`] plans for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QualityPreset {
    pub images_per_camera: usize,
    pub image_scale: f64,
    pub iterations: usize,
    /// `None`: no budget.
    pub budget_secs: Option<f64>,
}

impl Quality {
    pub fn preset(self) -> QualityPreset {
        match self {
            Quality::Fast => QualityPreset {
                images_per_camera: 8,
                image_scale: 0.125,
                iterations: 500,
                budget_secs: Some(240.0),
            },
            Quality::Default => QualityPreset {
                images_per_camera: 16,
                image_scale: 0.25,
                iterations: 1000,
                budget_secs: Some(600.0),
            },
            Quality::Paper => QualityPreset {
                images_per_camera: 32,
                image_scale: 0.25,
                iterations: 2000,
                budget_secs: None,
            },
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Quality::Fast => "fast",
            Quality::Default => "default",
            Quality::Paper => "paper",
        }
    }
}

impl std::str::FromStr for Quality {
    type Err = ParseError;

    fn from_str(text: &str) -> Result<Self, ParseError> {
        match text {
            "fast" => Ok(Quality::Fast),
            "default" => Ok(Quality::Default),
            "paper" => Ok(Quality::Paper),
            other => Err(ParseError::new(format!(
                "unknown quality '{other}' (expected fast, default or paper)"
            ))),
        }
    }
}

/// Whether the cameras are fitted to their own motion before UniCal.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HandEye {
    /// Where the drive turns enough; a fit is kept where the camera's edges align with the
    /// reference LiDAR's at least as well as at its start.
    #[default]
    Auto,
    Always,
    Never,
}

/// The LiDAR stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LidarSettings {
    /// Register the LiDARs classically first (the reference to the trajectory where the drive
    /// turns enough, every other one to the reference by point-to-plane ICP) and hold them
    /// while UniCal calibrates the cameras; `false`: UniCal moves the LiDARs too.
    pub register: bool,
    /// Sweeps of each LiDAR the ICP registers.
    pub icp_sweeps: usize,
    /// Sweeps of the reference LiDAR fitted to the trajectory.
    pub trajectory_sweeps: usize,
    /// Sweeps per LiDAR spread over the drive that shape UniCal's scene, besides the one nearest
    /// each image the cameras are fitted on (`unical::scene_sweeps`).
    pub scene_sweeps: usize,
}

impl Default for LidarSettings {
    fn default() -> Self {
        Self {
            register: true,
            icp_sweeps: 3,
            trajectory_sweeps: 10,
            scene_sweeps: 4,
        }
    }
}

/// The camera stage.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraSettings {
    pub hand_eye: HandEye,
    /// Images per camera UniCal trains on (`None`: the quality's).
    pub images_per_camera: Option<usize>,
    /// The scale the images are used at, in (0, 1] (`None`: the quality's).
    pub image_scale: Option<f64>,
    /// A rolling shutter: the first and last image rows were exposed this many milliseconds
    /// after each stamp (`None`: a global shutter).
    pub readout_ms: Option<(f64, f64)>,
    /// A known delay added to every image's stamp (ms).
    pub time_offset_ms: f64,
}

/// Everything the pipeline can be told.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PipelineConfig {
    pub quality: Quality,
    /// The run's wall-time budget in seconds (`None`: the quality's). The plan fits the steps
    /// to it, and the run stops at it.
    pub budget_secs: Option<f64>,
    /// Seed of every random choice: one seed, one result at a fixed thread count.
    pub seed: u64,
    /// UniCal's steps (`None`: the quality's, fitted to the budget).
    pub iterations: Option<usize>,
    /// Stop the run after this many steps, whatever the schedule (what a run the budget
    /// stopped records, so that its configuration repeats it).
    pub stop_at_step: Option<usize>,
    /// Where the budget shortened UniCal's schedule: at step `k` (the first of each pair) the
    /// run went on to `n` steps in all (the second), its rates decaying and its hash levels
    /// opening to the new end. A run records the shortenings it made; given here they are
    /// applied at those steps and the budget is not measured again (the run repeats).
    pub budget_cuts: Vec<(usize, usize)>,
    pub lidars: LidarSettings,
    pub cameras: CameraSettings,
    /// UniCal's scene and optimiser (the run-time parts — root, held sensors, steps, seed —
    /// come from the plan).
    pub unical: DepthCalibConfig,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            quality: Quality::default(),
            budget_secs: None,
            seed: 1,
            iterations: None,
            stop_at_step: None,
            budget_cuts: Vec::new(),
            lidars: LidarSettings::default(),
            cameras: CameraSettings::default(),
            unical: DepthCalibConfig::default(),
        }
    }
}

/// A configuration that cannot be used.
#[derive(Debug, Error, PartialEq)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read {path}: {message}")]
    Read { path: String, message: String },
    /// The YAML does not describe a configuration (an unknown key, a wrong type).
    #[error("{path}: {message}")]
    Parse { path: String, message: String },
    /// A value outside what it can be.
    #[error("{key}: {message}")]
    Value { key: &'static str, message: String },
}

impl PipelineConfig {
    /// Read a configuration from YAML: a `--print-config` output, or the `provenance.config`
    /// of a calibration file rigcal wrote (so an output repeats its run). `path` names the
    /// source in errors.
    pub fn from_yaml(text: &str, path: &str) -> Result<Self, ConfigError> {
        let value: serde_yaml::Value =
            crate::calib::yaml::from_str(text).map_err(|e| ConfigError::Parse {
                path: path.to_string(),
                message: one_line(&e.to_string()),
            })?;
        // A calibration file: its provenance holds the configuration of the run.
        let value = match value.get("rigcal_calibration") {
            Some(_) => match value.get("provenance").and_then(|p| p.get("config")) {
                Some(config) if config.get("method").is_none() => config.clone(),
                _ => {
                    return Err(ConfigError::Parse {
                        path: path.to_string(),
                        message: "this calibration file records no pipeline configuration (it was written by a single method or an older rigcal)".into(),
                    });
                }
            },
            None => value,
        };
        // The path of the key at fault (`cameras.image_scale`) leads the message.
        let config: PipelineConfig =
            serde_path_to_error::deserialize(value).map_err(|e| ConfigError::Parse {
                path: path.to_string(),
                message: format!("{}: {}", e.path(), one_line(&e.inner().to_string())),
            })?;
        config.check()?;
        Ok(config)
    }

    /// Read a configuration file.
    pub fn load(path: &std::path::Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError::Read {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        Self::from_yaml(&text, &path.display().to_string())
    }

    /// The configuration as YAML.
    pub fn to_yaml(&self) -> String {
        serde_yaml::to_string(self).unwrap_or_default()
    }

    /// Values outside what they can be, named by their key.
    pub fn check(&self) -> Result<(), ConfigError> {
        let bad = |key, message: &str| {
            Err(ConfigError::Value {
                key,
                message: message.to_string(),
            })
        };
        if let Some(b) = self.budget_secs
            && !(b.is_finite() && b > 0.0)
        {
            return bad("budget_secs", "expected a number of seconds above 0");
        }
        if self.iterations == Some(0) {
            return bad("iterations", "expected at least one step");
        }
        if let Some(s) = self.cameras.image_scale
            && !(s.is_finite() && s > 0.0 && s <= 1.0)
        {
            return bad("cameras.image_scale", "expected a scale in (0, 1]");
        }
        if self.cameras.images_per_camera == Some(0) {
            return bad(
                "cameras.images_per_camera",
                "expected at least one image (leave the cameras out with --sensors)",
            );
        }
        if !(self.cameras.time_offset_ms.is_finite() && self.cameras.time_offset_ms.abs() <= 1000.0)
        {
            return bad(
                "cameras.time_offset_ms",
                "expected milliseconds within ±1000",
            );
        }
        if let Some((a, b)) = self.cameras.readout_ms
            && !(a.is_finite() && b.is_finite() && a.abs() <= 1000.0 && b.abs() <= 1000.0)
        {
            return bad("cameras.readout_ms", "expected milliseconds within ±1000");
        }
        if self.lidars.icp_sweeps == 0
            || self.lidars.trajectory_sweeps < 2
            || self.lidars.scene_sweeps == 0
        {
            return bad(
                "lidars",
                "expected at least one sweep each (two for the trajectory)",
            );
        }
        self.check_unical()
    }

    /// UniCal's settings a run could not use.
    fn check_unical(&self) -> Result<(), ConfigError> {
        let u = &self.unical;
        let bad = |key, message: &str| {
            Err(ConfigError::Value {
                key,
                message: message.to_string(),
            })
        };
        let within = |v: f64, lo: f64, hi: f64| v.is_finite() && v >= lo && v <= hi;
        if u.rays_per_camera == 0 || u.rays_per_sensor == 0 {
            return bad(
                "unical.rays_per_camera, unical.rays_per_sensor",
                "expected at least one ray",
            );
        }
        if !(u.lr_camera_pose.is_finite() && u.lr_camera_pose > 0.0) {
            return bad("unical.lr_camera_pose", "expected a rate above 0");
        }
        if !(u.camera_translation_rate.is_finite() && u.camera_translation_rate >= 0.0) {
            return bad(
                "unical.camera_translation_rate",
                "expected a multiple of 0 or more",
            );
        }
        if let Some(f) = u.camera_translation_final_fraction
            && !(f.is_finite() && f > 0.0 && f <= 1.0)
        {
            return bad(
                "unical.camera_translation_final_fraction",
                "expected a fraction in (0, 1]",
            );
        }
        if !(u.alignment_release_rate > 0.0 && u.alignment_release_rate <= 1.0) {
            return bad(
                "unical.alignment_release_rate",
                "expected a fraction in (0, 1]",
            );
        }
        if let Some(r) = u.camera_hold_unobserved
            && !(r.is_finite() && r > 0.0 && r < 1.0)
        {
            return bad(
                "unical.camera_hold_unobserved",
                "expected a fraction in (0, 1)",
            );
        }
        if !within(u.silhouette_share, 0.0, 1.0) {
            return bad("unical.silhouette_share", "expected a fraction from 0 to 1");
        }
        if let Some(l) = u.colour_pose_levels
            && !within(f64::from(l), 0.0, 64.0)
        {
            return bad("unical.colour_pose_levels", "expected levels from 0 to 64");
        }
        if !(12..=24).contains(&u.field.grid.log2_table_size) {
            return bad(
                "unical.field.grid.log2_table_size",
                "expected a power of two from 12 to 24",
            );
        }
        if !within(f64::from(u.pose_average_fraction), 0.0, 1.0) {
            return bad(
                "unical.pose_average_fraction",
                "expected a fraction of the run from 0 to 1",
            );
        }
        if let Some(r) = u.scene_radius_m
            && !(r.is_finite() && r >= 5.0)
        {
            return bad(
                "unical.scene_radius_m",
                "expected a distance of 5 m or more",
            );
        }
        if let Some(c) = u.coarse_to_fine
            && !(c.start_levels >= 1.0 && c.end_fraction > 0.0 && c.end_fraction <= 1.0)
        {
            return bad(
                "unical.coarse_to_fine",
                "expected start_levels ≥ 1 and end_fraction in (0, 1]",
            );
        }
        Ok(())
    }
}

/// Parse a duration: `90` or `90s` (seconds), `10m`, `1h`, `1h30m`.
pub fn parse_duration_secs(text: &str) -> Result<f64, ParseError> {
    let bad = || {
        ParseError::new(format!(
            "'{text}': expected a duration such as 600, 600s, 10m or 1h30m"
        ))
    };
    let t = text.trim();
    if t.is_empty() {
        return Err(bad());
    }
    if let Ok(secs) = t.parse::<f64>() {
        return (secs.is_finite() && secs > 0.0)
            .then_some(secs)
            .ok_or_else(bad);
    }
    let (mut total, mut number) = (0.0, String::new());
    for c in t.chars() {
        if c.is_ascii_digit() || c == '.' {
            number.push(c);
            continue;
        }
        let unit = match c {
            'h' => 3600.0,
            'm' => 60.0,
            's' => 1.0,
            _ => return Err(bad()),
        };
        let n: f64 = number.parse().map_err(|_| bad())?;
        total += n * unit;
        number.clear();
    }
    if !(number.is_empty() && total.is_finite() && total > 0.0) {
        return Err(bad());
    }
    Ok(total)
}

/// serde_yaml's message on one line.
fn one_line(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_printed_configuration_reads_back_as_itself() {
        let mut config = PipelineConfig {
            quality: Quality::Fast,
            budget_secs: Some(120.0),
            seed: 9,
            ..PipelineConfig::default()
        };
        config.cameras.readout_ms = Some((-30.0, 10.0));
        config.unical.silhouette_share = 0.25;
        let text = config.to_yaml();
        assert_eq!(PipelineConfig::from_yaml(&text, "c.yaml").unwrap(), config);
        // An empty file is the default configuration.
        assert_eq!(
            PipelineConfig::from_yaml("{}", "c.yaml").unwrap(),
            PipelineConfig::default()
        );
    }

    #[test]
    fn a_bad_configuration_names_the_key() {
        let e = PipelineConfig::from_yaml("cameras:\n  image_scael: 0.5\n", "c.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("image_scael") && e.contains("c.yaml"), "{e}");
        assert!(!e.contains('\n'), "{e}");
        let e = PipelineConfig::from_yaml("seed: many\n", "c.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("seed") && !e.contains('\n'), "{e}");
        let e = PipelineConfig::from_yaml("unical:\n  rays_per_camera: -3\n", "c.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("rays_per_camera"), "{e}");
        let e = PipelineConfig::from_yaml("cameras:\n  image_scale: 3\n", "c.yaml")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "cameras.image_scale: expected a scale in (0, 1]");
        for (yaml, key) in [
            ("unical:\n  lr_camera_pose: 0\n", "unical.lr_camera_pose"),
            (
                "unical:\n  silhouette_share: 1.5\n",
                "unical.silhouette_share",
            ),
            ("unical:\n  scene_radius_m: 4\n", "unical.scene_radius_m"),
            (
                "unical:\n  field:\n    grid:\n      log2_table_size: 30\n",
                "unical.field.grid.log2_table_size",
            ),
            (
                "unical:\n  camera_hold_unobserved: 1\n",
                "unical.camera_hold_unobserved",
            ),
        ] {
            let e = PipelineConfig::from_yaml(yaml, "c.yaml")
                .unwrap_err()
                .to_string();
            assert!(e.starts_with(key), "{e}");
        }
    }

    #[test]
    fn durations_read_in_seconds_minutes_and_hours() {
        assert_eq!(parse_duration_secs("600").unwrap(), 600.0);
        assert_eq!(parse_duration_secs("90s").unwrap(), 90.0);
        assert_eq!(parse_duration_secs("10m").unwrap(), 600.0);
        assert_eq!(parse_duration_secs("1h30m").unwrap(), 5400.0);
        for bad in ["", "0", "-5", "10x", "m", "5m3"] {
            assert!(parse_duration_secs(bad).is_err(), "{bad}");
        }
    }

    /// The leaf keys of a serialised configuration as dotted paths (a tagged enum's fields
    /// under its own key).
    fn leaf_keys(prefix: &str, value: &serde_yaml::Value, out: &mut Vec<String>) {
        match value {
            serde_yaml::Value::Mapping(m) if !m.is_empty() => {
                for (k, v) in m {
                    let k = k.as_str().unwrap_or_default();
                    let path = if prefix.is_empty() {
                        k.to_owned()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    leaf_keys(&path, v, out);
                }
            }
            serde_yaml::Value::Tagged(t) => leaf_keys(prefix, &t.value, out),
            _ => out.push(prefix.to_owned()),
        }
    }

    /// docs/configuration.md documents every key of the configuration, and no key that does
    /// not exist (optional sections counted with their fields).
    #[test]
    fn the_configuration_reference_names_every_key_and_only_real_ones() {
        let doc = include_str!("../../docs/configuration.md");
        let documented: std::collections::BTreeSet<String> = doc
            .lines()
            .filter_map(|l| l.strip_prefix("| `"))
            .filter_map(|l| l.split('`').next())
            .map(str::to_owned)
            .collect();
        let mut keys = Vec::new();
        leaf_keys(
            "",
            &serde_yaml::to_value(PipelineConfig::default()).unwrap(),
            &mut keys,
        );
        for k in &keys {
            assert!(
                documented.contains(k),
                "docs/configuration.md does not document `{k}`"
            );
        }
        // Every key of the optional sections, when they are set.
        let mut full = PipelineConfig::default();
        full.unical.transient_returns = Some(Default::default());
        full.unical.lidar_pose_update =
            crate::unical::pose_newton::PoseUpdate::Newton(Default::default());
        let mut all = Vec::new();
        leaf_keys("", &serde_yaml::to_value(&full).unwrap(), &mut all);
        all.extend(keys);
        // A section that can be set to `null` (`unical.coarse_to_fine`) is a key too.
        for d in &documented {
            let section = format!("{d}.");
            assert!(
                all.iter().any(|k| k == d || k.starts_with(&section)),
                "docs/configuration.md documents `{d}`, which the configuration does not have"
            );
        }
    }
}
