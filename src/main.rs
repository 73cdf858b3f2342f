//! The `rigcal` command line: argument parsing and dispatch only (docs/interfaces.md).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "rigcal",
    version,
    about = "Calibrate every LiDAR and camera on a vehicle from an ordinary drive"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

/// Typical `calibrate` commands, printed after its options.
const CALIBRATE_EXAMPLES: &str = "\
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

// Parsed once at start-up: the calibrate variant's many options cost nothing worth boxing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
enum Command {
    /// The studio (the default when no command is given).
    Studio {
        /// The log to open (default: the embedded demo drive).
        log: Option<PathBuf>,
        /// An initial calibration: a native file, URDF, ROS camera_info YAML or an MCAP's
        /// /tf_static (default: the log's /tf_static).
        #[arg(long)]
        calibration: Option<PathBuf>,
        /// Restore a saved session (its log, edits, segments, locks and view).
        #[arg(long)]
        session: Option<PathBuf>,
    },
    /// Sensors, topics, counts, rates, time range, TF tree and problems of a log.
    Inspect {
        /// The log (MCAP, ROS 2 or Foxglove schemas).
        log: PathBuf,
        /// Fixed frame of the trajectory (default: the parent of the densest /tf edge).
        #[arg(long)]
        fixed_frame: Option<String>,
        /// The vehicle frame (default: the child of that edge).
        #[arg(long)]
        vehicle_frame: Option<String>,
    },
    /// Calibrate a drive and write the native calibration file.
    #[command(after_help = CALIBRATE_EXAMPLES, allow_negative_numbers = true)]
    Calibrate {
        /// The drive (MCAP, ROS 2 or Foxglove schemas).
        #[arg(required_unless_present = "print_config")]
        log: Option<PathBuf>,
        /// The native calibration file to write (atomically; see the note below).
        #[arg(long, required_unless_present = "print_config")]
        out: Option<PathBuf>,
        /// auto (the default: the pipeline, every LiDAR and camera) | unical (UniCal alone,
        /// every sensor in one scene) | icp | mi | target | pose-graph | edge
        #[arg(long, default_value = "auto")]
        method: String,
        /// Initial guess: a native calibration file, URDF, ROS camera_info YAML (or a directory
        /// of them) or an MCAP's /tf_static; sensors matched by name or frame id. Default: the
        /// log's /tf_static.
        #[arg(long)]
        init: Option<PathBuf>,
        /// Time range in seconds from the start of the log, START..END.
        #[arg(long, allow_hyphen_values = true)]
        segment: Option<String>,
        /// Sensors to calibrate, comma-separated (default: all the method handles); the
        /// others stay where the initial guess puts them.
        #[arg(long, value_delimiter = ',')]
        sensors: Vec<String>,
        /// A sensor whose extrinsic stays fixed; for the pipeline and the classical methods,
        /// the reference LiDAR (default the first, which the pipeline fits to the trajectory).
        #[arg(long)]
        root: Option<String>,
        /// fast | default (at most about 10 minutes on two cores) | paper (the longer
        /// schedule, no time budget): images per camera, their scale and UniCal's steps.
        #[arg(long)]
        quality: Option<String>,
        /// The run's time budget, e.g. 600, 10m, 1h (default: the quality's); the plan fits its
        /// steps to it and the run stops at it.
        #[arg(long, value_name = "DURATION")]
        budget: Option<String>,
        /// The whole configuration as YAML (every UniCal setting, the cameras' rolling shutter
        /// and delay): a --print-config output, or an earlier output file (its run repeated).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        /// Print the configuration (--config, --quality, --budget and --seed applied) as YAML
        /// and exit.
        #[arg(long)]
        print_config: bool,
        /// Optimisation steps (UniCal: default the quality's; mi, target and edge have their own,
        /// and edge with 0 writes the initial guess as it is); icp and pose-graph run until they
        /// converge.
        #[arg(long)]
        iterations: Option<usize>,
        /// Seed of every random choice (ray draws, RANSAC, --perturb-*): one seed, one result
        /// at a fixed thread count (default 1).
        #[arg(long)]
        seed: Option<u64>,
        /// Move every sensor of the initial guess by exactly this many degrees about a random
        /// axis (drawn from --seed), to measure recovery from a known start.
        #[arg(long, default_value_t = 0.0)]
        perturb_deg: f64,
        /// Move every sensor of the initial guess by exactly this many centimetres along a random
        /// direction (drawn from --seed).
        #[arg(long, default_value_t = 0.0)]
        perturb_cm: f64,
    },
    /// Measure a calibration against a reference: pose errors after root alignment, and with a
    /// log the LiDAR–LiDAR, edge-alignment (and checkerboard, photometric) metrics on the data.
    Eval {
        /// The reference: a native calibration file or a dataset's ground_truth.json.
        #[arg(long)]
        ground_truth: PathBuf,
        /// The calibration to measure (native file).
        #[arg(long)]
        calibration: PathBuf,
        /// A log to measure the alignment on.
        log: Option<PathBuf>,
        /// Root sensor for the alignment (default: the reference's first LiDAR).
        #[arg(long)]
        root: Option<String>,
        /// Frames per sensor pair for the data metrics (1–1000).
        #[arg(long, default_value_t = 3)]
        frames: usize,
        /// Also measure the checkerboard corner re-projection error (logs with boards).
        #[arg(long)]
        checkerboard: bool,
        /// Also measure every camera's photometric consistency over the LiDAR map (texture-free)
        /// and the image delay at which it is best
        #[arg(long)]
        photometric: bool,
        /// With a log: the cameras have a rolling shutter whose readout began FIRST and ended
        /// LAST milliseconds after each image's stamp (as calibrate's option of that name), for
        /// the edge-alignment and photometric metrics
        #[arg(long, value_name = "FIRST..LAST", allow_hyphen_values = true)]
        camera_readout_ms: Option<String>,
        /// Also write the report as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Run the paper's evaluation protocols on simulated drives and the PandaSet drive; write
    /// Markdown tables, CSV, JSON and PNG plots.
    Bench {
        /// quick (≤ 10 minutes on two cores, release build) | paper (the full protocol: a day or more)
        #[arg(long, default_value = "quick")]
        suite: String,
        /// Folder for the tables, CSV, JSON, plots and the simulated drives.
        #[arg(long, default_value = "bench-out")]
        out: PathBuf,
        /// Folder of the PandaSet drive (pandaset-002.mcap + ground_truth.json); skipped when
        /// it is not there.
        #[arg(long, default_value = "../shared/data/pandaset-002")]
        pandaset: PathBuf,
        /// Seeds per perturbation level (default: the suite's).
        #[arg(long)]
        seeds: Option<u64>,
    },
    /// Write a calibration in another tool's format; every file names the direction of the
    /// transforms it holds.
    Export {
        /// The native calibration file.
        calibration: PathBuf,
        /// native | camera-info | mcap | urdf | ros2-static-tf | ros2-launch | autoware | opencv
        /// | kalibr | kitti | nuscenes
        #[arg(long)]
        format: String,
        /// The file to write; for camera-info and opencv a directory (one file per camera).
        #[arg(long)]
        out: PathBuf,
        /// Only these sensors, comma-separated (default: all).
        #[arg(long, value_delimiter = ',')]
        sensors: Vec<String>,
        /// opencv, kitti: the reference LiDAR (default: the first).
        #[arg(long)]
        lidar: Option<String>,
        /// kitti, kalibr: the reference camera, cam0 (default: the first).
        #[arg(long)]
        camera: Option<String>,
    },
    /// Simulate a drive with known ground truth and write it as a ROS 2 MCAP.
    // A negative number is a value to check, not an unknown flag.
    #[command(allow_negative_numbers = true)]
    Synth {
        /// urban | parking-lot | featureless | checkerboard
        #[arg(long, default_value = "urban")]
        scene: String,
        /// pandaset | truck | kitti, or a native calibration file
        #[arg(long, default_value = "pandaset")]
        rig: String,
        /// straight | circle | s-curve | figure8 | flower | stationary
        #[arg(long, default_value = "figure8")]
        trajectory: String,
        /// Length of the drive (seconds).
        #[arg(long, default_value_t = 8.0)]
        seconds: f64,
        /// Seed of the scene's layout and textures, the trajectory's variation and the
        /// perturbation of the initial guess.
        #[arg(long, default_value_t = 7)]
        seed: u64,
        /// Rotation error of the initial guess written to /tf_static, per sensor (degrees).
        #[arg(long, default_value_t = 0.0)]
        perturb_deg: f64,
        /// Translation error of the initial guess, per sensor (centimetres).
        #[arg(long, default_value_t = 0.0)]
        perturb_cm: f64,
        /// Image size factor, e.g. 0.5 for half-size images.
        #[arg(long, default_value_t = 1.0)]
        scale: f64,
        /// Camera frame rate (Hz); LiDARs run at their own rate.
        #[arg(long, default_value_t = 10.0)]
        camera_hz: f64,
        /// The drive to write (ROS 2 MCAP; /tf_static holds the initial guess).
        #[arg(long)]
        out: PathBuf,
        /// The true extrinsics, as a native calibration file.
        #[arg(long)]
        ground_truth: PathBuf,
    },
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("rigcal: {}", one_line(&e));
            ExitCode::FAILURE
        }
    }
}

