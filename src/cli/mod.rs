//! Command-line front ends that are library code (so tests can call them): reports and
//! progress output. The binary in `main.rs` only parses arguments and dispatches.

pub mod calibrate;
pub mod eval;
pub mod inspect;
pub mod pipeline;
pub mod progress;
