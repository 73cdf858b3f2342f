//! A run that diverges stops, keeping the best result it had.
//!
//! [`Guarded`] wraps any [`Calibrator`]. After every step it checks the step's losses and every
//! pose of the current rig: the first loss that is NaN or infinite, or the first pose with a
//! component that is not finite, ends the run (the step reports `done`) with a message naming
//! the step and what went wrong. From then on [`Calibrator::current`] and
//! [`Calibrator::best`] return the last rigs that were finite, so a front end writes (or
//! shows) the best result seen before the divergence and never a NaN pose. The CLI, the
//! studio's worker and the pipeline all step through it.

use crate::calib::Rig;

use super::runner::{Calibrator, StepReport};

/// A calibrator whose run ends at the first non-finite loss or pose.
pub struct Guarded<C> {
    inner: C,
    steps: usize,
    last_current: Rig,
    last_best: Rig,
    diverged: Option<String>,
}

impl<C: Calibrator> Guarded<C> {
    pub fn new(inner: C) -> Self {
        let last_current = inner.current();
        let last_best = inner.best();
        Self {
            inner,
            steps: 0,
            last_current,
            last_best,
            diverged: None,
        }
    }

    /// Why the run stopped, if it diverged: the step and the first loss or pose that was not
    /// finite.
    pub fn diverged(&self) -> Option<&str> {
        self.diverged.as_deref()
    }

    pub fn inner(&self) -> &C {
        &self.inner
    }
}

/// The first sensor of `rig` whose pose has a component that is not finite.
fn non_finite_pose(rig: &Rig) -> Option<&str> {
    rig.sensors.iter().find_map(|s| {
        let t = s.vehicle_from_sensor;
        let finite = t.translation.is_finite() && t.rotation.is_finite();
        (!finite).then_some(s.name.as_str())
    })
}

impl<C: Calibrator> Calibrator for Guarded<C> {
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn failures(&self) -> Vec<(String, String)> {
        self.inner.failures()
    }

    fn max_steps(&self) -> usize {
        self.inner.max_steps()
    }

    fn step(&mut self) -> StepReport {
        if self.diverged.is_some() {
            return StepReport {
                losses: Vec::new(),
                done: true,
            };
        }
        let mut report = self.inner.step();
        self.steps += 1;
        let step = self.steps;
        let bad_loss = report
            .losses
            .iter()
            .find(|(_, v)| !v.is_finite())
            .map(|(name, v)| format!("step {step}: the loss '{name}' became {v}"));
        let current = self.inner.current();
        let bad_pose = non_finite_pose(&current)
            .map(|name| format!("step {step}: the pose of '{name}' is not finite"));
        if let Some(why) = bad_loss.or(bad_pose) {
            self.diverged = Some(format!(
                "the run diverged at {why}; it stopped there and keeps the best result before it"
            ));
            report.losses.retain(|(_, v)| v.is_finite());
            report.done = true;
            return report;
        }
        self.last_current = current;
        let best = self.inner.best();
        if non_finite_pose(&best).is_none() {
            self.last_best = best;
        }
        report
    }

    fn current(&self) -> Rig {
        if self.diverged.is_some() {
            self.last_current.clone()
        } else {
            self.inner.current()
        }
    }