/// `text` on standard output. A reader that went away (`rigcal inspect LOG | head`) ends the
/// output quietly; any other failure (a full disk) is an error, not a panic as `print!` gives.
fn print_stdout(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(anyhow::anyhow!("cannot write to standard output: {e}"))
        }
        _ => Ok(()),
    }
}

/// The error and its causes on one line, leaving out a cause whose text an outer message
/// already holds (the library's errors name their source in their own message).
fn one_line(error: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in error.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

/// A usage error from the command line's parser on one line: its message, with any tip, and
/// where to look (clap spreads it over several, with the usage, which `--help` gives).
fn one_line_usage(rendered: &str) -> String {
    // Some errors (a bad value) carry no usage, only the closing hint.
    let message = rendered
        .split("\n\nUsage:")
        .next()
        .and_then(|m| m.split("\n\nFor more information").next())
        .unwrap_or(rendered);
    let words: Vec<&str> = message.split_whitespace().collect();
    let text = words.join(" ");
    let text = text.strip_prefix("error: ").unwrap_or(&text);
    format!("rigcal: {text} (see --help)")
}

/// `calibrate`'s options with a default value (UniCal's), by their argument ids.
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

/// For an unknown option that moved to the configuration file, where it went.
fn moved_option(e: &clap::Error) -> Option<String> {
    let arg = match e.get(clap::error::ContextKind::InvalidArg)? {
        clap::error::ContextValue::String(s) => s.clone(),
        _ => return None,
    };
    let flag = arg.split('=').next().unwrap_or(&arg);
    MOVED_TO_CONFIG
        .iter()
        .find(|(f, _)| *f == flag)
        .map(|(f, key)| {
            format!(
                "{f} is no longer an option of calibrate: its setting is {key} in the configuration file (rigcal calibrate --print-config prints it; --config FILE reads it)"
            )
        })
}

fn run() -> Result<()> {
    use clap::{CommandFactory, FromArgMatches};
    let parsed = Cli::command()
        .try_get_matches()
        .and_then(|m| Cli::from_arg_matches(&m));
    let cli = match parsed {
        Ok(parsed) => parsed,
        Err(e)
            if e.kind() == clap::error::ErrorKind::UnknownArgument
                && std::env::args().nth(1).as_deref() == Some("calibrate")
                && moved_option(&e).is_some() =>
        {
            eprintln!("rigcal: {}", moved_option(&e).unwrap_or_default());
            std::process::exit(2);
        }
        Err(e)
            if e.use_stderr()
                && e.kind() != clap::error::ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand =>
        {
            eprintln!("{}", one_line_usage(&e.render().to_string()));
            std::process::exit(2);
        }
        // Help and the version go to standard output, as clap prints them.
        Err(e) => e.exit(),
    };
    match cli.command {
        None => studio(None, None, None),
        Some(Command::Studio {
            log,
            calibration,
            session,
        }) => studio(log, calibration, session),
        Some(Command::Inspect {
            log,
            fixed_frame,
            vehicle_frame,
        }) => {
            let options = rigcal::log::DriveOptions {
                fixed_frame,
                vehicle_frame,
                ..Default::default()
            };
            let drive = rigcal::log::Drive::open_with(&log, &options)
                .with_context(|| format!("cannot inspect {}", log.display()))?;
            print_stdout(&rigcal::cli::inspect::report(&drive))
        }
        Some(Command::Calibrate {
            log,
            out,
            method,
            init,
            segment,
            sensors,
            root,
            quality,
            budget,
            config,
            print_config,
            iterations,
            seed,
            perturb_deg,
            perturb_cm,
        }) => {
            let quality = quality
                .map(|q| q.parse::<rigcal::pipeline::Quality>())
                .transpose()
                .map_err(|e| anyhow::anyhow!("--quality {e}"))?;
            let budget_secs = budget
                .map(|b| rigcal::pipeline::config::parse_duration_secs(&b))
                .transpose()
                .map_err(|e| anyhow::anyhow!("--budget {e}"))?;
            let (log, out) = (log.unwrap_or_default(), out.unwrap_or_default());
            let args = rigcal::cli::calibrate::CalibrateArgs {
                log: log.clone(),
                method,
                init,
                segment,
                sensors,
                iterations,
                seed: seed.unwrap_or(1),
                seed_given: seed.is_some(),
                root,
                perturb: (perturb_deg, perturb_cm),
                out: out.clone(),
                quality,
                budget_secs,
                config_file: config,
            };
            if print_config {
                let config =
                    rigcal::cli::pipeline::resolve_config(&args).map_err(anyhow::Error::msg)?;
                return print_stdout(&config.to_yaml());
            }
            let started = std::time::Instant::now();
            let mut bar = rigcal::cli::progress::Progress::new("calibrate", 1);
            let (_, moves) = rigcal::cli::calibrate::calibrate(&args, &mut |done, total| {
                bar.report(done, total)
            })
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("cannot calibrate {}", log.display()))?;
            bar.finish();
            // After the bar: on a terminal it would be drawn over the report.
            eprint!("{moves}");
            eprintln!(
                "wrote {} in {:.1} s",
                out.display(),
                started.elapsed().as_secs_f64()
            );
            Ok(())
        }
        Some(Command::Eval {
            ground_truth,
            calibration,
            log,
            root,
            frames,
            checkerboard,
            photometric,
            camera_readout_ms,
            json,
        }) => {
            let args = rigcal::cli::eval::EvalArgs {
                ground_truth,
                calibration,
                log,
                root,
                frames,
                checkerboard,
                photometric,
                camera_readout_ms,
            };
            let mut bar = rigcal::cli::progress::Progress::new("eval", 1);
            let report =
                rigcal::cli::eval::evaluate(&args, &mut |done, total| bar.report(done, total))
                    .map_err(anyhow::Error::msg)
                    .context("cannot evaluate")?;
            bar.finish();
            print_stdout(&report.to_markdown())?;
            if let Some(path) = json {
                let text = serde_json::to_string_pretty(&report)?;
                rigcal::util::write_atomic(&path, text.as_bytes())
                    .with_context(|| format!("cannot write {}", path.display()))?;
                eprintln!("wrote {}", path.display());
            }
            Ok(())
        }
        Some(Command::Export {
            calibration,
            format,
            out,
            sensors,
            lidar,
            camera,
        }) => {
            use rigcal::interop;
            let format: interop::ExportFormat = format.parse()?;
            // The library's errors already name the file and the cause: print them once.
            let doc = rigcal::calib::CalibrationFile::load(&calibration)
                .map_err(|e| anyhow::Error::msg(e.to_string()))?;
            let options = interop::ExportOptions {
                sensors,
                lidar,
                camera,
            };
            let export = interop::export(&doc, format, &options)
                .with_context(|| format!("cannot export {}", calibration.display()))?;
            if let Some(p) = interop::paths(&export, &out)
                .iter()
                .find(|p| rigcal::util::same_file(&calibration, p))
            {
                anyhow::bail!(
                    "--out {}: the export would overwrite the calibration being exported ({}); choose another path",
                    out.display(),
                    p.display()
                );
            }
            let written = interop::write(&export, &out)?;
            for path in written {
                // On stderr: the export itself may be going to stdout.
                eprintln!("wrote {}", path.display());
            }
            Ok(())
        }
        Some(Command::Bench {
            suite,
            out,
            pandaset,
            seeds,
        }) => bench(&suite, &out, pandaset, seeds),
        Some(Command::Synth {
            scene,
            rig,
            trajectory,
            seconds,
            seed,
            perturb_deg,
            perturb_cm,
            scale,
            camera_hz,
            out,
            ground_truth,
        }) => {
            use rigcal::sim::{rigs, synth, trajectories::TrajectoryKind, world::SceneKind};
            let scene: SceneKind = scene.parse().map_err(anyhow::Error::msg)?;
            let trajectory: TrajectoryKind = trajectory.parse().map_err(anyhow::Error::msg)?;
            let sim_rig = match rig.parse::<rigs::RigPreset>() {
                Ok(preset) => rigs::SimRig::preset(preset),
                Err(_) => rigs::SimRig::from_calibration_file(std::path::Path::new(&rig))
                    .with_context(|| format!("--rig '{rig}' is neither a preset (pandaset, truck, kitti) nor a readable calibration file"))?,
            };
            let mut cfg = synth::SynthConfig::new(scene, sim_rig, trajectory, seconds, seed);
            cfg.perturb_deg = perturb_deg;
            cfg.perturb_cm = perturb_cm;
            cfg.scale = scale;
            cfg.camera_rate_hz = camera_hz;
            let started = std::time::Instant::now();
            let mut bar = rigcal::cli::progress::Progress::new("synth", 1);
            let result = synth::synthesize(&cfg, &out, &ground_truth, &mut |done, total| {
                bar.report(done, total)
            })
            .with_context(|| format!("cannot synthesize {}", out.display()))?;
            bar.finish();
            eprintln!(
                "wrote {} ({} sweeps, {} images) and {} in {:.1} s",
                out.display(),
                result.sweeps,
                result.images,
                ground_truth.display(),
                started.elapsed().as_secs_f64()
            );
            Ok(())
        }
    }
}

