//! Background optimisation runs: a worker thread steps a [`Calibrator`] and publishes
//! [`Packet`]s on a channel; the caller (CLI or studio) polls them and never waits.
//!
//! Control is a shared atomic (run / pause / stop). Packets are sent at most every 100 ms while
//! running (so ≥ 2 Hz whenever steps are faster than 0.5 s) and always for the last step. A
//! stopped run ends with a final packet carrying the best rig found so far.

use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::divergence::Guarded;
use crate::calib::Rig;

/// What one step of a calibrator reports.
#[derive(Clone, Debug, PartialEq)]
pub struct StepReport {
    /// Named loss terms of the current state (e.g. "edge_px/front_camera").
    pub losses: Vec<(String, f64)>,
    /// The optimiser has converged; the run ends.
    pub done: bool,
}

/// A calibration method that can be stepped.
pub trait Calibrator: Send {
    fn name(&self) -> &str;
    /// Upper bound on the number of steps (for progress and ETA).
    fn max_steps(&self) -> usize;
    fn step(&mut self) -> StepReport;
    /// The rig at the current state.
    fn current(&self) -> Rig;
    /// The best rig seen (lowest total loss).
    fn best(&self) -> Rig;
    /// Sensors whose result the method itself rejects, each with why (e.g. mutual
    /// information's search stopped at its bound); the front end keeps their initial guess.
    fn failures(&self) -> Vec<(String, String)> {
        Vec::new()
    }
}

/// A message from the worker.
#[derive(Clone, Debug)]
pub struct Packet {
    pub step: usize,
    pub max_steps: usize,
    pub steps_per_sec: f64,
    pub losses: Vec<(String, f64)>,
    pub current: Rig,
    pub best: Rig,
    pub finished: bool,
    /// Set when the run could not start (preparation failed); nothing else is meaningful then.
    pub error: Option<String>,
    /// Why a finished run stopped early, for the user (it diverged: [`Guarded`]).
    pub note: Option<String>,
}

const RUN: u8 = 0;
const PAUSE: u8 = 1;
const STOP: u8 = 2;

/// How far a run's preparation has got, `(phase, done, total)`: written by the worker while it
/// prepares, read by the caller (the studio's progress bar).
#[derive(Clone, Debug, Default)]
pub struct Preparing(Arc<Mutex<Option<(String, usize, usize)>>>);

impl Preparing {
    /// Record progress; within one phase `done` never moves backwards (reports may come from
    /// several threads out of order).
    pub fn report(&self, phase: &str, done: usize, total: usize) {
        if let Ok(mut now) = self.0.lock() {
            let done = match now.as_ref() {
                Some((p, d, _)) if p == phase => done.max(*d),
                _ => done,
            };
            *now = Some((phase.to_owned(), done, total));
        }
    }

    pub fn get(&self) -> Option<(String, usize, usize)> {
        self.0.lock().ok().and_then(|now| now.clone())
    }
}

/// Handle of a running optimisation.
pub struct Run {
    control: Arc<AtomicU8>,
    pub packets: Receiver<Packet>,
    /// The preparation's progress (stays at its last report once stepping starts).
    pub preparing: Preparing,
    thread: Option<JoinHandle<()>>,
}

impl Run {
    /// Start stepping `calibrator` on a new thread.
    pub fn spawn(calibrator: Box<dyn Calibrator>) -> Self {
        Self::spawn_with(move || Ok::<_, std::convert::Infallible>(calibrator))
    }

    /// Prepare a calibrator on the worker thread (loading images, building problems: slow work
    /// the UI must not wait on), then step it. A failed preparation sends one packet with
    /// `error` set (the error's message).
    pub fn spawn_with<F, E>(prepare: F) -> Self
    where
        F: FnOnce() -> Result<Box<dyn Calibrator>, E> + Send + 'static,
        E: std::fmt::Display,
    {
        Self::spawn_preparing(move |_| prepare())
    }

    /// [`Run::spawn_with`] for a preparation that reports its progress ([`Run::preparing`]).
    pub fn spawn_preparing<F, E>(prepare: F) -> Self
    where
        F: FnOnce(&Preparing) -> Result<Box<dyn Calibrator>, E> + Send + 'static,
        E: std::fmt::Display,
    {
        let control = Arc::new(AtomicU8::new(RUN));
        let (tx, rx) = channel();
        let ctl = control.clone();
        let preparing = Preparing::default();
        let status = preparing.clone();
        let thread = std::thread::Builder::new()
            .name("rigcal-optimiser".into())
            .spawn(move || match prepare(&status) {
                Ok(c) => worker(&mut Guarded::new(c), &ctl, &tx),
                Err(e) => {
                    let _ = tx.send(Packet {
                        step: 0,
                        max_steps: 0,
                        steps_per_sec: 0.0,
                        losses: Vec::new(),
                        current: Rig::default(),
                        best: Rig::default(),
                        finished: true,
                        error: Some(e.to_string()),
                        note: None,
                    });
                }
            })
            .ok();
        Self {
            control,
            packets: rx,
            preparing,
            thread,
        }
    }

