//! `rigcal calibrate`: run a calibrator on a drive without the studio and write the native
//! calibration file (atomically), with provenance and the final losses as metrics.
//!
//! Without `--method` (or with `--method auto`) the automatic pipeline runs
//! ([`super::pipeline`]); `--method unical` runs the pipeline's UniCal stage alone, every LiDAR
//! and camera in one scene, with the settings of the same configuration. The classical methods:
//! `edge` (cameras against a reference LiDAR by edge alignment), `icp` (every LiDAR against the
//! reference LiDAR, `--root`, default the first, by point-to-plane ICP on three sweeps each),
//! `mi` (every camera against the reference LiDAR by mutual information), `target` (every camera
//! against the reference LiDAR by checkerboard edges and planes) and `pose-graph` (every LiDAR
//! pair by ICP and every camera–LiDAR pair by checkerboards, or mutual information where there
//! are none, unified by a pose graph with the reference LiDAR fixed).

use super::CliError;
use crate::calib::{CalibrationFile, Rig};
use crate::classical::icp::IcpConfig;
use crate::classical::icp_calibrator::IcpCalibrator;
use crate::classical::mi_calibrator::MiCalibrator;
use crate::classical::mutual_info::MiConfig;
use crate::classical::pose_graph_calibrator::{PoseGraphCalibrator, PoseGraphConfig};
use crate::classical::target::TargetConfig;
use crate::classical::target_calibrator::TargetCalibrator;
use crate::error::ParseError;
use crate::geometry::Rigid;
use crate::log::Drive;
use crate::optim::divergence::Guarded;
use crate::optim::edge_refine::EdgeRefiner;
use crate::optim::runner::Calibrator;

pub use super::calibrate_args::CalibrateArgs;

/// How many sweeps (each with its nearest image) edge alignment and mutual information fit.
const EDGE_FRAMES: usize = 4;
const MI_FRAMES: usize = 3;
const EDGE_HOLDS_TRANSLATION: &str = "edge alignment turns the camera only and keeps the initial guess's translation (at street distances a few centimetres move a silhouette by under a pixel)";

/// The reference LiDAR: `--root`, else the rig's first LiDAR.
fn reference_lidar(args: &CalibrateArgs, rig: &Rig) -> Result<String, CliError> {
    match &args.root {
        Some(r) if rig.lidars().any(|l| &l.name == r) => Ok(r.clone()),
        Some(r) => Err(format!(
            "--root: '{r}' is not a LiDAR of {}; --method {} registers against a LiDAR",
            args.log().display(),
            args.method
        )
        .into()),
        None => rig
            .lidars()
            .next()
            .map(|l| l.name.clone())
            .ok_or_else(|| CliError::Usage("the log has no LiDAR".into())),
    }
}

/// The cameras with intrinsics that `--sensors` selects (all when empty).
fn selected_cameras(args: &CalibrateArgs, rig: &Rig) -> Vec<String> {
    rig.cameras()
        .filter(|c| c.camera.is_some())
        .map(|c| c.name.clone())
        .filter(|c| args.sensors.is_empty() || args.sensors.contains(c))
        .collect()
}

/// Parse `--camera-readout-ms FIRST..LAST`: when a rolling shutter exposed the first and the
/// last image rows, in milliseconds after the stamp (each within ±1000; LAST below FIRST is a
/// readout from the bottom up).
pub(crate) fn parse_readout(text: &str) -> Result<crate::geometry::RowTimes, ParseError> {
    crate::geometry::RowTimes::parse_millis(text)
        .map_err(|e| ParseError::new(format!("--camera-readout-ms {e}")))
}

/// Parse `START..END` (seconds from `t0`) into nanoseconds.
pub fn parse_segment(text: &str, t0_nanos: i64) -> Result<(i64, i64), ParseError> {
    let (a, b) = text
        .split_once("..")
        .ok_or_else(|| format!("--segment '{text}': expected START..END in seconds"))?;
    let parse = |s: &str| {
        s.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0)
            .ok_or_else(|| format!("--segment '{text}': '{s}' is not a time in seconds"))
    };
    let (a, b) = (parse(a)?, parse(b)?);
    if b <= a {
        return Err(format!("--segment '{text}': END must be after START").into());
    }
    Ok((t0_nanos + (a * 1e9) as i64, t0_nanos + (b * 1e9) as i64))
}