fn bench(suite: &str, out: &std::path::Path, pandaset: PathBuf, seeds: Option<u64>) -> Result<()> {
    use rigcal::bench::{Stage, Suite};
    let make: fn(Option<PathBuf>) -> Suite = match suite {
        "quick" => Suite::quick,
        "paper" => Suite::paper,
        other => anyhow::bail!("unknown --suite '{other}' (expected quick or paper)"),
    };
    let pandaset = pandaset
        .join("pandaset-002.mcap")
        .is_file()
        .then_some(pandaset);
    if pandaset.is_none() {
        eprintln!("rigcal bench: no PandaSet drive found (--pandaset); its rows are skipped");
    }
    let mut chosen = make(pandaset);
    if let Some(n) = seeds {
        anyhow::ensure!(n >= 1, "--seeds 0: expected at least one seed per case");
        chosen = chosen.with_seeds(n);
    }
    eprintln!(
        "rigcal bench --suite {suite}: {} runs for {} table cells, into {}",
        chosen.runs().len(),
        chosen.cases.len(),
        out.display()
    );
    let mut bar: Option<(String, rigcal::cli::progress::Progress)> = None;
    let report = rigcal::bench::run_suite(&chosen, out, &mut |stage, done, total| {
        let label = match stage {
            Stage::Simulating(name) => format!("simulate {name}"),
            Stage::Running { index, runs, what } => format!("run {index}/{runs}: {what}"),
        };
        if bar.as_ref().is_none_or(|(l, _)| *l != label) {
            if let Some((_, b)) = bar.as_mut() {
                b.finish();
            }
            bar = Some((
                label.clone(),
                rigcal::cli::progress::Progress::new(&label, 1),
            ));
        }
        if let Some((_, b)) = bar.as_mut() {
            b.report(done, total);
        }
    })
    .map_err(anyhow::Error::msg)
    .context("rigcal bench failed")?;
    if let Some((_, b)) = bar.as_mut() {
        b.finish();
    }
    print_stdout(&report.to_markdown())?;
    eprintln!(
        "wrote tables.md, results.csv, results.json, convergence.png and error-vs-perturbation.png into {} ({:.0} s)",
        out.display(),
        report.total_secs
    );
    Ok(())
}

