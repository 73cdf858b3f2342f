//! `rigcal calibrate LOG --out FILE` with no method (or `--method auto`): the automatic
//! pipeline ([`crate::pipeline`]); `--method unical` is its UniCal stage alone. The plan's decisions are printed with their reasons, the
//! stages run with progress, UniCal runs until its schedule ends, every pose has settled or
//! the budget is spent, and the report ends the run: printed, and written in the output's
//! `metrics.report`. The output is written before the first step and every 30 s (atomically).

use super::CliError;
use std::path::PathBuf;
use std::time::Instant;

use crate::calib::{CalibrationFile, Rig};
use crate::optim::divergence::Guarded;
use crate::optim::runner::Calibrator;
use crate::pipeline::calibrator::PipelineCalibrator;
use crate::pipeline::plan::format_secs;
use crate::pipeline::{PipelineConfig, Plan, PlanRequest};

use super::calibrate::{CalibrateArgs, moves_report, open_inputs, record_skipped, rig_moved};

/// Seconds between checkpoints of a running calibration.
const CHECKPOINT_SECS: f64 = 30.0;

/// The configuration `args` asks for: `--config` (a `--print-config` output or an earlier
/// output file), then `--quality`, `--budget`, `--seed` and `--iterations` over it; with
/// `--method unical`, no classical LiDAR stage and no hand-eye.
pub fn resolve_config(args: &CalibrateArgs) -> Result<PipelineConfig, CliError> {
    let mut config = match &args.config_file {
        Some(path) => PipelineConfig::load(path).map_err(|e| format!("--config: {e}"))?,
        None => PipelineConfig::default(),
    };
    // A new quality, budget or step count plans afresh: what an earlier output resolved (its
    // images, scale, steps and the budget's cuts) gives way.
    if args.quality.is_some() || args.budget_secs.is_some() || args.iterations.is_some() {
        config.stop_at_step = None;
        config.budget_cuts.clear();
    }
    if let Some(q) = args.quality {
        config.quality = q;
        config.iterations = None;
        config.budget_secs = None;
        config.cameras.images_per_camera = None;
        config.cameras.image_scale = None;
    }
    if let Some(b) = args.budget_secs {
        config.budget_secs = Some(b);
        config.iterations = None;
    }
    if args.seed.is_some() || args.config_file.is_none() {
        config.seed = args.seed();
    }
    if let Some(n) = args.iterations {
        config.iterations = Some(n);
    }
    if args.method == "unical" {
        // UniCal alone: every sensor in one scene, no classical stage before it.
        config.lidars.register = false;
        config.cameras.hand_eye = crate::pipeline::config::HandEye::Never;
    }
    config.check()?;
    Ok(config)
}

