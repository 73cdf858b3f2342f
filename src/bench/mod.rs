//! `rigcal bench`: the paper's evaluation protocols (method.md §13; supplementary A4) run on
//! simulated drives and on the real PandaSet drive, reported as Markdown tables in the paper's
//! layouts, CSV, JSON and PNG plots.
//!
//! How it works: a [`suite::Suite`] lists cases (protocol, row, method, drive, initial
//! perturbation, seed); identical runs shared by several tables run once. Each run
//! ([`case::run_case`]) starts from the reference calibration perturbed by the case's seeded
//! rotation and translation and records the errors after root alignment at every step
//! (convergence curves). Simulated drives are written once into `OUT/drives/` and reused by
//! later runs of the suite. One failed run is reported and the suite goes on.

pub mod case;
pub mod plot;
pub mod report;
pub mod suite;

/// Why a benchmark suite could not run or write its outputs (a failed *case* is not one: it is
/// a row of the report with its reason).
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// A suite's drive could not be simulated.
    #[error("cannot simulate {name}: {source}")]
    Simulate {
        name: String,
        source: crate::sim::synth::SimError,
    },
    /// A file or folder of the outputs, or a drive's, named in the message.
    #[error("{0}")]
    Output(String),
}

impl From<String> for BenchError {
    fn from(what: String) -> Self {
        Self::Output(what)
    }
}

impl From<&str> for BenchError {
    fn from(what: &str) -> Self {
        Self::Output(what.to_owned())
    }
}

use std::path::Path;
use std::time::Instant;

pub use report::BenchReport;
pub use suite::Suite;

/// What the bench is doing, for progress output.
#[derive(Clone, Debug, PartialEq)]
pub enum Stage<'a> {
    /// Simulating drive `name` (frames done, total).
    Simulating(&'a str),
    /// Run `index` of `runs` (1-based): its description.
    Running {
        index: usize,
        runs: usize,
        what: &'a str,
    },
}

/// Run every distinct case of `suite` and write `tables.md`, `results.csv`, `results.json`,
/// `convergence.png` and `error-vs-perturbation.png` into `out_dir` (atomically).
/// `progress(stage, done, total)` reports simulation frames and optimisation steps.
pub fn run_suite(
    suite: &Suite,
    out_dir: &Path,
    progress: &mut dyn FnMut(&Stage, usize, usize),
) -> Result<BenchReport, BenchError> {
    std::fs::create_dir_all(out_dir)
        .map_err(|e| format!("cannot create {}: {e}", out_dir.display()))?;
    // Fail on an unwritable folder now, not after an hour of runs.
    crate::util::write_atomic(&out_dir.join(".rigcal-bench"), b"rigcal bench output\n")
        .map_err(|e| format!("cannot write into {}: {e}", out_dir.display()))?;
    let started = Instant::now();
    let drives_dir = out_dir.join("drives");
    let runs = suite.runs();
    let mut results = Vec::with_capacity(runs.len());
    for (k, case) in runs.iter().enumerate() {
        let name = case.drive.name();
        let drive = case::ensure_drive(&case.drive, &drives_dir, &mut |d, t| {
            progress(&Stage::Simulating(&name), d, t)
        });
        let what = format!(
            "{} on {}, {}° / {} cm, seed {}",
            case.method.label(),
            name,
            case.perturb_deg,
            case.perturb_cm,
            case.seed
        );
        let stage = Stage::Running {
            index: k + 1,
            runs: runs.len(),
            what: &what,
        };
        let result = match drive {
            Ok((mcap, gt)) => case::run_case(case, &mcap, &gt, &mut |d, t| progress(&stage, d, t)),
            Err(e) => case::CaseResult::failed(case, Some(e.to_string())),
        };
        results.push(result);
    }
    let report = report::report(
        suite,
        results,
        machine(),
        crate::util::today_utc(),
        started.elapsed().as_secs_f64(),
    );
    write_outputs(&report, out_dir)?;
    Ok(report)
}

/// Write the report's files into `out_dir`.
pub fn write_outputs(report: &BenchReport, out_dir: &Path) -> Result<(), BenchError> {
    let write = |name: &str, bytes: &[u8]| {
        let path = out_dir.join(name);
        crate::util::write_atomic(&path, bytes)
            .map_err(|e| format!("cannot write {}: {e}", path.display()))
    };
    write("tables.md", report.to_markdown().as_bytes())?;
    write("results.csv", report.to_csv().as_bytes())?;
    let json = serde_json::to_string_pretty(report).map_err(|e| e.to_string())?;
    write("results.json", json.as_bytes())?;
    plot::convergence(report, &out_dir.join("convergence.png"))?;
    plot::error_vs_perturbation(report, &out_dir.join("error-vs-perturbation.png"))
}

/// "N cores, CPU model" of this machine (best effort).
pub fn machine() -> String {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, m)| m.trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    format!(
        "{cores} cores, {model}, {} threads",
        rayon::current_num_threads()
    )
}