#[cfg(feature = "app")]
fn studio(
    log: Option<PathBuf>,
    calibration: Option<PathBuf>,
    session: Option<PathBuf>,
) -> Result<()> {
    rigcal::app::run(log, calibration, session)
}

#[cfg(not(feature = "app"))]
fn studio(
    _log: Option<PathBuf>,
    _calibration: Option<PathBuf>,
    _session: Option<PathBuf>,
) -> Result<()> {
    anyhow::bail!(
        "this build has no studio (built without the `app` feature); use the subcommands, e.g. `rigcal inspect LOG.mcap`"
    )
}

#[cfg(test)]
mod tests {
    use super::{Cli, one_line, one_line_usage};
    use clap::Parser;

    /// `calibrate --help` stays short: expert settings live in the configuration file.
    #[test]
    fn calibrate_takes_at_most_fifteen_options() {
        use clap::CommandFactory;
        let command = Cli::command();
        let calibrate = command.find_subcommand("calibrate").unwrap();
        let options = calibrate
            .get_arguments()
            .filter(|a| !a.is_positional())
            .count();
        assert!(options <= 15, "{options} options");
    }

    #[test]
    fn usage_errors_are_one_line() {
        let cases: [&[&str]; 3] = [
            &["rigcal", "calibrate", "drive.mcap"],
            &[
                "rigcal",
                "calibrate",
                "drive.mcap",
                "--method",
                "unical",
                "--out",
                "c.yaml",
                "--frobnicate",
            ],
            &["rigcal", "eval", "--calibration"],
        ];
        for args in cases {
            let Err(e) = Cli::try_parse_from(args) else {
                panic!("{args:?} parsed");
            };
            let line = one_line_usage(&e.render().to_string());
            assert!(!line.contains('\n'), "{line}");
            assert!(
                line.starts_with("rigcal: ") && line.ends_with("(see --help)"),
                "{line}"
            );
        }
        let Err(e) = Cli::try_parse_from(["rigcal", "calibrate", "d.mcap"]) else {
            panic!("parsed");
        };
        assert_eq!(
            one_line_usage(&e.render().to_string()),
            "rigcal: the following required arguments were not provided: --out <OUT> (see --help)"
        );
        // A bad value has no usage block, only the closing hint, which is not repeated.
        let Err(e) = Cli::try_parse_from(["rigcal", "eval", "--calibration"]) else {
            panic!("parsed");
        };
        assert_eq!(
            one_line_usage(&e.render().to_string()),
            "rigcal: a value is required for '--calibration <CALIBRATION>' but none was supplied (see --help)"
        );
    }

