//! What `rigcal calibrate` takes: its options, defined once here (clap derives the flags and
//! their help from this type; docs/cli.md lists them and a test checks the list), and the
//! options that moved to the configuration file, so that typing one says where it went.

use super::CliError;
use std::path::{Path, PathBuf};

/// Typical `calibrate` commands, printed after its options.
pub const CALIBRATE_EXAMPLES: &str = "\
Examples:
  # Every LiDAR and camera: the pipeline plans its stages from the drive and says why
  rigcal calibrate drive.mcap --out calib.yaml
  # From your own initial guess, with a longer schedule
  rigcal calibrate drive.mcap --init guess.urdf --quality paper --out calib.yaml
  # Every setting in one file: print it, edit it, run with it (or repeat an earlier output)
  rigcal calibrate --print-config > rigcal.yaml
  rigcal calibrate drive.mcap --config rigcal.yaml --out calib.yaml
  # LiDARs only, by point-to-plane ICP against the first LiDAR
  rigcal calibrate drive.mcap --method icp --out lidars.yaml
  # Then measure and export
  rigcal eval --ground-truth gt.yaml --calibration calib.yaml drive.mcap
  rigcal export calib.yaml --format ros2-launch --out static_tf.launch.xml

The output is written before the first step and every 30 s (status: running: step k of n),
so an interrupted run keeps its latest result.";

// What `rigcal calibrate` was asked to do (a plain comment: clap would take a doc comment here
// for the subcommand's description, which main.rs gives).
#[derive(Clone, Debug, Default, clap::Args)]
pub struct CalibrateArgs {
    /// The drive (MCAP, ROS 2 or Foxglove schemas).
    #[arg(required_unless_present = "print_config")]
    pub log: Option<PathBuf>,
    /// The native calibration file to write (atomically; see the note below).
    #[arg(long, required_unless_present = "print_config")]
    pub out: Option<PathBuf>,
    /// auto (the default: the pipeline, every LiDAR and camera) | unical (UniCal alone,
    /// every sensor in one scene) | icp | mi | target | pose-graph | edge
    #[arg(long, default_value = "auto")]
    pub method: String,
    /// Initial guess: a native calibration file, URDF, ROS camera_info YAML (or a directory
    /// of them) or an MCAP's /tf_static; sensors matched by name or frame id. Default: the
    /// log's /tf_static.
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// Time range in seconds from the start of the log, START..END.
    #[arg(long, allow_hyphen_values = true)]
    pub segment: Option<String>,
    /// Sensors to calibrate, comma-separated (default: all the method handles); the
    /// others stay where the initial guess puts them.
    #[arg(long, value_delimiter = ',')]
    pub sensors: Vec<String>,
    /// A sensor whose extrinsic stays fixed; for the pipeline and the classical methods,
    /// the reference LiDAR (default the first, which the pipeline fits to the trajectory).
    #[arg(long)]
    pub root: Option<String>,
    /// fast | default (at most about 10 minutes on two cores) | paper (the longer
    /// schedule, no time budget): images per camera, their scale and UniCal's steps.
    #[arg(long)]
    pub quality: Option<crate::pipeline::Quality>,
    /// The run's time budget, e.g. 600, 10m, 1h (default: the quality's); the plan fits its
    /// steps to it and the run stops at it.
    #[arg(long = "budget", value_name = "DURATION", value_parser = crate::pipeline::config::parse_duration_secs)]
    pub budget_secs: Option<f64>,
    /// The whole configuration as YAML (every UniCal setting, the cameras' rolling shutter
    /// and delay): a --print-config output, or an earlier output file (its run repeated).
    #[arg(long = "config", value_name = "FILE")]
    pub config_file: Option<PathBuf>,
    /// Print the configuration (--config, --quality, --budget and --seed applied) as YAML
    /// and exit.
    #[arg(long)]
    pub print_config: bool,
    /// Optimisation steps (UniCal: default the quality's; mi, target and edge have their own,
    /// and edge with 0 writes the initial guess as it is); icp and pose-graph run until they
    /// converge.
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Seed of every random choice (ray draws, RANSAC, --perturb-*): one seed, one result
    /// at a fixed thread count (default 1).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Move every sensor of the initial guess by exactly this many degrees about a random
    /// axis (drawn from --seed), to measure recovery from a known start.
    #[arg(long, default_value_t = 0.0)]
    pub perturb_deg: f64,
    /// Move every sensor of the initial guess by exactly this many centimetres along a random
    /// direction (drawn from --seed).
    #[arg(long, default_value_t = 0.0)]
    pub perturb_cm: f64,
}

impl CalibrateArgs {
    /// The drive (empty only with `--print-config`, which reads none).
    pub fn log(&self) -> &Path {
        self.log.as_deref().unwrap_or(Path::new(""))
    }