/// The values `--method` takes.
const METHODS: [&str; 7] = [
    "auto",
    "unical",
    "icp",
    "mi",
    "target",
    "pose-graph",
    "edge",
];

fn unknown_method(method: &str) -> String {
    format!(
        "unknown --method '{method}' (expected auto, unical, icp, mi, target, pose-graph or edge)"
    )
}

/// `--sensors` naming a sensor the method does not calibrate (a camera for ICP, a LiDAR for
/// mutual information) would be written back unchanged; it is refused instead.
fn check_sensor_kinds(args: &CalibrateArgs, rig: &Rig) -> Result<(), CliError> {
    use crate::calib::SensorKind;
    let calibrates = match args.method.as_str() {
        "icp" => Some((SensorKind::Lidar, "LiDARs")),
        "mi" | "edge" | "target" => Some((SensorKind::Camera, "cameras")),
        // unical and pose-graph calibrate every sensor.
        _ => None,
    };
    let Some((kind, what)) = calibrates else {
        return Ok(());
    };
    match args
        .sensors
        .iter()
        .find(|s| rig.sensor(s).is_some_and(|s| s.kind != kind))
    {
        Some(s) => Err(format!(
            "--sensors: --method {} calibrates {what}; '{s}' is not one",
            args.method
        )
        .into()),
        None => Ok(()),
    }
}

/// A segment must overlap the log's time range; else the error says where the log lies.
fn check_segment_in_log(
    text: &str,
    (start, end): (i64, i64),
    (first, last): (i64, i64),
    log: &std::path::Path,
) -> Result<(), CliError> {
    if start < last && end > first {
        return Ok(());
    }
    Err(format!(
        "--segment '{text}' lies outside {}, which spans 0..{:.1} s",
        log.display(),
        (last - first) as f64 * 1e-9
    )
    .into())
}

/// The drive, the initial guess (after `--init` and `--perturb-*`) and the segments of a run,
/// each checked against the log.
pub(crate) fn open_inputs(
    args: &CalibrateArgs,
    options: &crate::log::DriveOptions,
    perturbation: Option<(f64, f64)>,
) -> Result<(Drive, Rig, Vec<(i64, i64)>), CliError> {
    let drive = Drive::open_with(args.log(), options)?;
    let mut rig = drive.rig.clone();
    if let Some(init) = &args.init {
        let imported = crate::interop::import::load_initial_guess(init, &rig)
            .map_err(|e| format!("--init: {e}"))?;
        let kept: Vec<&str> = rig
            .sensors
            .iter()
            .map(|s| s.name.as_str())
            .filter(|name| !imported.matched.iter().any(|m| m == name))
            .collect();
        if !kept.is_empty() {
            // Not an error (a file may hold only some sensors), but never silent.
            eprintln!(
                "--init {} ({}) gives {} of {} sensors; from the log's /tf_static: {}",
                init.display(),
                imported.format,
                rig.sensors.len() - kept.len(),
                rig.sensors.len(),
                kept.join(", ")
            );
        }
        rig = imported.rig;
    }
    if let Some((deg, cm)) = perturbation {
        rig = crate::sim::synth::perturb_rig(&rig, deg, cm, args.seed());
    }
    let asked = args.sensors.iter().map(|s| ("--sensors", s));
    for (option, s) in asked.chain(args.root.iter().map(|s| ("--root", s))) {
        if rig.sensor(s).is_none() {
            return Err(format!(
                "{option}: '{s}' is not a sensor of {}",
                args.log().display()
            )
            .into());
        }
    }
    let range = drive.time_range_nanos();
    let t0 = range.map_or(0, |r| r.0);
    let segments: Vec<(i64, i64)> = match &args.segment {
        Some(s) => {
            let segment = parse_segment(s, t0)?;
            if let Some(range) = range {
                check_segment_in_log(s, segment, range, args.log())?;
            }
            vec![segment]
        }
        None => Vec::new(),
    };
    Ok((drive, rig, segments))
}

