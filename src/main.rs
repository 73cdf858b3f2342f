//! The `rigcal` command line: argument parsing and dispatch only (docs/interfaces.md). Each
//! subcommand's options and the code that runs it are library code in `rigcal::cli`.

use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};
use rigcal::cli;

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
    Studio(cli::StudioArgs),
    /// Sensors, topics, counts, rates, time range, TF tree and problems of a log.
    Inspect(cli::inspect::InspectArgs),
    /// Calibrate a drive and write the native calibration file.
    #[command(after_help = cli::calibrate_args::CALIBRATE_EXAMPLES, allow_negative_numbers = true)]
    Calibrate(cli::calibrate::CalibrateArgs),
    /// Measure a calibration against a reference: pose errors after root alignment, and with a
    /// log the LiDAR–LiDAR, edge-alignment (and checkerboard, photometric) metrics on the data.
    Eval(cli::eval::EvalArgs),
    /// Run the paper's evaluation protocols on simulated drives and the PandaSet drive; write
    /// Markdown tables, CSV, JSON and PNG plots.
    Bench(cli::bench::BenchArgs),
    /// Write a calibration in another tool's format; every file names the direction of the
    /// transforms it holds.
    Export(cli::export::ExportArgs),
    /// Simulate a drive with known ground truth and write it as a ROS 2 MCAP.
    // A negative number is a value to check, not an unknown flag.
    #[command(allow_negative_numbers = true)]
    Synth(cli::synth::SynthArgs),
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("rigcal: {}", cli::usage::one_line(&e));
            ExitCode::FAILURE
        }
    }
}

/// For an unknown option of `calibrate` that moved to the configuration file, where it went.
fn moved_option(e: &clap::Error) -> Option<String> {
    if e.kind() != clap::error::ErrorKind::UnknownArgument
        || std::env::args().nth(1).as_deref() != Some("calibrate")
    {
        return None;
    }
    match e.get(clap::error::ContextKind::InvalidArg)? {
        clap::error::ContextValue::String(arg) => cli::calibrate_args::moved_option(arg),
        _ => None,
    }
}

fn run() -> Result<()> {
    let cli = match Cli::try_parse() {
        Ok(parsed) => parsed,
        Err(e) => {
            if let Some(said) = moved_option(&e) {
                eprintln!("rigcal: {said}");
                std::process::exit(2);
            }
            if e.use_stderr()
                && e.kind() != clap::error::ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
            {
                eprintln!("{}", cli::usage::one_line_usage(&e.render().to_string()));
                std::process::exit(2);
            }
            // Help and the version go to standard output, as clap prints them.
            e.exit()
        }
    };
    match cli.command {
        None => studio(&cli::StudioArgs::default()),
        Some(Command::Studio(args)) => studio(&args),
        Some(Command::Inspect(args)) => cli::inspect::run(&args),
        Some(Command::Calibrate(args)) => cli::calibrate::run(&args),
        Some(Command::Eval(args)) => cli::eval::run(&args),
        Some(Command::Bench(args)) => cli::bench::run(&args),
        Some(Command::Export(args)) => cli::export::run(&args),
        Some(Command::Synth(args)) => cli::synth::run(&args),
    }
}

#[cfg(feature = "app")]
fn studio(args: &cli::StudioArgs) -> Result<()> {
    rigcal::app::run(
        args.log.clone(),
        args.calibration.clone(),
        args.session.clone(),
    )
}

#[cfg(not(feature = "app"))]
fn studio(_args: &cli::StudioArgs) -> Result<()> {
    anyhow::bail!(
        "this build has no studio (built without the `app` feature); use the subcommands, e.g. `rigcal inspect LOG.mcap`"
    )
}

#[cfg(test)]
mod tests {
    use super::Cli;

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
