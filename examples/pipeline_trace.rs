#![allow(clippy::unwrap_used, clippy::expect_used)]
//! How the plain command's poses approach the truth step by step: the pipeline is planned and
//! prepared as `rigcal calibrate LOG --out FILE` does (default configuration, `--perturb-deg`,
//! `--perturb-cm` and `--seed` as given, or the log's own rig), then stepped; every
//! [`SETTLE_EVERY`] steps it prints the time, each sensor's error against the reference after
//! aligning the root (as `rigcal eval`), and how far the rig moved over the last 100 steps (the
//! statistic the settling criterion compares). It says which step a looser criterion would have
//! stopped at and what the errors were there, to judge the schedule and the early stop.
//! `cargo run --release --no-default-features --example pipeline_trace -- LOG REFERENCE [DEG CM SEED]`
//! (`RIGCAL_CONFIG=FILE`: the pipeline's configuration from a file, as `--config` reads it).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use rigcal::calib::Rig;
use rigcal::calib::dataset_json::load_reference;
use rigcal::geometry::rigid::rig_errors;
use rigcal::log::{Drive, DriveOptions};
use rigcal::optim::runner::Calibrator;
use rigcal::pipeline::calibrator::PipelineCalibrator;
use rigcal::pipeline::run::SETTLE_EVERY;
use rigcal::pipeline::{PipelineConfig, Plan, PlanRequest};

/// Largest rotation (deg) and translation (cm) any sensor moved between two rigs.
fn moved(a: &Rig, b: &Rig) -> (f64, f64) {
    a.sensors.iter().fold((0.0, 0.0), |(r, t), s| {
        let Some(o) = b.sensor(&s.name) else {
            return (r, t);
        };
        let (dr, dt) = s.vehicle_from_sensor.difference(o.vehicle_from_sensor);
        (r.max(dr.to_degrees()), t.max(dt * 100.0))
    })
}

fn errors(reference: &Rig, rig: &Rig, root: &str) -> Vec<(String, f64, f64)> {
    rig_errors(&reference.extrinsics(), &rig.extrinsics(), root)
        .unwrap()
        .into_iter()
        .map(|e| (e.sensor, e.rotation_deg, e.translation_m * 100.0))
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let log = PathBuf::from(&args[1]);
    let reference = load_reference(std::path::Path::new(&args[2])).unwrap();
    let drive = Drive::open_with(&log, &DriveOptions::default()).unwrap();
    let mut initial = drive.rig.clone();
    if args.len() >= 6 {
        let deg: f64 = args[3].parse().unwrap();
        let cm: f64 = args[4].parse().unwrap();
        let seed: u64 = args[5].parse().unwrap();
        initial = rigcal::sim::synth::perturb_rig(&initial, deg, cm, seed);
    }
    // `RIGCAL_CONFIG=FILE`: a configuration as `--config` reads it (e.g. `iterations: 600`).
    let config = match std::env::var("RIGCAL_CONFIG") {
        Ok(path) => PipelineConfig::load(std::path::Path::new(&path)).unwrap(),
        Err(_) => PipelineConfig::default(),
    };
    let request = PlanRequest {
        root: None,
        sensors: Vec::new(),
        segments_nanos: Vec::new(),
    };
    let started = Instant::now();
    let plan = Plan::build(&drive, &initial, &request, &config).unwrap();
    for line in &plan.decisions {
        eprintln!("plan: {line}");
    }
    let quiet = |_: &str, _: usize, _: usize| {};
    let mut run =
        PipelineCalibrator::prepare(Arc::new(drive), initial, plan, started, &quiet).unwrap();
    let root = reference.lidars().map(|s| s.name.clone()).next().unwrap();
    let mut history: Vec<(usize, f64, Rig)> = Vec::new();
    let print = |step: usize, secs: f64, rig: &Rig, window: Option<(f64, f64)>| {
        let e = errors(&reference, rig, &root);
        let worst_cam = e
            .iter()
            .filter(|(n, _, _)| {
                reference
                    .sensor(n)
                    .is_some_and(|s| s.kind == rigcal::calib::SensorKind::Camera)
            })
            .fold((0.0f64, 0.0f64), |(r, t), (_, er, et)| {
                (r.max(*er), t.max(*et))
            });
        let cells: Vec<String> = e
            .iter()
            .map(|(n, r, t)| format!("{n} {r:.3}/{t:.2}"))
            .collect();
        let w = window.map_or("-".into(), |(r, t)| format!("{r:.4}°/{:.3} mm", t * 10.0));
        println!(
            "step {step:5} {secs:7.1} s  worst camera {:.3}°/{:.2} cm  moved/100 {w}  | {}",
            worst_cam.0,
            worst_cam.1,
            cells.join("  ")
        );
    };
    print(0, started.elapsed().as_secs_f64(), &run.current(), None);
    let steps = run.max_steps();
    for step in 1..=steps {
        let r = run.step();
        if step.is_multiple_of(SETTLE_EVERY) || r.done {
            let rig = run.current();
            let secs = started.elapsed().as_secs_f64();
            let window = history
                .iter()
                .rev()
                .find(|(s, _, _)| *s + 100 <= step)
                .map(|(_, _, old)| moved(old, &rig));
            print(step, secs, &rig, window);
            history.push((step, secs, rig));
        }
        if r.done {
            break;
        }
    }
    if let Some(why) = run.stopped() {
        println!("{why}");
    }
    // Where each looser criterion (the rig moved less than this over 100 steps, from the step
    // the pipeline starts checking) would have stopped, and the errors there.
    let last = &history[history.len() - 1].2;
    for (deg, mm) in [(0.005, 0.5), (0.01, 1.0), (0.02, 2.0), (0.05, 5.0)] {
        let stop = history.iter().enumerate().find(|(i, (s, _, rig))| {
            history[..*i]
                .iter()
                .rev()
                .find(|(o, _, _)| *o + 100 <= *s)
                .is_some_and(|(_, _, old)| {
                    let (r, t) = moved(old, rig);
                    r <= deg && t * 10.0 <= mm
                })
        });
        match stop {
            Some((_, (s, secs, rig))) => {
                let (r, t) = moved(rig, last);
                println!(
                    "criterion {deg}°/{mm} mm over 100 steps: step {s} at {secs:.0} s; from there to the end {r:.3}°/{:.2} cm",
                    t
                );
            }
            None => println!("criterion {deg}°/{mm} mm over 100 steps: never"),
        }
    }
}