/// Run the pipeline; `progress(step, steps)` follows UniCal's steps. Returns the written
/// document and the closing text (moves and report).
pub fn calibrate_auto(
    args: &CalibrateArgs,
    perturbation: Option<(f64, f64)>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(CalibrationFile, String), CliError> {
    let config = resolve_config(args)?;
    let options = crate::log::DriveOptions {
        camera_time_offset_nanos: (config.cameras.time_offset_ms * 1e6).round() as i64,
        camera_readout: match config.cameras.readout_ms {
            Some((a, b)) => crate::geometry::RowTimes::from_millis(a, b),
            None => crate::geometry::RowTimes::GLOBAL,
        },
        ..crate::log::DriveOptions::default()
    };
    let (drive, initial, segments) = open_inputs(args, &options, perturbation)?;
    let started = Instant::now();
    let request = PlanRequest {
        root: args.root.clone(),
        sensors: args.sensors.clone(),
        segments_nanos: segments,
    };
    let bars = super::progress::PhasedProgress::default();
    let plan = Plan::build(&drive, &initial, &request, &config)?;
    for line in &plan.decisions {
        eprintln!("plan: {line}");
    }
    let report_progress = |phase: &str, done, total| bars.report(phase, done, total);
    let drive = std::sync::Arc::new(drive);
    let run = PipelineCalibrator::prepare(
        drive.clone(),
        initial.clone(),
        plan,
        started,
        &report_progress,
    )?;
    bars.finish();
    for line in run.notes() {
        eprintln!("{line}");
    }
    // A NaN or an infinity ends the run with the best result before it.
    let mut run = Guarded::new(run);
    let write = |run: &Guarded<PipelineCalibrator>, status: String, losses: &[(String, f64)]| {
        // The skipped frames are said once, at the end.
        let last_write = status == "complete" || status.starts_with("diverged");
        let mut doc = document(
            args,
            &run.best(),
            run.inner().plan(),
            &run.inner().resolved_config(),
            status,
        );
        for (name, value) in losses {
            doc.metrics
                .insert(name.clone(), serde_yaml::Value::from(*value));
        }
        if let Some(r) = run.inner().report() {
            doc.metrics.insert("report".into(), r.to_yaml());
        }
        if last_write {
            record_skipped(&drive, &mut doc);
        }
        doc.save(args.out())
            .map_err(|e| e.to_string())
            .map(|()| doc)
    };
    let steps = run.max_steps();
    write(&run, format!("running: step 0 of {steps}"), &[])?;
    let mut saved_at = Instant::now();
    let mut last = Vec::new();
    let mut first_update = false;
    let optimising = Instant::now();
    for step in 1..=steps {
        let r = run.step();
        if !r.losses.is_empty() {
            last = r.losses;
        }
        if !first_update && rig_moved(&initial, &run.current()) {
            first_update = true;
            eprintln!(
                "first extrinsic update: step {step}, {:.1} s into the optimisation",
                optimising.elapsed().as_secs_f64()
            );
        }
        // The budget may shorten the schedule as the run goes.
        progress(step, run.max_steps());
        if r.done {
            break;
        }
        if saved_at.elapsed().as_secs_f64() >= CHECKPOINT_SECS {
            write(
                &run,
                format!("running: step {step} of {}", run.max_steps()),
                &last,
            )?;
            saved_at = Instant::now();
        }
    }
    if let Some(why) = run.inner().stopped() {
        eprintln!("\n{why}");
    }
    if let Some(why) = run.diverged() {
        write(&run, format!("diverged: {why}"), &last)?;
        return Err(CliError::Failed(format!(
            "{why}; that result is written to {}",
            args.out().display()
        )));
    }
    let doc = write(&run, "complete".into(), &last)?;
    let result = run.best();
    let report = run
        .inner()
        .report()
        .map(|r| r.to_text())
        .unwrap_or_default();
    let text = format!(
        "{}{report}total {}\n",
        moves_report(&initial, &result),
        format_secs(started.elapsed().as_secs_f64())
    );
    Ok((doc, text))
}

/// The native file of `rig` with the pipeline's provenance: the resolved configuration (which
/// `--config` reads back), the plan's decisions, input, date and status.
fn document(
    args: &CalibrateArgs,
    rig: &Rig,
    plan: &Plan,
    config: &PipelineConfig,
    status: String,
) -> CalibrationFile {
    let mut doc = CalibrationFile::from_rig(rig);
    let v = |s: String| serde_yaml::Value::String(s);
    let input: PathBuf =
        std::path::absolute(args.log()).unwrap_or_else(|_| args.log().to_path_buf());
    let p = &mut doc.provenance;
    p.insert("input".into(), v(input.display().to_string()));
    p.insert(
        "method".into(),
        v(if args.method == "unical" {
            "unical".into()
        } else {
            "pipeline".into()
        }),
    );
    p.insert(
        "config".into(),
        serde_yaml::to_value(config).unwrap_or(serde_yaml::Value::Null),
    );
    p.insert(
        "plan".into(),
        serde_yaml::Value::Sequence(plan.decisions.iter().cloned().map(v).collect()),
    );
    p.insert("date".into(), v(crate::util::now_utc()));
    if let Some(s) = &args.segment {
        p.insert("time_range".into(), v(format!("{s} s")));
    }
    if let Some(i) = &args.init {
        p.insert("init".into(), v(i.display().to_string()));
    }
    if let Some((deg, cm)) = args.perturb_given() {
        p.insert(
            "init_perturbed".into(),
            v(format!(
                "{deg}° and {cm} cm per sensor, seed {}",
                args.seed()
            )),
        );
    }
    p.insert(
        "version".into(),
        v(format!("rigcal {}", env!("CARGO_PKG_VERSION"))),
    );
    p.insert("status".into(), v(status));
    doc
}
