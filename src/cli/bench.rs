//! `rigcal bench`: run an evaluation suite ([`crate::bench`]) with a progress bar per run and
//! print its tables.

use std::path::PathBuf;

use anyhow::Context;

use crate::bench::{Stage, Suite};

// What `rigcal bench` takes (a plain comment: clap would take a doc comment for the
// subcommand's description).
#[derive(Clone, Debug, clap::Args)]
pub struct BenchArgs {
    /// quick (≤ 10 minutes on two cores, release build) | paper (the full protocol: a day or more)
    #[arg(long, default_value = "quick")]
    pub suite: String,
    /// Folder for the tables, CSV, JSON, plots and the simulated drives.
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
    /// Folder of the PandaSet drive (pandaset-002.mcap + ground_truth.json); skipped when
    /// it is not there.
    #[arg(long, default_value = "../shared/data/pandaset-002")]
    pub pandaset: PathBuf,
    /// Seeds per perturbation level (default: the suite's).
    #[arg(long)]
    pub seeds: Option<u64>,
}

/// Run the suite into `args.out` and print its tables.
pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    let make: fn(Option<PathBuf>) -> Suite = match args.suite.as_str() {
        "quick" => Suite::quick,
        "paper" => Suite::paper,
        other => anyhow::bail!("unknown --suite '{other}' (expected quick or paper)"),
    };
    let pandaset = args
        .pandaset
        .join("pandaset-002.mcap")
        .is_file()
        .then(|| args.pandaset.clone());
    if pandaset.is_none() {
        eprintln!("rigcal bench: no PandaSet drive found (--pandaset); its rows are skipped");
    }
    let mut chosen = make(pandaset);
    if let Some(n) = args.seeds {
        anyhow::ensure!(n >= 1, "--seeds 0: expected at least one seed per case");
        chosen = chosen.with_seeds(n);
    }
    eprintln!(
        "rigcal bench --suite {}: {} runs for {} table cells, into {}",
        args.suite,
        chosen.runs().len(),
        chosen.cases.len(),
        args.out.display()
    );
    // One bar per stage (a simulated drive, a run), replaced when the stage changes.
    let mut bar: Option<(String, super::progress::Progress)> = None;
    let report = crate::bench::run_suite(&chosen, &args.out, &mut |stage, done, total| {
        let label = match stage {
            Stage::Simulating(name) => format!("simulate {name}"),
            Stage::Running { index, runs, what } => format!("run {index}/{runs}: {what}"),
        };
        if bar.as_ref().is_none_or(|(l, _)| *l != label) {
            if let Some((_, b)) = bar.as_mut() {
                b.finish();
            }
            bar = Some((label.clone(), super::progress::Progress::new(&label, 1)));
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
    super::print_stdout(&report.to_markdown())?;
    eprintln!(
        "wrote tables.md, results.csv, results.json, convergence.png and error-vs-perturbation.png into {} ({:.0} s)",
        args.out.display(),
        report.total_secs
    );
    Ok(())
}