    #[test]
    fn a_cause_already_in_the_message_is_not_repeated() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file");
        #[derive(Debug, thiserror::Error)]
        #[error("x.mcap: cannot read: {source}")]
        struct Read {
            source: std::io::Error,
        }
        let e = anyhow::Error::new(Read { source: io }).context("cannot inspect x.mcap");
        assert_eq!(
            one_line(&e),
            "cannot inspect x.mcap: x.mcap: cannot read: No such file"
        );
        // A cause that adds something is kept.
        let e = anyhow::anyhow!("disk full").context("cannot write out.yaml");
        assert_eq!(one_line(&e), "cannot write out.yaml: disk full");
    }

    /// docs/cli.md lists, for every subcommand, exactly the options clap defines.
    #[test]
    fn the_command_line_reference_lists_every_option_of_every_subcommand() {
        use clap::CommandFactory;
        use std::collections::BTreeSet;
        let doc = include_str!("../docs/cli.md");
        let command = Cli::command();
        for sub in command.get_subcommands() {
            let name = sub.get_name();
            if name == "help" {
                continue;
            }
            let heading = format!("## `rigcal {name}`");
            let section = doc
                .split("\n## ")
                .find(|s| format!("## {s}").starts_with(&heading))
                .unwrap_or_else(|| panic!("docs/cli.md has no section {heading}"));
            let documented: BTreeSet<String> = section
                .lines()
                .filter_map(|l| l.strip_prefix("| `--"))
                .filter_map(|l| l.split([' ', '`', '=']).next())
                .map(|f| format!("--{f}"))
                .collect();
            let defined: BTreeSet<String> = sub
                .get_arguments()
                .filter_map(|a| a.get_long())
                .filter(|l| *l != "help" && *l != "version")
                .map(|l| format!("--{l}"))
                .collect();
            assert_eq!(documented, defined, "docs/cli.md, rigcal {name}");
        }
    }
}