    fn best(&self) -> Rig {
        self.last_best.clone()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::calib::{Sensor, SensorKind};
    use crate::geometry::Rigid;
    use glam::DVec3;

    /// Moves one LiDAR 1 cm a step along x; from step `nan_at` on its loss is NaN and, a step
    /// later, its pose too.
    pub(crate) struct Diverging {
        pub x_m: f64,
        pub steps: usize,
        pub nan_at: usize,
        pub nan_in_pose: bool,
    }

    impl Diverging {
        pub(crate) fn rig(x_m: f64) -> Rig {
            Rig {
                sensors: vec![Sensor {
                    name: "lidar".into(),
                    kind: SensorKind::Lidar,
                    frame_id: "lidar".into(),
                    topics: Vec::new(),
                    vehicle_from_sensor: Rigid::from_translation(DVec3::new(x_m, 0.0, 0.0)),
                    camera: None,
                }],
                ..Rig::default()
            }
        }
    }

    impl Calibrator for Diverging {
        fn name(&self) -> &str {
            "diverging"
        }
        fn max_steps(&self) -> usize {
            100
        }
        fn step(&mut self) -> StepReport {
            self.steps += 1;
            let broken = self.steps >= self.nan_at;
            self.x_m = if broken && self.nan_in_pose {
                f64::NAN
            } else {
                self.x_m + 0.01
            };
            let loss = if broken && !self.nan_in_pose {
                f64::NAN
            } else {
                1.0 / self.steps as f64
            };
            StepReport {
                losses: vec![("total".into(), loss)],
                done: false,
            }
        }
        fn current(&self) -> Rig {
            Self::rig(self.x_m)
        }
        fn best(&self) -> Rig {
            Self::rig(self.x_m)
        }
    }

    #[test]
    fn a_nan_loss_stops_the_run_and_keeps_the_last_finite_result() {
        let inner = Diverging {
            x_m: 0.0,
            steps: 0,
            nan_at: 5,
            nan_in_pose: false,
        };
        let mut g = Guarded::new(inner);
        let mut steps = 0;
        while !g.step().done {
            steps += 1;
            assert!(steps < 100, "the run did not stop");
        }
        // Steps 1–4 were finite; step 5's loss was NaN.
        assert_eq!(steps, 4);
        let why = g.diverged().expect("diverged");
        assert!(why.contains("step 5") && why.contains("'total'"), "{why}");
        let x = g.best().sensors[0].vehicle_from_sensor.translation.x;
        assert!((x - 0.04).abs() < 1e-12, "{x}");
        // Further steps do nothing.
        assert!(g.step().done);
    }

    #[test]
    fn a_nan_pose_stops_the_run_and_never_reaches_the_caller() {
        let inner = Diverging {
            x_m: 0.0,
            steps: 0,
            nan_at: 3,
            nan_in_pose: true,
        };
        let mut g = Guarded::new(inner);
        while !g.step().done {}
        let why = g.diverged().expect("diverged");
        assert!(why.contains("'lidar'") && why.contains("step 3"), "{why}");
        for rig in [g.current(), g.best()] {
            assert!(non_finite_pose(&rig).is_none());
            let x = rig.sensors[0].vehicle_from_sensor.translation.x;
            assert!((x - 0.02).abs() < 1e-12, "{x}");
        }
    }

    #[test]
    fn the_background_worker_ends_a_diverging_run_with_its_best_result_and_says_why() {
        let run = crate::optim::runner::Run::spawn(Box::new(Diverging {
            x_m: 0.0,
            steps: 0,
            nan_at: 7,
            nan_in_pose: true,
        }));
        let packets = run.join();
        let last = packets.last().expect("a last packet");
        assert!(last.finished);
        let note = last.note.as_deref().expect("the run says why it stopped");
        assert!(
            note.contains("diverged") && note.contains("step 7"),
            "{note}"
        );
        for p in &packets {
            for rig in [&p.current, &p.best] {
                assert!(
                    non_finite_pose(rig).is_none(),
                    "a NaN pose reached the caller"
                );
            }
            assert!(p.losses.iter().all(|(_, v)| v.is_finite()));
        }
        let x = last.best.sensors[0].vehicle_from_sensor.translation.x;
        assert!((x - 0.06).abs() < 1e-12, "{x}");
    }

    #[test]
    fn a_finite_run_passes_through_unchanged() {
        let inner = Diverging {
            x_m: 0.0,
            steps: 0,
            nan_at: usize::MAX,
            nan_in_pose: false,
        };
        let mut g = Guarded::new(inner);
        for _ in 0..10 {
            assert!(!g.step().done);
        }
        assert!(g.diverged().is_none());
        assert_eq!(g.current(), g.inner().current());
    }
}