    pub fn pause(&self) {
        let _ = self
            .control
            .compare_exchange(RUN, PAUSE, Ordering::SeqCst, Ordering::SeqCst);
    }

    pub fn resume(&self) {
        let _ = self
            .control
            .compare_exchange(PAUSE, RUN, Ordering::SeqCst, Ordering::SeqCst);
    }

    pub fn stop(&self) {
        self.control.store(STOP, Ordering::SeqCst);
    }

    pub fn is_paused(&self) -> bool {
        self.control.load(Ordering::SeqCst) == PAUSE
    }

    /// Whether the worker thread has ended.
    pub fn is_finished(&self) -> bool {
        self.thread.as_ref().is_none_or(|t| t.is_finished())
    }

    /// Wait for the worker to end and return every packet not yet received.
    pub fn join(mut self) -> Vec<Packet> {
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        self.packets.try_iter().collect()
    }
}

impl Drop for Run {
    fn drop(&mut self) {
        self.stop();
    }
}

fn worker(c: &mut Guarded<Box<dyn Calibrator>>, control: &AtomicU8, tx: &Sender<Packet>) {
    let started = Instant::now();
    let mut last_sent = Instant::now() - Duration::from_secs(1);
    let max_steps = c.max_steps();
    let mut step = 0;
    let mut paused_for = Duration::ZERO;
    loop {
        match control.load(Ordering::SeqCst) {
            STOP => break,
            PAUSE => {
                let t = Instant::now();
                std::thread::sleep(Duration::from_millis(20));
                paused_for += t.elapsed();
                continue;
            }
            _ => {}
        }
        let report = c.step();
        step += 1;
        let done = report.done || step >= max_steps;
        if done || last_sent.elapsed() >= Duration::from_millis(100) {
            let active = started.elapsed().saturating_sub(paused_for);
            let p = Packet {
                step,
                max_steps,
                steps_per_sec: step as f64 / active.as_secs_f64().max(1e-9),
                losses: report.losses,
                current: c.current(),
                best: c.best(),
                finished: done,
                error: None,
                note: c.diverged().map(str::to_owned),
            };
            if tx.send(p).is_err() {
                return; // nobody listens any more
            }
            last_sent = Instant::now();
        }
        if done {
            return;
        }
    }
    // Stopped: a final packet with the best result.
    let active = started.elapsed().saturating_sub(paused_for);
    let _ = tx.send(Packet {
        step,
        max_steps,
        steps_per_sec: step as f64 / active.as_secs_f64().max(1e-9),
        losses: Vec::new(),
        current: c.current(),
        best: c.best(),
        finished: true,
        error: None,
        note: None,
    });
}

/// [`Calibrator::failures`] of searches bounded around the initial guess: each sensor with the
/// bounds its best pose sits on (empty: inside them) fails where it sits on one, since a pose on
/// a bound is where `method` was stopped, not an optimum.
pub fn bound_failures<'a>(
    method: &str,
    at_bounds: impl Iterator<Item = (&'a str, String)>,
) -> Vec<(String, String)> {
    at_bounds
        .filter(|(_, at)| !at.is_empty())
        .map(|(name, at)| {
            (
                name.to_string(),
                format!(
                    "{method} ran to its bounds ({at} from the initial guess): a pose on a bound is not an optimum"
                ),
            )
        })
        .collect()
}

/// A borrowed or boxed calibrator steps as the one inside it (so a caller or a front end can
/// wrap one in [`Guarded`]).
macro_rules! forward_calibrator {
    ($($wrapper:ty),*) => {$(
        impl<C: Calibrator + ?Sized> Calibrator for $wrapper {
            fn name(&self) -> &str {
                (**self).name()
            }
            fn max_steps(&self) -> usize {
                (**self).max_steps()
            }
            fn step(&mut self) -> StepReport {
                (**self).step()
            }
            fn current(&self) -> Rig {
                (**self).current()
            }
            fn best(&self) -> Rig {
                (**self).best()
            }
            fn failures(&self) -> Vec<(String, String)> {
                (**self).failures()
            }
        }
    )*};
}
forward_calibrator!(&mut C, Box<C>);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preparation_progress_reaches_the_caller_and_never_moves_back_within_a_phase() {
        let p = Preparing::default();
        assert_eq!(p.get(), None);
        p.report("loading", 3, 10);
        p.report("loading", 2, 10); // a late report from another thread
        assert_eq!(p.get(), Some(("loading".into(), 3, 10)));
        p.report("matching", 0, 40);
        assert_eq!(p.get(), Some(("matching".into(), 0, 40)));
        // Through a run: the worker's reports are what the caller sees, and a failed
        // preparation still ends with its error packet.
        let run = Run::spawn_preparing(|preparing| {
            preparing.report("matching", 7, 9);
            Err::<Box<dyn Calibrator>, _>("no cameras")
        });
        let status = run.preparing.clone();
        let packets = run.join();
        assert_eq!(status.get(), Some(("matching".into(), 7, 9)));
        assert_eq!(packets.len(), 1);
        assert_eq!(packets[0].error.as_deref(), Some("no cameras"));
    }
}
