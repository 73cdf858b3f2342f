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

/// `calibrate --help`'s group of UniCal's everyday options.
const HEADING_UNICAL: &str = "UniCal (--method unical)";
/// `calibrate --help`'s group of UniCal's options that are off by default: each changes what
/// the run does in a way BENCHMARKS.md measures, none has held on every drive tried.
const HEADING_EXPERIMENTAL: &str =
    "UniCal, experimental (off by default; what each did is in BENCHMARKS.md)";
/// Typical `calibrate` commands, printed after its options.
const CALIBRATE_EXAMPLES: &str = "\
Examples:
  # Every LiDAR and camera with UniCal: LiDARs registered by ICP first, 16 images per camera
  rigcal calibrate drive.mcap --method unical --lidar-icp --camera-frames 16 \\
      --camera-scale 0.25 --iterations 1400 --out calib.yaml
  # The same from a poor initial guess (10°, a metre): each camera fitted to its motion first
  rigcal calibrate drive.mcap --method unical --lidar-icp --camera-hand-eye --camera-frames 16 \\
      --camera-scale 0.25 --iterations 1400 --init guess.urdf --out calib.yaml
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
        /// auto (the default: the whole pipeline, every LiDAR and camera) | unical | icp | mi |
        /// target | pose-graph | edge
        #[arg(long, default_value = "auto")]
        method: String,
        /// The pipeline's quality: fast | default (at most about 10 minutes on two cores) |
        /// paper (the longer schedule, no time budget)
        #[arg(long)]
        quality: Option<String>,
        /// The pipeline's time budget, e.g. 600, 10m, 1h (default: the quality's); the plan
        /// fits its steps to it and the run stops at it
        #[arg(long, value_name = "DURATION")]
        budget: Option<String>,
        /// The pipeline's whole configuration as YAML: a --print-config output, or an earlier
        /// output file (its run is repeated)
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        /// Print the pipeline's configuration (with --config, --quality, --budget and --seed
        /// applied) as YAML and exit
        #[arg(long)]
        print_config: bool,
        /// Initial guess: a native calibration file, URDF, ROS camera_info YAML (or a directory
        /// of them) or an MCAP's /tf_static; sensors matched by name or frame id. Default: the
        /// log's /tf_static.
        #[arg(long)]
        init: Option<PathBuf>,
        /// Time range in seconds from the start of the log, START..END.
        #[arg(long, allow_hyphen_values = true)]
        segment: Option<String>,
        /// Sensors to optimise, comma-separated (default: all the method handles).
        #[arg(long, value_delimiter = ',')]
        sensors: Vec<String>,
        /// Optimisation steps for unical (default 300), mi, target and edge (their own
        /// defaults; edge with 0 writes the initial guess as it is); icp and pose-graph run
        /// until they converge.
        #[arg(long)]
        iterations: Option<usize>,
        /// Seed of every random choice (ray draws, RANSAC, --perturb-*): one seed, one result
        /// at a fixed thread count.
        #[arg(long)]
        seed: Option<u64>,
        /// Images per camera for the colour term (cameras join the optimisation;
        /// 0 = LiDAR depth stage only)
        #[arg(help_heading = HEADING_UNICAL, long, default_value_t = 0)]
        camera_frames: usize,
        /// LiDAR sweeps per LiDAR that shape the scene (spread over the drive or the
        /// segments; more: denser geometry under the cameras' rays, a longer preparation)
        #[arg(help_heading = HEADING_UNICAL, long, default_value_t = rigcal::cli::calibrate::DEFAULT_LIDAR_SWEEPS)]
        lidar_sweeps: usize,
        /// Drop LiDAR returns farther than this many metres (horizontally) from the
        /// drive before the scene box is formed: the scene spans the drive's surroundings, not
        /// the LiDARs' whole reach, and camera rays leave it into the background model
        #[arg(help_heading = HEADING_EXPERIMENTAL, long = "scene-radius")]
        scene_radius_m: Option<f64>,
        /// unical: a sensor whose extrinsic stays fixed (default none: every sensor moves and
        /// the trajectory fixes the gauge); icp, mi, target, pose-graph, edge and --lidar-icp:
        /// the reference LiDAR (default the first)
        #[arg(long)]
        root: Option<String>,
        /// With --camera-frames: the correspondence term between camera images: none |
        /// ray-distance (SC-NeRF's projected ray distance) | surface (UniCal's surface alignment)
        #[arg(help_heading = HEADING_UNICAL, long, default_value = "surface")]
        alignment: String,
        /// Register the reference LiDAR (the root, else the first) to the trajectory
        /// by its own sweeps (not the root: it stays) and every other LiDAR to it by
        /// point-to-plane ICP first, then hold the LiDARs while UniCal calibrates the cameras
        #[arg(long, help_heading = HEADING_UNICAL)]
        lidar_icp: bool,
        /// With --camera-frames: fit each camera to its own motion first (hand-eye against the
        /// trajectory, from keypoints matched between its images a few metres apart): for
        /// starts too far off for the scene (10°, a metre); directions the drive does not
        /// observe (the height on a level drive) are kept. Fitted cameras then move at half
        /// the rotation rate, their translations at the full rate decaying to 5 %, and UniCal
        /// turns them at most 0.5° from their fit
        #[arg(long, help_heading = HEADING_UNICAL)]
        camera_hand_eye: bool,
        /// With --camera-frames: the scale images are used at (0.125: 1920×1080 → 240×135)
        #[arg(help_heading = HEADING_UNICAL, long, default_value_t = rigcal::cli::calibrate::DEFAULT_CAMERA_SCALE)]
        camera_scale: f64,
        /// With --camera-frames: rays per camera and step (more: less noisy pose gradients,
        /// slower steps)
        #[arg(help_heading = HEADING_UNICAL, long, default_value_t = rigcal::cli::calibrate::DEFAULT_CAMERA_RAYS)]
        camera_rays: usize,
        /// With --camera-frames: the camera pose rate (Adam; it decays to 1 % over the run and
        /// bounds how far a camera can move)
        #[arg(long, help_heading = HEADING_UNICAL)]
        camera_lr: Option<f32>,
        /// With --camera-frames: the cameras' translation rate as a multiple of their rotation
        /// rate (default 1; translations are the slower-observed part of a camera's pose)
        #[arg(long, help_heading = HEADING_UNICAL)]
        camera_translation_rate: Option<f32>,
        /// With --camera-frames: what the cameras' translation rate decays to by the end of the
        /// run, as a fraction of its start (default: 0.01, as the rotation's); a larger one
        /// keeps translations moving late, when the rotations have settled
        #[arg(long, help_heading = HEADING_UNICAL)]
        camera_translation_final: Option<f32>,
        /// With --camera-frames: the cameras start to move at iteration ITER of
        /// the geometry initialisation, on the correspondence term alone, at RATE (default
        /// 0.1) times their rate, so the first extrinsic update comes seconds into the run
        /// instead of after the warm-up; --camera-hand-eye sets it at 30, and then only the
        /// translations of the cameras it fitted move until the warm-up ends; ",translations"
        /// moves only the translations whatever the start
        #[arg(help_heading = HEADING_UNICAL, long, value_name = "ITER[,RATE[,translations]]")]
        camera_early_release: Option<String>,
        /// Run in ROUNDS rounds of --iterations each, every one with a fresh scene
        /// formed at the extrinsics the previous round reached (a scene formed around the
        /// cameras' errors holds them back)
        #[arg(help_heading = HEADING_UNICAL, long, default_value_t = 1)]
        rounds: usize,
        /// Coarse-to-fine hash grid, LEVELS,FRACTION: the scene starts with LEVELS open
        /// levels and opens the rest evenly until FRACTION of the run (BARF); default 4,0.6 (the
        /// CPU preset), `off` opens every level from the start
        #[arg(long, help_heading = HEADING_UNICAL)]
        coarse_to_fine: Option<String>,
        /// With --camera-frames: also step one translation shared by every camera (the camera
        /// rig's offset from the LiDARs) on the sum of their gradients: on the simulator it
        /// follows a height a level drive leaves the LiDARs at, on the real PandaSet drive it
        /// lets the cameras drift together (BENCHMARKS.md)
        #[arg(long, help_heading = HEADING_EXPERIMENTAL)]
        shared_camera_translation: bool,
        /// With --camera-frames: each camera's translation coordinates share Adam's step scale,
        /// so a direction the drive hardly sees moves by its share of the gradient instead of
        /// the full rate (BENCHMARKS.md)
        #[arg(long, help_heading = HEADING_EXPERIMENTAL)]
        grouped_camera_translation: bool,
        /// With --camera-frames: draw camera rays only up to the LiDARs' highest beam (above it
        /// the scene has no geometry and the cameras' colour can only go to the sky); on the
        /// real PandaSet drive rotations end closer to the reference, translations further
        /// (BENCHMARKS.md)
        #[arg(long, help_heading = HEADING_EXPERIMENTAL)]
        camera_rays_below_lidar_top: bool,
        /// With --camera-frames: solution remapping: each camera step keeps only the directions
        /// of its pose that the correspondence term observes at least RATIO times as well as
        /// its best one (e.g. 0.02); the rest stay at the initial guess (BENCHMARKS.md)
        #[arg(help_heading = HEADING_EXPERIMENTAL, long, value_name = "RATIO")]
        camera_hold_unobserved: Option<f64>,
        /// With --camera-frames: hold each camera's translation along its own optical axis at
        /// the initial guess; only the part of each step square to the axis moves it. Along the
        /// axis a camera is observed least, and there the colour term pulls it away from what it
        /// sees (BENCHMARKS.md)
        #[arg(long, help_heading = HEADING_EXPERIMENTAL)]
        camera_hold_axial: bool,
        /// With --camera-frames: the share of the camera rays, once heat maps are on, drawn
        /// around the LiDARs' silhouettes (depth edges projected into each image); the rest
        /// are drawn around keypoints but for a small uniform share. A silhouette ties a camera
        /// to the LiDARs' geometry where texture could slide. Preset 0.5; 0: heat maps around
        /// keypoints only, as in the paper (BENCHMARKS.md)
        #[arg(help_heading = HEADING_EXPERIMENTAL, long, value_name = "SHARE")]
        silhouette_share: Option<f64>,
        /// With --camera-frames: blur the images by a Gaussian of this σ (pixels at
        /// --camera-scale) before they become the colour term's target, to meet the scene's
        /// blurrier colour field halfway (0: sharp)
        #[arg(help_heading = HEADING_EXPERIMENTAL, long, value_name = "PX")]
        camera_blur: Option<f64>,
        /// With --camera-frames: the colour term moves the cameras through the hash grid's
        /// LEVELS coarsest levels only (fractions open a level partly); the scene still learns
        /// from every open level (BARF; BENCHMARKS.md)
        #[arg(help_heading = HEADING_EXPERIMENTAL, long, value_name = "LEVELS")]
        colour_pose_levels: Option<f64>,
        /// Entries per level of the scene's hash table, as a power of two (the CPU
        /// preset's 19, the paper's 21; 12 to 24): a larger table for a larger scene
        #[arg(help_heading = HEADING_UNICAL, long, value_name = "BITS")]
        hash_table_log2: Option<u32>,
        /// Report each pose averaged over the run's latest steps, this fraction of them
        /// (default 0.1; 0: the last step's pose). Averaging takes out the steps' noise
        #[arg(help_heading = HEADING_UNICAL, long, value_name = "FRACTION")]
        pose_average: Option<f64>,
        /// Map the scene box to the hash grid's unit cube by its largest extent, so
        /// cells are as tall as they are wide (default: each axis by its own extent, which on a
        /// street scene makes them about ten times finer vertically)
        #[arg(long, help_heading = HEADING_EXPERIMENTAL)]
        cubic_scene_box: bool,
        /// Drop LiDAR returns that other sweeps saw through (moving traffic), and mask
        /// the pixels near them and the vehicle's own body in the images (BENCHMARKS.md,
        /// "Moving traffic")
        #[arg(long, help_heading = HEADING_EXPERIMENTAL)]
        drop_moving: bool,
        /// Add this many milliseconds to every camera image's stamp: a known delay between the
        /// cameras and the trajectory (negative: the images were taken before their stamps)
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        camera_time_offset_ms: f64,
        /// With --camera-frames or --camera-hand-eye: the cameras have a rolling shutter whose
        /// readout began FIRST and ended LAST milliseconds after each image's stamp (at the
        /// image's top and bottom edges; negative: before it), rows in between evenly; each ray
        /// is cast from where the vehicle was when its row was exposed, and the hand-eye places
        /// each image at its middle row's time (e.g. -30..10; default: a global shutter at the
        /// stamp)
        #[arg(
            help_heading = HEADING_UNICAL,
            long,
            value_name = "FIRST..LAST",
            allow_hyphen_values = true
        )]
        camera_readout_ms: Option<String>,
        /// Perturb every sensor of the initial guess by this many degrees about a random axis
        /// (drawn from --seed), to measure how far a method recovers; a sensor whose frame is
        /// the vehicle frame (the trajectory's own, as PandaSet's Pandar64) is left alone
        #[arg(long, default_value_t = 0.0)]
        perturb_deg: f64,
        /// Perturb every sensor of the initial guess by this many centimetres along a random
        /// direction (drawn from --seed)
        #[arg(long, default_value_t = 0.0)]
        perturb_cm: f64,
        /// The native calibration file to write (atomically; see the note below).
        #[arg(long, required_unless_present = "print_config")]
        out: Option<PathBuf>,
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
const CALIBRATE_DEFAULTED: [&str; 6] = [
    "camera_frames",
    "lidar_sweeps",
    "alignment",
    "camera_scale",
    "camera_rays",
    "rounds",
];

