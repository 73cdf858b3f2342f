//! How the command line reports an error: on one line, the cause chain without repeats, and a
//! usage error without clap's usage block (which `--help` gives).

/// The error and its causes on one line, leaving out a cause whose text an outer message
/// already holds (the library's errors name their source in their own message).
pub fn one_line(error: &anyhow::Error) -> String {
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
pub fn one_line_usage(rendered: &str) -> String {
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

#[cfg(test)]
mod tests {
    use super::{one_line, one_line_usage};
    use clap::Args;

    /// `rigcal` with the two subcommands the cases use, built from their option types.
    fn command() -> clap::Command {
        clap::Command::new("rigcal")
            .subcommand(crate::cli::calibrate::CalibrateArgs::augment_args(
                clap::Command::new("calibrate"),
            ))
            .subcommand(crate::cli::eval::EvalArgs::augment_args(
                clap::Command::new("eval"),
            ))
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
            let Err(e) = command().try_get_matches_from(args) else {
                panic!("{args:?} parsed");
            };
            let line = one_line_usage(&e.render().to_string());
            assert!(!line.contains('\n'), "{line}");
            assert!(
                line.starts_with("rigcal: ") && line.ends_with("(see --help)"),
                "{line}"
            );
        }
        let Err(e) = command().try_get_matches_from(["rigcal", "calibrate", "d.mcap"]) else {
            panic!("parsed");
        };
        assert_eq!(
            one_line_usage(&e.render().to_string()),
            "rigcal: the following required arguments were not provided: --out <OUT> (see --help)"
        );
        // A bad value has no usage block, only the closing hint, which is not repeated.
        let Err(e) = command().try_get_matches_from(["rigcal", "eval", "--calibration"]) else {
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
