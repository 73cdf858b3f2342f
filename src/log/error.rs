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
