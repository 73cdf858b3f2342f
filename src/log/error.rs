//! Errors and non-fatal problems of log ingestion.
//!
//! A bad *file* (unreadable, not MCAP, no usable records) is a [`LogError`]. A bad *message* in a
//! good file is a [`Problem`]: reported, skipped, never fatal.

use std::fmt;
use std::path::PathBuf;

use thiserror::Error;

#[derive(Debug, Error)]
pub enum LogError {
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: not an MCAP file: {what}")]
    NotMcap { path: PathBuf, what: String },
    #[error("{path}: corrupt at byte {offset}: {what}")]
    Corrupt {
        path: PathBuf,
        offset: u64,
        what: String,
    },
    #[error("{path}: topic {topic}, message at log time {log_time_nanos} ns: {what}")]
    Message {
        path: PathBuf,
        topic: String,
        log_time_nanos: u64,
        what: String,
    },
    #[error("{path}: {what}")]
    Unusable { path: PathBuf, what: String },
}

/// Something wrong in a file that was skipped; the rest of the log is still usable.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    pub topic: Option<String>,
    pub log_time_nanos: Option<u64>,
    pub what: String,
}

impl Problem {
    pub fn file(what: impl Into<String>) -> Self {
        Self {
            topic: None,
            log_time_nanos: None,
            what: what.into(),
        }
    }

    pub fn message(topic: &str, log_time_nanos: u64, what: impl Into<String>) -> Self {
        Self {
            topic: Some(topic.to_string()),
            log_time_nanos: Some(log_time_nanos),
            what: what.into(),
        }
    }
}

/// The most problems a log keeps; past it they are counted, not kept (a log of a million
/// damaged messages must not hold a million messages about them).
pub const MAX_PROBLEMS: usize = 10_000;

/// A log's problems, capped at [`MAX_PROBLEMS`] with a count of those dropped; reads as a
/// slice of the kept ones.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Problems {
    kept: Vec<Problem>,
    dropped: usize,
}

impl Problems {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn push(&mut self, problem: Problem) {
        if self.kept.len() < MAX_PROBLEMS {
            self.kept.push(problem);
        } else {
            self.dropped += 1;
        }
    }

    pub fn append(&mut self, other: Problems) {
        self.dropped += other.dropped;
        for p in other.kept {
            self.push(p);
        }
    }

    /// How many problems were counted past the cap and not kept.
    pub fn dropped(&self) -> usize {
        self.dropped
    }

    /// Every problem found: those kept and those dropped.
    pub fn total(&self) -> usize {
        self.kept.len() + self.dropped
    }
}

impl std::ops::Deref for Problems {
    type Target = [Problem];
    fn deref(&self) -> &[Problem] {
        &self.kept
    }
}

impl Extend<Problem> for Problems {
    fn extend<I: IntoIterator<Item = Problem>>(&mut self, iter: I) {
        for p in iter {
            self.push(p);
        }
    }
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.topic, self.log_time_nanos) {
            (Some(topic), Some(t)) => write!(
                f,
                "topic {topic}, message at log time {t} ns: {}",
                self.what
            ),
            (Some(topic), None) => write!(f, "topic {topic}: {}", self.what),
            _ => write!(f, "{}", self.what),
        }
    }
}

/// Error of decoding one message payload (CDR, protobuf, JSON, image); becomes a [`Problem`].
#[derive(Debug, Error, Clone, PartialEq)]
#[error("{0}")]
pub struct DecodeError(pub String);

impl DecodeError {
    pub fn new(what: impl Into<String>) -> Self {
        Self(what.into())
    }
}

pub type DecodeResult<T> = Result<T, DecodeError>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn problems_past_the_cap_are_counted_not_kept() {
        let mut a = Problems::new();
        a.extend((0..MAX_PROBLEMS + 5).map(|i| Problem::file(format!("p{i}"))));
        assert_eq!(
            (a.len(), a.dropped(), a.total()),
            (MAX_PROBLEMS, 5, MAX_PROBLEMS + 5)
        );
        let mut b = Problems::new();
        b.push(Problem::file("first"));
        b.append(a);
        assert_eq!((b.len(), b.dropped()), (MAX_PROBLEMS, 6));
        assert_eq!(b[0].what, "first");
    }
}
