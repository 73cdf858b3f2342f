//! The one way rigcal parses YAML from a file or a user: calibration files, `--config`, `--init`
//! guesses (native, camera_info), a pasted transform.
//!
//! How it works: before the parser sees the text, [`from_str`] refuses text over
//! [`MAX_YAML_BYTES`] and flow collections (`[ … ]`, `{ … }`) nested deeper than
//! [`MAX_FLOW_NESTING`] (the parser's time grows steeply with that depth; its own recursion
//! limit stops block nesting). The depth scan follows YAML's quoting: a quote opens a quoted
//! scalar only where a scalar may start (at a line's start or after `:`, `-`, `,`, `?`, `[` or
//! `{`), so an apostrophe inside a plain scalar (`note: don't [[[[`) cannot hide brackets;
//! `#` starts a comment only after white space.

use serde::de::DeserializeOwned;

/// The deepest `[ … ]` / `{ … }` nesting accepted (a calibration file nests a few).
pub const MAX_FLOW_NESTING: usize = 64;
/// The largest YAML text accepted: a calibration or configuration is kilobytes.
pub const MAX_YAML_BYTES: usize = 64 << 20;

#[derive(Debug, thiserror::Error)]
pub enum YamlError {
    #[error("{bytes} bytes of YAML (at most {MAX_YAML_BYTES})")]
    TooLarge { bytes: usize },
    #[error("brackets nested {depth} deep (at most {MAX_FLOW_NESTING})")]
    TooDeep { depth: usize },
    #[error("{0}")]
    Syntax(#[from] serde_yaml::Error),
}

/// Parse `text` (a leading byte-order mark dropped) after the size and depth checks.
pub fn from_str<T: DeserializeOwned>(text: &str) -> Result<T, YamlError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    check(text)?;
    Ok(serde_yaml::from_str(text)?)
}

/// The size and depth checks alone.
pub fn check(text: &str) -> Result<(), YamlError> {
    if text.len() > MAX_YAML_BYTES {
        return Err(YamlError::TooLarge { bytes: text.len() });
    }
    let depth = flow_nesting_depth(text);
    if depth > MAX_FLOW_NESTING {
        return Err(YamlError::TooDeep { depth });
    }
    Ok(())
}

/// How deep flow collections nest in `text`, outside quoted scalars and comments. A quoted
/// scalar is taken to end with its line: one that runs on over-counts its next lines (a
/// refusal at worst), never hides a bracket of the text after it.
pub(crate) fn flow_nesting_depth(text: &str) -> usize {
    let (mut depth, mut deepest) = (0usize, 0usize);
    for line in text.lines() {
        let mut quote: Option<char> = None;
        let mut escaped = false;
        // The previous character, and the last one that is not white space, outside quotes.
        let (mut previous, mut significant) = (' ', '\n');
        for c in line.chars() {
            if let Some(q) = quote {
                if escaped {
                    escaped = false;
                } else if q == '"' && c == '\\' {
                    escaped = true;
                } else if c == q {
                    // `''` in a single-quoted scalar closes and at once reopens it: the same.
                    quote = None;
                    (previous, significant) = (c, c);
                }
                continue;
            }
            let scalar_may_start = (previous.is_whitespace()
                || matches!(previous, ':' | '-' | ',' | '?' | '[' | '{'))
                && matches!(significant, '\n' | ':' | '-' | ',' | '?' | '[' | '{');
            match c {
                '"' | '\'' if scalar_may_start => quote = Some(c),
                '#' if previous.is_whitespace() => break,
                '[' | '{' => {
                    depth += 1;
                    deepest = deepest.max(depth);
                }
                ']' | '}' => depth = depth.saturating_sub(1),
                _ => {}
            }
            previous = c;
            if !c.is_whitespace() {
                significant = c;
            }
        }
    }
    deepest
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_skips_quotes_and_comments() {
        assert_eq!(flow_nesting_depth("a: '[[[' # {{{\nb: [1, [2, {c: 3}]]"), 3);
        assert_eq!(flow_nesting_depth("a: \"x\\\"[[[\" \nb: []"), 1);
        // A quote left open at a line's end hides nothing on the next lines.
        let deep = format!("a: plain\n  'x\nb: {}1{}", "[".repeat(80), "]".repeat(80));
        assert_eq!(flow_nesting_depth(&deep), 80);
        // `x#y` is a plain scalar, not a comment.
        assert_eq!(flow_nesting_depth("a: x#y [[\n"), 2);
    }

    #[test]
    fn an_apostrophe_in_a_plain_scalar_hides_nothing() {
        let deep = format!("note: don't {}1{}", "[".repeat(80), "]".repeat(80));
        assert_eq!(flow_nesting_depth(&deep), 80);
        assert!(matches!(
            from_str::<serde_yaml::Value>(&deep),
            Err(YamlError::TooDeep { depth: 80 })
        ));
    }

    #[test]
    fn ordinary_yaml_parses() {
        let v: serde_yaml::Value = from_str("\u{feff}a: [1, {b: 'it''s'}]\n").unwrap();
        assert_eq!(v["a"][1]["b"].as_str(), Some("it's"));
        assert!(matches!(
            from_str::<serde_yaml::Value>("a: [1"),
            Err(YamlError::Syntax(_))
        ));
    }
}