/// Which of [`CALIBRATE_DEFAULTED`] were typed on the command line, as `--flag`s (whatever
/// their value: at the default they are still given, and refused with another method).
fn calibrate_given(matches: &clap::ArgMatches) -> Vec<String> {
    let Some(m) = matches.subcommand_matches("calibrate") else {
        return Vec::new();
    };
    CALIBRATE_DEFAULTED
        .iter()
        .filter(|id| m.value_source(id) == Some(clap::parser::ValueSource::CommandLine))
        .map(|id| format!("--{}", id.replace('_', "-")))
        .collect()
}

fn run() -> Result<()> {
    use clap::{CommandFactory, FromArgMatches};
    let parsed = Cli::command()
        .try_get_matches()
        .and_then(|m| Ok((Cli::from_arg_matches(&m)?, calibrate_given(&m))));
    let (cli, given_at_default) = match parsed {
        Ok(parsed) => parsed,
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
            method,
            quality,
            budget,
            config,
            print_config,
            init,
            segment,
            sensors,
            iterations,
            seed,
            camera_frames,
            lidar_sweeps,
            scene_radius_m,
            root,
            alignment,
            lidar_icp,
            camera_hand_eye,
            camera_scale,
            camera_rays,
            camera_lr,
            camera_translation_rate,
            camera_translation_final,
            camera_early_release,
            rounds,
            coarse_to_fine,
            shared_camera_translation,
            grouped_camera_translation,
            camera_rays_below_lidar_top,
            camera_hold_unobserved,
            camera_hold_axial,
            silhouette_share,
            camera_blur,
            colour_pose_levels,
            hash_table_log2,
            pose_average,
            cubic_scene_box,
            drop_moving,
            camera_time_offset_ms,
            camera_readout_ms,
            perturb_deg,
            perturb_cm,
            out,
        }) => {
            let alignment = alignment.parse().map_err(anyhow::Error::msg)?;
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
                quality,
                budget_secs,
                config_file: config,
                seed_given: seed.is_some(),
                init,
                segment,
                sensors,
                iterations,
                seed: seed.unwrap_or(1),
                camera_frames,
                lidar_sweeps,
                scene_radius_m,
                root,
                alignment,
                lidar_icp,
                camera_hand_eye,
                camera_scale,
                camera_rays,
                camera_lr,
                camera_translation_rate,
                camera_translation_final,
                camera_early_release,
                rounds,
                coarse_to_fine,
                shared_camera_translation,
                grouped_camera_translation,
                camera_rays_below_lidar_top,
                camera_hold_unobserved,
                camera_hold_axial,
                silhouette_share,
                camera_blur,
                colour_pose_levels,
                hash_table_log2,
                pose_average,
                cubic_scene_box,
                drop_moving,
                camera_time_offset_ms,
                camera_readout_ms,
                given_at_default,
                perturb: (perturb_deg, perturb_cm),
                out: out.clone(),
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

    /// Every id looked up for `calibrate`'s value sources is one of its arguments (a release
    /// build would not say so at run time).
    #[test]
    fn the_defaulted_calibrate_options_are_its_arguments() {
        use clap::CommandFactory;
        let command = Cli::command();
        let calibrate = command.find_subcommand("calibrate").unwrap();
        for id in super::CALIBRATE_DEFAULTED {
            assert!(calibrate.get_arguments().any(|a| a.get_id() == id), "{id}");
        }
        let m = command
            .try_get_matches_from([
                "rigcal",
                "calibrate",
                "d.mcap",
                "--method",
                "icp",
                "--out",
                "c.yaml",
                "--rounds",
                "1",
                "--camera-scale",
                "0.125",
            ])
            .unwrap();
        assert_eq!(super::calibrate_given(&m), ["--camera-scale", "--rounds"]);
    }

    #[test]
    fn usage_errors_are_one_line() {
        let cases: [&[&str]; 3] = [
            &["rigcal", "calibrate", "drive.mcap", "--out", "c.yaml"],
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
        let Err(e) = Cli::try_parse_from(["rigcal", "calibrate", "d.mcap", "--out", "c.yaml"])
        else {
            panic!("parsed");
        };
        assert_eq!(
            one_line_usage(&e.render().to_string()),
            "rigcal: the following required arguments were not provided: --method <METHOD> (see --help)"
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
}
