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
    ) -> Result<Self, String> {
        let prepared = super::run::prepare(&drive, &initial, &plan, progress)?;
        let stage = super::run::unical(&drive, &plan, &prepared, progress)?;
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
        c
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
        let (report, rig) = Report::build(
            &self.drive,
            &self.initial,
            &self.raw_best(),
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
        if !r.done && step >= self.steps {
            r.done = true;
        }
        if !r.done
            && step >= self.settle_from
            && step.is_multiple_of(SETTLE_EVERY)
            && self.settling.push(stage.current())
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
            && let Some(budget) = self.plan.config.budget_secs
            && self.started.elapsed().as_secs_f64() >= budget
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
