//! Progress reporting for long work: a bar on a terminal, plain lines otherwise.

use std::io::{IsTerminal, Write};
use std::time::Instant;

pub struct Progress {
    label: String,
    total: u64,
    done: u64,
    tty: bool,
    started: Instant,
    last_line_pct: u64,
}

impl Progress {
    pub fn new(label: &str, total: u64) -> Self {
        Self {
            label: label.into(),
            total: total.max(1),
            done: 0,
            tty: std::io::stderr().is_terminal(),
            started: Instant::now(),
            last_line_pct: 0,
        }
    }

    pub fn set_total(&mut self, total: u64) {
        self.total = total.max(1);
    }

    pub fn set(&mut self, done: u64) {
        self.done = done.min(self.total);
        let pct = self.done * 100 / self.total;
        let mut err = std::io::stderr();
        if self.tty {
            let width = 30;
            let filled = (self.done * width / self.total) as usize;
            let _ = write!(
                err,
                "\r{} [{}{}] {}/{} {:.1}s",
                self.label,
                "#".repeat(filled),
                " ".repeat(width as usize - filled),
                self.done,
                self.total,
                self.started.elapsed().as_secs_f64()
            );
            let _ = err.flush();
        } else if pct >= self.last_line_pct + 10
            || (self.done == self.total && self.last_line_pct < 100)
        {
            self.last_line_pct = pct;
            let _ = writeln!(err, "{}: {}/{} ({pct}%)", self.label, self.done, self.total);
        }
    }

    /// `done` of `total`: the shape of the library's `progress(done, total)` callbacks.
    pub fn report(&mut self, done: usize, total: usize) {
        self.set_total(total as u64);
        self.set(done as u64);
    }

    pub fn inc(&mut self) {
        self.set(self.done + 1);
    }

    pub fn finish(&mut self) {
        self.set(self.total);
        if self.tty {
            let _ = writeln!(std::io::stderr());
        }
    }
}

/// Bars for work in named phases, reported from any thread as `(phase, done, total)`: a new
/// bar when the phase changes (the previous one finished), never moving backwards within one.
#[derive(Default)]
pub struct PhasedProgress {
    bar: std::sync::Mutex<Option<(String, Progress)>>,
}

impl PhasedProgress {
    pub fn report(&self, phase: &str, done: usize, total: usize) {
        let Ok(mut bar) = self.bar.lock() else {
            return;
        };
        if bar.as_ref().is_none_or(|(p, _)| p != phase) {
            if let Some((_, previous)) = bar.as_mut() {
                previous.finish();
            }
            *bar = Some((phase.to_owned(), Progress::new(phase, total as u64)));
        }
        if let Some((_, progress)) = bar.as_mut() {
            progress.set_total(total as u64);
            progress.set((done as u64).max(progress.done));
        }
    }

    pub fn finish(&self) {
        if let Ok(mut bar) = self.bar.lock()
            && let Some((_, mut progress)) = bar.take()
        {
            progress.finish();
        }
    }
}