/// Run the calibration; `progress(step, max_steps)` is called after every step. Returns the
/// written document and the text that closes the run (how far each sensor moved from the
/// initial guess, [`moves_report`], and for the pipeline its report).
pub fn calibrate(
    args: &CalibrateArgs,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(CalibrationFile, String), CliError> {
    let perturbation = args.perturbation()?;
    if !METHODS.contains(&args.method.as_str()) {
        return Err(unknown_method(&args.method).into());
    }
    let classical = !matches!(args.method.as_str(), "auto" | "unical");
    if matches!(args.method.as_str(), "icp" | "pose-graph") && args.iterations.is_some() {
        return Err(format!(
            "--iterations: --method {} runs until it converges",
            args.method
        )
        .into());
    }
    let pipeline_only: Vec<&str> = [
        ("--quality", args.quality.is_some()),
        ("--budget", args.budget_secs.is_some()),
        ("--config", args.config_file.is_some()),
    ]
    .iter()
    .filter(|(_, given)| *given)
    .map(|(f, _)| *f)
    .collect();
    if classical && !pipeline_only.is_empty() {
        return Err(format!(
            "{} appl{} to the pipeline and --method unical only",
            pipeline_only.join(", "),
            if pipeline_only.len() == 1 { "ies" } else { "y" }
        )
        .into());
    }
    if let Ok(crate::util::OutputTarget::Direct(_)) = crate::util::output_target(args.out()) {
        return Err(format!(
            "--out {} is not a regular file (a device or pipe); calibrate writes its file at the start and replaces it every 30 s",
            args.out().display()
        ).into());
    }
    if crate::util::same_file(args.out(), args.log()) {
        return Err(format!(
            "--out {} is the log itself; the calibration would overwrite it",
            args.out().display()
        )
        .into());
    }
    if !classical {
        if args.iterations == Some(0) {
            return Err("--iterations 0: UniCal needs at least one step".into());
        }
        return super::pipeline::calibrate_auto(args, perturbation, progress);
    }
    let options = crate::log::DriveOptions::default();
    let (drive, rig, segments) = open_inputs(args, &options, perturbation)?;
    // What the user gave (after --init and --perturb-*), to say at the end how far each sensor
    // moved from it.
    let initial_guess = rig.clone();
    check_sensor_kinds(args, &rig)?;
    // Every classical method registers against one LiDAR; the camera methods fit
    // `fitted_sweeps` of its sweeps (spread evenly), which their check then stays off.
    let reference = reference_lidar(args, &rig)?;
    let cameras = selected_cameras(args, &rig);
    let target_config = TargetConfig {
        iterations: args
            .iterations
            .unwrap_or(TargetConfig::default().iterations),
        ..TargetConfig::default()
    };
    let fitted_sweeps = match args.method.as_str() {
        "edge" => EDGE_FRAMES,
        "mi" => MI_FRAMES,
        _ => target_config.frames,
    };
    let calibrator: Box<dyn Calibrator> = match args.method.as_str() {
        "edge" => Box::new(
            EdgeRefiner::new(
                &drive,
                &rig,
                (&reference, &cameras),
                EDGE_FRAMES,
                &segments,
                drive.camera_readout,
            )
            .map_err(crate::error::RunError::from)?,
        ),
        "icp" => Box::new(IcpCalibrator::from_drive(
            &drive,
            &rig,
            &reference,
            3,
            &segments,
            IcpConfig::default(),
        )?),
        "mi" => {
            let config = MiConfig {
                iterations: args.iterations.unwrap_or(MiConfig::default().iterations),
                ..MiConfig::default()
            };
            Box::new(MiCalibrator::from_drive(
                &drive, &rig, &reference, &cameras, MI_FRAMES, &segments, config,
            )?)
        }
        "target" => Box::new(TargetCalibrator::from_drive(
            &drive,
            &rig,
            &reference,
            &cameras,
            &segments,
            target_config,
            &Default::default(),
        )?),
        "pose-graph" => {
            let cal = PoseGraphCalibrator::from_drive(
                &drive,
                &rig,
                &reference,
                &segments,
                PoseGraphConfig::default(),
            )?;
            for s in cal.skipped() {
                eprintln!("pose-graph: skipped {s}");
            }
            Box::new(cal)
        }
        m => return Err(unknown_method(m).into()),
    };
    // A NaN or an infinity ends the run with the best result before it.
    let mut calibrator = Guarded::new(calibrator);
    let max_steps = match (args.method.as_str(), args.iterations) {
        ("edge", Some(n)) => n.min(calibrator.max_steps()),
        _ => calibrator.max_steps(),
    };
    // The output is written before the first step (an unwritable path fails now, not after
    // the run) and again every CHECKPOINT_SECS, atomically: a run that is killed or crashes
    // leaves its latest result, marked as unfinished.
    let mut last = Vec::new();
    let checkpoint = |calibrator: &dyn Calibrator, last: &[(String, f64)], status: String| {
        document(args, &rig, calibrator, last, status)
            .save(args.out())
            .map_err(|e| e.to_string())
    };
    checkpoint(
        &calibrator,
        &last,
        format!("running: step 0 of {max_steps}"),
    )?;
    let mut saved_at = std::time::Instant::now();
    let optimising_since = std::time::Instant::now();
    let mut first_update_seen = false;
    for step in 1..=max_steps {
        let r = calibrator.step();
        last = r.losses;
        if !first_update_seen && rig_moved(&rig, &calibrator.current()) {
            first_update_seen = true;
            report_first_update(step, optimising_since.elapsed().as_secs_f64());
        }
        progress(step, max_steps);
        if r.done {
            break;
        }
        if saved_at.elapsed().as_secs_f64() >= CHECKPOINT_SECS {
            checkpoint(
                &calibrator,
                &last,
                format!("running: step {step} of {max_steps}"),
            )?;
            saved_at = std::time::Instant::now();
        }
    }
    let mut result = result_rig(args, &rig, &calibrator);
    // Never worse: a camera method's result is checked by edge alignment on frames it did not
    // fit, and a camera that aligns worse than at the initial guess is put back there.
    let mut report = None;
    if matches!(args.method.as_str(), "edge" | "mi" | "target") && calibrator.diverged().is_none() {
        let failures = calibrator.failures();
        let fit = crate::pipeline::report::MethodFit {
            reference: &reference,
            cameras: &cameras,
            fitted_sweeps,
            failures: &failures,
            held_translation: (args.method == "edge").then_some(EDGE_HOLDS_TRANSLATION),
            fitted_edges: args.method == "edge",
        };
        let (checked, rig_to_write) =
            crate::pipeline::report::Report::for_cameras(&drive, &rig, &result, &fit, &segments);
        result = rig_to_write;
        report = Some(checked);
    }
    let status = match calibrator.diverged() {
        Some(why) => format!("diverged: {why}"),
        None => "complete".into(),
    };
    let mut doc = document_of(args, &result, &calibrator, &last, status);
    if let Some(r) = &report {
        doc.metrics.insert("report".into(), r.to_yaml());
    }
    record_skipped(&drive, &mut doc);
    doc.save(args.out())?;
    if let Some(why) = calibrator.diverged() {
        return Err(CliError::Failed(format!(
            "{why}; that result is written to {}",
            args.out().display()
        )));
    }
    let mut closing = moves_report(&initial_guess, &result);
    if let Some(r) = &report {
        closing.push_str(&r.to_text());
    }
    Ok((doc, closing))
}

/// Say how many frames the run skipped because they did not decode, and list them in `doc`'s
/// metrics (`skipped_frames`: topic, log time and what was wrong, one entry per frame).
pub(crate) fn record_skipped(drive: &Drive, doc: &mut CalibrationFile) {
    let Some(line) = drive.skipped_summary() else {
        return;
    };
    eprintln!("{line}");
    let skipped = drive
        .skipped()
        .iter()
        .map(|(_, p)| serde_yaml::Value::String(p.to_string()))
        .collect();
    doc.metrics.insert(
        "skipped_frames".into(),
        serde_yaml::Value::Sequence(skipped),
    );
}

/// How far each sensor of `result` lies from the initial guess, one line each, the largest
/// rotation first; sensors that did not move are named together. A camera far from a guess
/// the user trusts is the one to look at in the studio.
pub fn moves_report(initial: &Rig, result: &Rig) -> String {
    let mut moved: Vec<(String, f64, f64)> = Vec::new();
    let mut kept: Vec<&str> = Vec::new();
    for s in &initial.sensors {
        let Some(r) = result.sensor(&s.name) else {
            continue;
        };
        match moved_by(s.vehicle_from_sensor, r.vehicle_from_sensor) {
            Some((rot, trans)) => moved.push((s.name.clone(), rot.to_degrees(), trans * 100.0)),
            None => kept.push(&s.name),
        }
    }
    moved.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut out = String::from("moved from the initial guess:\n");
    let width = moved.iter().map(|m| m.0.len()).max().unwrap_or(0);
    for (name, deg, cm) in &moved {
        out.push_str(&format!("  {name:width$}  {deg:6.3}° {cm:7.2} cm\n"));
    }
    if !kept.is_empty() {
        out.push_str(&format!("  where they were: {}\n", kept.join(", ")));
    }
    out
}

/// Whether any sensor of `now` differs from `start` (by more than rounding).
pub(crate) fn rig_moved(start: &Rig, now: &Rig) -> bool {
    start.sensors.iter().any(|s| {
        now.sensor(&s.name)
            .is_some_and(|n| moved_by(s.vehicle_from_sensor, n.vehicle_from_sensor).is_some())
    })
}

/// The rotation (rad) and translation (m) between two poses of a sensor, if it moved by more
/// than rounding.
fn moved_by(from: Rigid, to: Rigid) -> Option<(f64, f64)> {
    let (rot, trans) = from.difference(to);
    (rot + trans > 1e-9).then_some((rot, trans))
}

/// The step and the time into the optimisation at which the extrinsics first changed: what a
/// user watching the run waits for (issue 5 asks for it within 5 s).
fn report_first_update(step: usize, seconds: f64) {
    use std::io::IsTerminal;
    let lead = if std::io::stderr().is_terminal() {
        "\n"
    } else {
        ""
    };
    eprintln!("{lead}first extrinsic update: step {step}, {seconds:.1} s into the optimisation");
}

/// `rigcal calibrate`: print the configuration (`--print-config`), or run the calibration
/// with a progress bar and write the file; how far each sensor moved, the report and the time
/// go to standard error.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    use anyhow::Context;
    if args.print_config {
        let config = super::pipeline::resolve_config(args).map_err(anyhow::Error::msg)?;
        return super::print_stdout(&config.to_yaml());
    }
    let started = std::time::Instant::now();
    let mut bar = super::progress::Progress::new("calibrate", 1);
    let (_, moves) = calibrate(args, &mut |done, total| bar.report(done, total))
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("cannot calibrate {}", args.log().display()))?;
    bar.finish();
    // After the bar: on a terminal it would be drawn over the report.
    eprint!("{moves}");
    eprintln!(
        "wrote {} in {:.1} s",
        args.out().display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Seconds between checkpoints of a running calibration.
const CHECKPOINT_SECS: f64 = 30.0;

/// The native file for the calibrator's best rig: sensors not asked for keep their initial
/// extrinsics; provenance (input, method, time range, init, version, status) and the latest
/// losses as metrics.
fn document(
    args: &CalibrateArgs,
    initial: &Rig,
    calibrator: &dyn Calibrator,
    losses: &[(String, f64)],
    status: String,
) -> CalibrationFile {
    let result = result_rig(args, initial, calibrator);
    document_of(args, &result, calibrator, losses, status)
}

/// The calibrator's best rig, with the sensors `--sensors` leaves out where `initial` has them.
fn result_rig(args: &CalibrateArgs, initial: &Rig, calibrator: &dyn Calibrator) -> Rig {
    let mut result: Rig = calibrator.best();
    if !args.sensors.is_empty() {
        for s in &mut result.sensors {
            if !args.sensors.contains(&s.name)
                && let Some(r) = initial.sensor(&s.name)
            {
                s.vehicle_from_sensor = r.vehicle_from_sensor;
            }
        }
    }
    result
}

/// The native file of `result`, with the run's provenance and losses.
fn document_of(
    args: &CalibrateArgs,
    result: &Rig,
    calibrator: &dyn Calibrator,
    losses: &[(String, f64)],
    status: String,
) -> CalibrationFile {
    let mut doc = CalibrationFile::from_rig(result);
    let v = |s: String| serde_yaml::Value::String(s);
    let input = std::path::absolute(args.log()).unwrap_or_else(|_| args.log().to_path_buf());
    doc.provenance
        .insert("input".into(), v(input.display().to_string()));
    doc.provenance
        .insert("method".into(), v(calibrator.name().to_string()));
    doc.provenance
        .insert("config".into(), serde_yaml::Value::Mapping(args.config()));
    doc.provenance
        .insert("date".into(), v(crate::util::now_utc()));
    if let Some(s) = &args.segment {
        doc.provenance
            .insert("time_range".into(), v(format!("{s} s")));
    }
    if let Some(i) = &args.init {
        doc.provenance
            .insert("init".into(), v(i.display().to_string()));
    }
    if let Ok(Some((deg, cm))) = args.perturbation() {
        doc.provenance.insert(
            "init_perturbed".into(),
            v(format!(
                "{deg}° and {cm} cm per sensor, seed {}",
                args.seed()
            )),
        );
    }
    doc.provenance.insert(
        "version".into(),
        v(format!("rigcal {}", env!("CARGO_PKG_VERSION"))),
    );
    doc.provenance.insert("status".into(), v(status));
    for (name, value) in losses {
        doc.metrics
            .insert(name.clone(), serde_yaml::Value::from(*value));
    }
    doc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_moves_report_names_each_sensor_largest_turn_first_and_the_ones_kept() {
        use crate::calib::{Sensor, SensorKind};
        use crate::geometry::so3;
        use glam::DVec3;
        let sensor = |name: &str| Sensor {
            name: name.into(),
            kind: SensorKind::Lidar,
            frame_id: name.into(),
            topics: Vec::new(),
            vehicle_from_sensor: Rigid::IDENTITY,
            camera: None,
        };
        let initial = Rig {
            vehicle_frame: "base_link".into(),
            sensors: vec![sensor("top"), sensor("front"), sensor("rear")],
        };
        let mut result = initial.clone();
        result.sensors[1].vehicle_from_sensor = Rigid::new(
            so3::exp(DVec3::new(0.0, 0.0, 0.5f64.to_radians())),
            DVec3::new(0.03, 0.0, 0.04),
        );
        result.sensors[2].vehicle_from_sensor = Rigid::new(
            so3::exp(DVec3::new(2f64.to_radians(), 0.0, 0.0)),
            DVec3::ZERO,
        );
        let report = moves_report(&initial, &result);
        let lines: Vec<&str> = report.lines().collect();
        assert_eq!(lines.len(), 4, "{report}");
        assert!(
            lines[1].contains("rear") && lines[1].contains("2.000°"),
            "{report}"
        );
        assert!(
            lines[2].contains("front") && lines[2].contains("0.500°"),
            "{report}"
        );
        assert!(lines[2].contains("5.00 cm"), "{report}");
        assert_eq!(lines[3], "  where they were: top");
    }

    #[test]
    fn segments_parse_in_seconds_from_the_start() {
        assert_eq!(
            parse_segment("1.5..4", 100),
            Ok((1_500_000_100, 4_000_000_100))
        );
        assert!(
            parse_segment("4..1", 0)
                .unwrap_err()
                .to_string()
                .contains("after")
        );
        assert!(
            parse_segment("a..1", 0)
                .unwrap_err()
                .to_string()
                .contains("'a'")
        );
        assert!(
            parse_segment("3", 0)
                .unwrap_err()
                .to_string()
                .contains("START..END")
        );
        // A segment must overlap the log: 100..200 s of an 8-second log is refused by name.
        let log = std::path::Path::new("drive.mcap");
        let range = (1_000, 1_000 + 8_000_000_000);
        let far = parse_segment("100..200", 1_000).unwrap();
        let err = check_segment_in_log("100..200", far, range, log).unwrap_err();
        assert!(
            err.to_string().contains("drive.mcap") && err.to_string().contains("0..8.0 s"),
            "{err}"
        );
        let inside = parse_segment("7..20", 1_000).unwrap();
        assert!(check_segment_in_log("7..20", inside, range, log).is_ok());
    }

    #[test]
    fn a_readout_parses_the_first_and_last_rows_milliseconds() {
        use crate::geometry::RowTimes;
        assert_eq!(
            parse_readout("-30..10"),
            Ok(RowTimes {
                first_row_nanos: -30_000_000,
                last_row_nanos: 10_000_000
            })
        );
        // Bottom up, and fractions of a millisecond.
        assert_eq!(
            parse_readout(" 12.5 .. -2.25 "),
            Ok(RowTimes::from_millis(12.5, -2.25))
        );
        for (bad, says) in [
            ("30", "FIRST..LAST"),
            ("a..10", "'a'"),
            ("-30..2000", "'2000'"),
            ("nan..0", "'nan'"),
        ] {
            let err = parse_readout(bad).unwrap_err();
            assert!(
                err.to_string().contains(says) && err.to_string().contains(bad),
                "{err}"
            );
        }
    }
}
