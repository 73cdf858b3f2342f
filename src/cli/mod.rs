//! The command line's front ends, as library code so tests can call them: each subcommand's
//! options (one clap `Args` type per command, the single definition of its flags) and the
//! function that runs it, with its progress output and reports. The binary in `main.rs` only
//! parses the arguments and dispatches.

pub mod bench;
pub mod calibrate;
pub mod calibrate_args;
pub mod eval;
pub mod export;
pub mod inspect;
pub mod pipeline;
pub mod progress;
pub mod synth;
pub mod usage;

use thiserror::Error;

/// Why a command could not do what it was asked; the message names the flag, file or sensor.
#[derive(Debug, Error)]
pub enum CliError {
    /// A flag, or a combination of flags, the command refuses.
    #[error("{0}")]
    Usage(String),
    /// The run produced a result it will not stand behind (it diverged); the message says
    /// where that result was written.
    #[error("{0}")]
    Failed(String),
    #[error(transparent)]
    Parse(#[from] crate::error::ParseError),
    #[error(transparent)]
    Run(#[from] crate::error::RunError),
    #[error(transparent)]
    Log(#[from] crate::log::LogError),
    #[error(transparent)]
    Config(#[from] crate::pipeline::config::ConfigError),
    #[error(transparent)]
    Plan(#[from] crate::pipeline::plan::PlanError),
    #[error(transparent)]
    CalibFile(#[from] crate::calib::CalibFileError),
    #[error(transparent)]
    Import(#[from] crate::interop::ImportError),
}

impl From<String> for CliError {
    fn from(what: String) -> Self {
        Self::Usage(what)
    }
}

impl From<&str> for CliError {
    fn from(what: &str) -> Self {
        Self::Usage(what.to_owned())
    }
}

// What the studio opens (`rigcal studio`, and `rigcal` alone; a plain comment: clap would take
// a doc comment for the subcommand's description).
#[derive(Clone, Debug, Default, clap::Args)]
pub struct StudioArgs {
    /// The log to open (default: the embedded demo drive).
    pub log: Option<std::path::PathBuf>,
    /// An initial calibration: a native file, URDF, ROS camera_info YAML or an MCAP's
    /// /tf_static (default: the log's /tf_static).
    #[arg(long)]
    pub calibration: Option<std::path::PathBuf>,
    /// Restore a saved session (its log, edits, segments, locks and view).
    #[arg(long)]
    pub session: Option<std::path::PathBuf>,
}

/// `text` on standard output. A reader that went away (`rigcal inspect LOG | head`) ends the
/// output quietly; any other failure (a full disk) is an error, not a panic as `print!` gives.
pub fn print_stdout(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(anyhow::anyhow!("cannot write to standard output: {e}"))
        }
        _ => Ok(()),
    }
}