    /// The file to write (empty only with `--print-config`).
    pub fn out(&self) -> &Path {
        self.out.as_deref().unwrap_or(Path::new(""))
    }

    /// The seed of every random choice: `--seed`, else 1.
    pub fn seed(&self) -> u64 {
        self.seed.unwrap_or(1)
    }

    /// What a classical run was asked to do, for the file's provenance: the method as
    /// `--method` names it, the seed, and every option given, keyed by the option's name with
    /// underscores, so the run can be repeated from its output.
    pub fn config(&self) -> serde_yaml::Mapping {
        use serde_yaml::Value;
        let mut m = serde_yaml::Mapping::new();
        let mut put = |key: &str, value: Value| {
            m.insert(Value::String(key.into()), value);
        };
        put("method", Value::String(self.method.clone()));
        put("seed", Value::from(self.seed()));
        if let Some(n) = self.iterations {
            put("iterations", Value::from(n as u64));
        }
        if !self.sensors.is_empty() {
            put("sensors", Value::String(self.sensors.join(",")));
        }
        if let Some(root) = &self.root {
            put("root", Value::String(root.clone()));
        }
        m
    }

    /// The perturbation of the initial guess when there is a valid one.
    pub(crate) fn perturb_given(&self) -> Option<(f64, f64)> {
        self.perturbation().ok().flatten()
    }

    /// The perturbation of the initial guess, `None` when there is none; an error for
    /// negative, non-finite or too large values.
    pub(crate) fn perturbation(&self) -> Result<Option<(f64, f64)>, CliError> {
        let (deg, cm) = (self.perturb_deg, self.perturb_cm);
        crate::sim::synth::check_perturbation(deg, cm)?;
        Ok((deg > 0.0 || cm > 0.0).then_some((deg, cm)))
    }
}

/// `calibrate`'s options that moved to the configuration file (0.2), and their keys.
const MOVED_TO_CONFIG: [(&str, &str); 28] = [
    ("--camera-frames", "cameras.images_per_camera"),
    ("--camera-scale", "cameras.image_scale"),
    ("--camera-hand-eye", "cameras.hand_eye: always"),
    ("--camera-readout-ms", "cameras.readout_ms: [FIRST, LAST]"),
    ("--camera-time-offset-ms", "cameras.time_offset_ms"),
    ("--lidar-icp", "lidars.register"),
    ("--lidar-sweeps", "lidars.scene_sweeps"),
    ("--alignment", "unical.alignment"),
    ("--camera-rays", "unical.rays_per_camera"),
    ("--camera-lr", "unical.lr_camera_pose"),
    (
        "--camera-translation-rate",
        "unical.camera_translation_rate",
    ),
    (
        "--camera-translation-final",
        "unical.camera_translation_final_fraction",
    ),
    ("--camera-early-release", "unical.alignment_release"),
    ("--coarse-to-fine", "unical.coarse_to_fine"),
    ("--hash-table-log2", "unical.field.grid.log2_table_size"),
    ("--pose-average", "unical.pose_average_fraction"),
    ("--scene-radius", "unical.scene_radius_m"),
    ("--cubic-scene-box", "unical.field.cubic_box"),
    (
        "--drop-moving",
        "unical.transient_returns and unical.mask_own_vehicle",
    ),
    ("--silhouette-share", "unical.silhouette_share"),
    ("--camera-hold-unobserved", "unical.camera_hold_unobserved"),
    ("--camera-hold-axial", "unical.camera_hold_axial"),
    (
        "--shared-camera-translation",
        "unical.shared_camera_translation",
    ),
    (
        "--camera-rays-below-lidar-top",
        "unical.camera_rays_below_lidar_top",
    ),
    ("--colour-pose-levels", "unical.colour_pose_levels"),
    ("--rounds", "nothing: it was removed"),
    ("--grouped-camera-translation", "nothing: it was removed"),
    ("--camera-blur", "nothing: it was removed"),
];

/// For an option `calibrate` does not know (`--camera-frames=8` or `--camera-frames`) that
/// moved to the configuration file, where it went.
pub fn moved_option(arg: &str) -> Option<String> {
    let flag = arg.split('=').next().unwrap_or(arg);
    MOVED_TO_CONFIG
        .iter()
        .find(|(f, _)| *f == flag)
        .map(|(f, key)| {
            format!(
                "{f} is no longer an option of calibrate: its setting is {key} in the configuration file (rigcal calibrate --print-config prints it; --config FILE reads it)"
            )
        })
}

#[cfg(test)]
mod tests {
    use super::moved_option;

    #[test]
    fn a_moved_option_names_its_key_with_or_without_a_value() {
        let said = moved_option("--camera-frames=8").unwrap_or_default();
        assert!(said.contains("cameras.images_per_camera"), "{said}");
        assert_eq!(moved_option("--camera-frames"), Some(said));
        assert_eq!(moved_option("--frobnicate"), None);
    }
}
