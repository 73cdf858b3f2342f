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

#[derive(Subcommand)]
enum Command {
    /// The studio (the default when no command is given).
    Studio {
        log: Option<PathBuf>,
        #[arg(long)]
        calibration: Option<PathBuf>,
    },
    /// Sensors, topics, counts, rates, time range, TF tree and problems of a log.
    Inspect {
        log: PathBuf,
        /// Fixed frame of the trajectory (default: the parent of the densest /tf edge).
        #[arg(long)]
        fixed_frame: Option<String>,
        /// The vehicle frame (default: the child of that edge).
        #[arg(long)]
        vehicle_frame: Option<String>,
    },
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("rigcal: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        None => studio(None, None),
        Some(Command::Studio { log, calibration }) => studio(log, calibration),
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
            print!("{}", rigcal::cli::inspect::report(&drive));
            Ok(())
        }
    }
}

#[cfg(feature = "app")]
fn studio(log: Option<PathBuf>, calibration: Option<PathBuf>) -> Result<()> {
    rigcal::app::run(log, calibration)
}

#[cfg(not(feature = "app"))]
fn studio(_log: Option<PathBuf>, _calibration: Option<PathBuf>) -> Result<()> {
    anyhow::bail!(
        "this build has no studio (built without the `app` feature); use the subcommands, e.g. `rigcal inspect LOG.mcap`"
    )
}
