//! The whole pipeline as one [`Calibrator`]: the stages before UniCal run when it is prepared,
//! its steps are UniCal's, it ends when the schedule does, when every pose has settled or when
//! the budget is spent, and its last step checks the result ([`Report`]): the rig it then
//! reports as best has the unobserved axes back at the initial guess and the failed sensors at
//! it. The CLI steps it in its loop (with checkpoints), the studio in its background run.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use crate::calib::Rig;
use crate::log::Drive;
use crate::optim::runner::{Calibrator, StepReport};
use crate::unical::calibrator::UnicalLidarStage;

use super::config::PipelineConfig;
use super::plan::{Plan, format_secs};
use super::report::Report;
use super::run::{Prepared, Progress, SETTLE_EVERY, Settling};

/// Seconds kept from the budget for the report at the end of a run.
const REPORT_MARGIN_SECS: f64 = 20.0;

/// Where a finished run leaves its report (the studio's checks tab reads it).
pub type ReportSink = Arc<Mutex<Option<Report>>>;

pub struct PipelineCalibrator {
    drive: Arc<Drive>,
    initial: Rig,
    plan: Plan,
    prepared: Prepared,
    stage: Option<UnicalLidarStage>,
    step: usize,
    steps: usize,
    started: Instant,
    settling: Settling,
    settle_from: usize,
    stopped: Option<String>,
    stop_at_step: Option<usize>,
    /// The budget's shortenings made so far, and when the last check was (step, seconds).
    cuts: Vec<(usize, usize)>,
    last_check: (usize, f64),
    finished: Option<(Report, Rig)>,
    sink: Option<ReportSink>,
}

impl PipelineCalibrator {
    /// Run the plan's stages before UniCal on `initial` and build UniCal's calibrator.
    /// `started` is when the run began (the budget counts from it).
    pub fn prepare(
        drive: Arc<Drive>,
        initial: Rig,
        plan: Plan,
        started: Instant,
        progress: Progress,
    ) -> Result<Self, crate::error::RunError> {
        let prepared = super::run::prepare(&drive, &initial, &plan, progress)?;
        // The stages before UniCal dropped their images and maps: their memory goes back
        // before UniCal's tables are allocated (BENCHMARKS.md, "Issue 59's yardstick").
        crate::util::release_freed();
        let stage = super::run::unical(&drive, &plan, &prepared, progress)?;
        // UniCal keeps its own copies of what it read: the log's caches of decoded images
        // and decompressed chunks go too.
        drive.release_caches();
        crate::util::release_freed();
        let steps = match &stage {
            Some(s) => plan
                .config
                .stop_at_step
                .map_or(s.max_steps(), |k| k.min(s.max_steps())),
            None => 0,
        };
        // Poses settle only once every hash level is open and the rates have decayed.
        let settle_from = (plan.unical.iterations as f32
            * plan
                .unical
                .coarse_to_fine
                .map_or(0.5, |c| c.end_fraction.max(0.5))) as usize;
        // The pace is measured from the first step, not from the start of the preparation.
        let prepared_at = started.elapsed().as_secs_f64();
        Ok(Self {
            drive,
            initial,
            plan,
            prepared,
            stage,
            step: 0,
            steps,
            started,
            settling: Settling::default(),
            settle_from,
            stopped: None,
            stop_at_step: None,
            cuts: Vec::new(),
            last_check: (0, prepared_at),
            finished: None,
            sink: None,
        })
    }

    /// Leave the report in `sink` when the run ends.
    pub fn with_report_sink(mut self, sink: ReportSink) -> Self {
        self.sink = Some(sink);
        self
    }

    /// What the stages before UniCal did, one line each.
    pub fn notes(&self) -> &[String] {
        &self.prepared.notes
    }

    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// Why the run ended before its schedule did, if it did.
    pub fn stopped(&self) -> Option<&str> {
        self.stopped.as_deref()
    }

    /// The report, once the run has ended.
    pub fn report(&self) -> Option<&Report> {
        self.finished.as_ref().map(|(r, _)| r)
    }

    /// The configuration that repeats this run: the plan's, with the step a budget stopped it
    /// at.
    pub fn resolved_config(&self) -> PipelineConfig {
        let mut c = self.plan.config.clone();
        if self.stop_at_step.is_some() {
            c.stop_at_step = self.stop_at_step;
        }
        if c.budget_cuts.is_empty() {
            c.budget_cuts = self.cuts.clone();
        }
        c
    }

    /// Fit the rest of the schedule to the budget: at a quarter, half and three quarters of
    /// the run, the steps since the last check give the pace, and a schedule that would end
    /// past the budget (less a margin for the report) is shortened to end within it. A
    /// configuration that records its cuts replays them instead.
    fn fit_budget(&mut self, step: usize) {
        let Some(stage) = self.stage.as_mut() else {
            return;
        };
        let recorded = &self.plan.config.budget_cuts;
        if !recorded.is_empty() {
            if let Some(&(_, n)) = recorded.iter().find(|(k, _)| *k == step) {
                stage.set_iterations(n);
                self.steps = stage
                    .max_steps()
                    .min(self.plan.config.stop_at_step.unwrap_or(usize::MAX));
            }
            return;
        }
        let Some(budget) = self.plan.config.budget_secs else {
            return;
        };
        if self.plan.config.stop_at_step.is_some() {
            return;
        }
        let total = self.steps;
        let checks = [total / 4, total / 2, 3 * total / 4];
        if !checks.contains(&step) {
            return;
        }
        let now = self.started.elapsed().as_secs_f64();
        let (since_step, since_secs) = self.last_check;
        self.last_check = (step, now);
        if step <= since_step {
            return;
        }
        let pace = (now - since_secs) / (step - since_step) as f64;
        let left = budget - now - REPORT_MARGIN_SECS;
        let fits = step + (left.max(0.0) / pace.max(1e-6)) as usize;
        if fits < total {
            // Not below the poses' warm-up and ramp: they would never move.
            let least = self.plan.unical.pose_warmup + self.plan.unical.pose_ramp;
            let n = fits.max(step + 1).max(least.min(total));
            stage.set_iterations(n);
            self.steps = stage.max_steps();
            self.cuts.push((step, self.steps));
        }
    }

    /// UniCal's best rig, or the prepared one, with the sensors not asked for at the initial
    /// guess.
    fn raw_best(&self) -> Rig {
        let mut rig = match &self.stage {
            Some(s) => s.best(),
            None => self.prepared.rig.clone(),
        };
        let asked = &self.plan.request.sensors;
        if !asked.is_empty() {
            for s in &mut rig.sensors {
                if !asked.contains(&s.name)
                    && let Some(r) = self.initial.sensor(&s.name)
                {
                    s.vehicle_from_sensor = r.vehicle_from_sensor;
                }
            }
        }
        rig
    }

    fn finish(&mut self) {
        let best = self.raw_best();
        // The report needs UniCal's result, not its tables: they go before it decodes images.
        self.stage = None;
        crate::util::release_freed();
        let (report, rig) = Report::build(
            &self.drive,
            &self.initial,
            &best,
            &self.plan,
            &self.prepared.lidars,
        );
        if let Some(sink) = &self.sink
            && let Ok(mut slot) = sink.lock()
        {
            *slot = Some(report.clone());
        }
        self.finished = Some((report, rig));
    }
}

impl Calibrator for PipelineCalibrator {
    fn name(&self) -> &str {
        "pipeline"
    }

    fn max_steps(&self) -> usize {
        self.steps.max(1)
    }

    fn step(&mut self) -> StepReport {
        if self.finished.is_some() {
            return StepReport {
                losses: Vec::new(),
                done: true,
            };
        }
        let Some(stage) = self.stage.as_mut() else {
            self.finish();
            return StepReport {
                losses: Vec::new(),
                done: true,
            };
        };
        let mut r = stage.step();
        self.step += 1;
        let step = self.step;
        self.fit_budget(step);
        if !r.done && step >= self.steps {
            r.done = true;
        }
        let current = self.stage.as_ref().map(|s| s.current());
        if !r.done
            && step >= self.settle_from
            && step.is_multiple_of(SETTLE_EVERY)
            && let Some(current) = current
            && self.settling.push(current)
        {
            self.stopped = Some(format!(
                "stopped at step {step} of {}: every pose has settled ({})",
                self.steps,
                Settling::describe()
            ));
            r.done = true;
        }
        if !r.done
            && self.plan.config.stop_at_step.is_none()
            && self.plan.config.budget_cuts.is_empty()
            && let Some(budget) = self.plan.config.budget_secs
            && self.started.elapsed().as_secs_f64() >= budget - REPORT_MARGIN_SECS
        {
            self.stopped = Some(format!(
                "stopped at step {step} of {}: the budget of {} is spent (the output's configuration records stop_at_step {step}, which repeats this run)",
                self.steps,
                format_secs(budget)
            ));
            self.stop_at_step = Some(step);
            r.done = true;
        }
        if r.done {
            self.finish();
        }
        r
    }

    fn current(&self) -> Rig {
        match (&self.finished, &self.stage) {
            (Some((_, rig)), _) => rig.clone(),
            (None, Some(s)) => s.current(),
            (None, None) => self.prepared.rig.clone(),
        }
    }

    fn best(&self) -> Rig {
        match &self.finished {
            Some((_, rig)) => rig.clone(),
            None => self.raw_best(),
        }
    }
}
