//! The report a user can trust: per sensor, how far it moved, which axes of its pose the drive
//! observed (with a 1-σ uncertainty each, in the sensor's own frame), the target-free checks
//! before and after, and a verdict with one line of why.
//!
//! Where the numbers come from:
//! - cameras: [`EdgeCheck`](crate::pipeline::edge_check::EdgeCheck) against the reference LiDAR at the result (the sandwich covariance
//!   of the edge-alignment cost over independent frames; its module doc). The σ rates the
//!   result without moving it; a camera whose edges align worse than at the initial guess, or
//!   whose LiDAR reflectivity matches its images worse ([`MiCheck`](crate::pipeline::mi_check::MiCheck)), keeps the initial guess
//!   and fails;
//! - LiDARs registered by ICP: the inverse of the point-to-plane information at the result
//!   ([`crate::classical::icp::IcpProblem::information`], neighbouring points counted as one),
//!   and the LiDAR–LiDAR point-to-plane residual before and after; a pair that registers worse
//!   keeps the initial guess and fails;
//! - the reference LiDAR: the directions its fit to the trajectory did not observe (kept at
//!   the initial guess), or why it was not fitted.

use glam::DVec3;
use serde::Serialize;

use crate::calib::{Rig, SensorKind};
use crate::geometry::{Rigid, so3};
use crate::log::Drive;

use super::plan::Plan;
use super::run::LidarEvidence;

mod camera;
mod lidar;
use camera::{Start, camera_report};
use lidar::{held_reference_report, lidar_report, reference_report, unical_lidar_report};

/// Frames of each camera the report's checks use.
const CHECK_FRAMES: usize = 8;
/// 1-σ bounds of an observed and of a weakly observed axis: rotations (degrees) and
/// translations (cm).
const OBSERVED_DEG: f64 = 0.1;
const WEAK_DEG: f64 = 0.5;
const OBSERVED_CM: f64 = 2.0;
const WEAK_CM: f64 = 10.0;
/// A check is worse when it rises by this fraction and this much over its start.
const WORSE_FRACTION: f64 = 0.02;
const WORSE_EDGE_PX: f64 = 0.05;
const WORSE_PLANE_CM: f64 = 0.1;

/// The names of a pose's axes in the sensor's own frame.
pub const AXES: [&str; 6] = ["rot x", "rot y", "rot z", "x", "y", "z"];

/// How well the drive observed one axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Observed {
    Observed,
    Weak,
    NotObserved,
    /// Held by request (the root, or not among `--sensors`).
    Fixed,
    /// No check measured it.
    Unknown,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    Good,
    CheckIt,
    Failed,
}

impl Verdict {
    pub fn label(self) -> &'static str {
        match self {
            Verdict::Good => "good",
            Verdict::CheckIt => "check it",
            Verdict::Failed => "failed",
        }
    }
}

/// One axis of a sensor's pose.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AxisReport {
    pub axis: &'static str,
    pub observed: Observed,
    /// 1-σ, degrees for rotations and cm for translations (`None`: not measured or infinite).
    pub sigma: Option<f64>,
}

/// A target-free measure before and after.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Check {
    pub what: String,
    pub before: f64,
    pub after: f64,
    pub unit: &'static str,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SensorReport {
    pub name: String,
    pub kind: &'static str,
    pub moved_deg: f64,
    pub moved_cm: f64,
    pub axes: Vec<AxisReport>,
    pub checks: Vec<Check>,
    pub verdict: Verdict,
    pub why: String,
}

impl SensorReport {
    /// The report of a sensor checked from `start` to `end`: how far it moved, with `end`
    /// written into `out`, the rig to save.
    fn settle(mut self, start: Rigid, end: Rigid, out: &mut Rig) -> Self {
        let (rot, trans) = start.difference(end);
        self.moved_deg = rot.to_degrees();
        self.moved_cm = trans * 100.0;
        if let Some(o) = out.sensor_mut(&self.name) {
            o.vehicle_from_sensor = end;
        }
        self
    }

    /// A sensor's report before any check: every axis fixed (`fixed`) or not yet known.
    fn unchecked(sensor: &crate::calib::Sensor, fixed: bool) -> Self {
        SensorReport {
            name: sensor.name.clone(),
            kind: match sensor.kind {
                SensorKind::Camera => "camera",
                SensorKind::Lidar => "lidar",
            },
            moved_deg: 0.0,
            moved_cm: 0.0,
            axes: AXES
                .iter()
                .map(|&axis| AxisReport {
                    axis,
                    observed: if fixed {
                        Observed::Fixed
                    } else {
                        Observed::Unknown
                    },
                    sigma: None,
                })
                .collect(),
            checks: Vec::new(),
            verdict: Verdict::CheckIt,
            why: String::new(),
        }
    }
}

/// The whole report.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Report {
    pub sensors: Vec<SensorReport>,
    /// How the uncertainties were found.
    pub method: String,
}

/// What a camera method (`edge`, `mi`, `target`) fitted, for [`Report::for_cameras`].
#[derive(Clone, Debug, Default)]
pub struct MethodFit<'a> {
    /// The LiDAR the cameras were fitted against.
    pub reference: &'a str,
    pub cameras: &'a [String],
    /// How many of the reference's sweeps (spread evenly, each with its nearest image) the
    /// method fitted: the check keeps off them.
    pub fitted_sweeps: usize,
    /// Cameras whose result the method itself rejects, with why ([`crate::optim::runner::Calibrator::failures`]).
    pub failures: &'a [(String, String)],
    /// Said of every camera when the method holds the translation at the initial guess.
    pub held_translation: Option<&'a str>,
    /// The method fitted edge alignment, the check's own measure: its result is also checked
    /// by mutual information ([`crate::pipeline::mi_check::MiCheck`]).
    pub fitted_edges: bool,
}

impl Report {
    /// Check `result` against `initial` on `drive` and return the report with the rig as it
    /// should be written: unobserved axes back at the initial guess, failed sensors at it.
    pub fn build(
        drive: &Drive,
        initial: &Rig,
        result: &Rig,
        plan: &Plan,
        lidars: &LidarEvidence,
    ) -> (Report, Rig) {
        let segments = &plan.request.segments_nanos;
        let asked = |name: &str| {
            plan.request.sensors.is_empty() || plan.request.sensors.iter().any(|s| s == name)
        };
        let mut out = result.clone();
        let mut sensors = Vec::new();
        let reference = plan.reference_lidar.clone().unwrap_or_default();
        for s in &initial.sensors {
            let Some(r) = result.sensor(&s.name) else {
                continue;
            };
            let start = s.vehicle_from_sensor;
            let fixed = !asked(&s.name) || plan.request.root.as_deref() == Some(s.name.as_str());
            let mut report = SensorReport::unchecked(s, fixed);
            let mut end = r.vehicle_from_sensor;
            if fixed {
                report.verdict = Verdict::Good;
                report.why = if asked(&s.name) {
                    "the root: held where the initial guess puts it".into()
                } else {
                    "not among --sensors: held where the initial guess puts it".into()
                };
            } else if s.kind == SensorKind::Camera {
                // Where UniCal moved the reference LiDAR with the scene (`--method unical`),
                // a camera is judged, and kept when it fails, at its initial pose relative
                // to that LiDAR, as another LiDAR is ([`unical_lidar_report`]).
                let from = match (initial.sensor(&reference), result.sensor(&reference)) {
                    (Some(a), Some(b))
                        if !plan.config.lidars.register
                            && a.vehicle_from_sensor != b.vehicle_from_sensor =>
                    {
                        Start::RelativeTo {
                            pose: b.vehicle_from_sensor * a.vehicle_from_sensor.inverse() * start,
                            lidar: &reference,
                        }
                    }
                    _ => Start::Initial(start),
                };
                end = camera_report(
                    drive,
                    result,
                    &s.name,
                    &reference,
                    (from, end),
                    plan.straight_travel,
                    (segments, &plan.fitted_images(drive, &s.name)),
                    plan.stationary_camera(&s.name),
                    &mut report,
                );
            } else if !plan.config.lidars.register && plan.unical.held_sensors.contains(&s.name) {
                // The reference of a log that does not move (`--method unical`): held.
                held_reference_report(
                    "the reference: the vehicle does not move, so nothing places it on the vehicle: kept at the initial guess".into(),
                    &mut report,
                );
                end = start;
            } else if !plan.config.lidars.register {
                // UniCal moved the LiDARs itself (`--method unical`).
                end = unical_lidar_report(
                    drive,
                    (initial, result),
                    &s.name,
                    &reference,
                    (start, end),
                    &mut report,
                );
            } else if s.name == reference {
                reference_report(lidars, &mut report);
            } else {
                end = lidar_report(
                    drive,
                    result,
                    &s.name,
                    &reference,
                    start,
                    end,
                    lidars,
                    &mut report,
                );
            }
            sensors.push(report.settle(start, end, &mut out));
        }
        let report = Report {
            sensors,
            method: "cameras: sandwich covariance of the edge-alignment cost against the reference LiDAR over independent frames; LiDARs: inverse point-to-plane ICP information (neighbouring points counted as one); σ in each sensor's own frame".into(),
        };
        (report, out)
    }

    /// A camera method's check (`edge`, `mi`, `target`): every camera of `cameras` that
    /// `result` moved from `initial`, checked against `reference` by edge alignment on eight
    /// frames spread over `segments_nanos`, none of them a frame the method fitted (it fitted
    /// `fitted_sweeps` sweeps of `reference` spread evenly, each with its nearest image) unless
    /// the log has no others, and by mutual information. A camera whose edges align worse than at
    /// the initial guess, or whose reflectivity matches its images worse, goes back to it, with
    /// the verdict "failed" and why. Returns the report and the rig to write.
    pub fn for_cameras(
        drive: &Drive,
        initial: &Rig,
        result: &Rig,
        fit: &MethodFit,
        segments_nanos: &[(i64, i64)],
    ) -> (Report, Rig) {
        let (reference, cameras) = (fit.reference, fit.cameras);
        let fitted = if fit.fitted_sweeps == 0 {
            Vec::new()
        } else {
            crate::log::spread_evenly(
                &drive.frames_within(reference, segments_nanos),
                fit.fitted_sweeps,
            )
        };
        let mut out = result.clone();
        let mut sensors = Vec::new();
        for s in initial.sensors.iter().filter(|s| cameras.contains(&s.name)) {
            let Some(r) = result.sensor(&s.name) else {
                continue;
            };
            let start = s.vehicle_from_sensor;
            let mut report = SensorReport::unchecked(s, false);
            let mut end = camera_report(
                drive,
                result,
                &s.name,
                reference,
                (Start::Initial(start), r.vehicle_from_sensor),
                None,
                (
                    segments_nanos,
                    &crate::optim::edge_align::images_nearest(drive, &s.name, reference, &fitted),
                ),
                fit.fitted_edges,
                &mut report,
            );
            if let Some((_, why)) = fit.failures.iter().find(|(name, _)| *name == s.name) {
                report.verdict = Verdict::Failed;
                report.why = format!("{why}; {}", Start::Initial(start).kept());
                for c in &mut report.checks {
                    c.after = c.before;
                }
                end = start;
            } else if let Some(held) = fit.held_translation {
                report.why = format!("{held}; {}", report.why);
            }
            sensors.push(report.settle(start, end, &mut out));
        }
        let report = Report {
            sensors,
            method: "cameras: sandwich covariance of the edge-alignment cost against the reference LiDAR over independent frames; σ in each camera's own frame".into(),
        };
        (report, out)
    }

    /// The report as text, one block per sensor.
    pub fn to_text(&self) -> String {
        let mut out = String::from("report (σ: 1-σ per axis in the sensor's frame; ° and cm):\n");
        let width = self.sensors.iter().map(|s| s.name.len()).max().unwrap_or(0);
        for s in &self.sensors {
            out.push_str(&format!(
                "  {:width$}  {:8}  moved {:.3}° / {:.2} cm; {}\n",
                s.name,
                s.verdict.label(),
                s.moved_deg,
                s.moved_cm,
                s.why
            ));
            let axes: Vec<String> = s
                .axes
                .iter()
                .map(|a| {
                    let sigma = match a.sigma {
                        Some(v) => format!(" ±{v:.2}"),
                        None => String::new(),
                    };
                    let state = match a.observed {
                        Observed::Observed => "ok",
                        Observed::Weak => "weak",
                        Observed::NotObserved => "not observed",
                        Observed::Fixed => "fixed",
                        Observed::Unknown => "?",
                    };
                    format!("{} {state}{sigma}", a.axis)
                })
                .collect();
            out.push_str(&format!("  {:width$}    {}\n", "", axes.join(", ")));
            for c in &s.checks {
                // Mutual information is a few hundredths of a nat.
                let digits = if c.unit == "nats" { 4 } else { 2 };
                out.push_str(&format!(
                    "  {:width$}    {}: {:.digits$} → {:.digits$} {}\n",
                    "", c.what, c.before, c.after, c.unit
                ));
            }
        }
        out
    }

    /// The report for the output file's `metrics`.
    pub fn to_yaml(&self) -> serde_yaml::Value {
        serde_yaml::to_value(self).unwrap_or(serde_yaml::Value::Null)
    }
}

fn classify(sigma: f64, rotation: bool) -> Observed {
    let (ok, weak) = if rotation {
        (OBSERVED_DEG, WEAK_DEG)
    } else {
        (OBSERVED_CM, WEAK_CM)
    };
    if !sigma.is_finite() || sigma > weak {
        Observed::NotObserved
    } else if sigma > ok {
        Observed::Weak
    } else {
        Observed::Observed
    }
}

/// Fill the axes from σ in rad and m; returns the axes not observed.
fn fill_axes(report: &mut SensorReport, sigmas: [f64; 6]) -> Vec<usize> {
    let mut unobserved = Vec::new();
    for (k, a) in report.axes.iter_mut().enumerate() {
        let rotation = k < 3;
        let v = if rotation {
            sigmas[k].to_degrees()
        } else {
            sigmas[k] * 100.0
        };
        a.observed = classify(v, rotation);
        a.sigma = v.is_finite().then_some(v);
        if a.observed == Observed::NotObserved {
            unobserved.push(k);
        }
    }
    unobserved
}

/// `end` with the axes `keep` (in the sensor's frame, rotations first) put back at `start`.
fn keep_axes(start: Rigid, end: Rigid, keep: &[usize]) -> Rigid {
    if keep.is_empty() {
        return end;
    }
    let delta = start.inverse() * end;
    let mut omega = so3::log(delta.rotation).to_array();
    let mut t = delta.translation.to_array();
    for &k in keep {
        if k < 3 {
            omega[k] = 0.0;
        } else {
            t[k - 3] = 0.0;
        }
    }
    start * Rigid::new(so3::exp(DVec3::from_array(omega)), DVec3::from_array(t))
}

fn axis_names(keep: &[usize]) -> String {
    keep.iter().map(|&k| AXES[k]).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_put_back_at_the_start_leave_the_others() {
        let start = Rigid::new(
            so3::exp(DVec3::new(0.1, -0.2, 0.3)),
            DVec3::new(1.0, 2.0, 3.0),
        );
        let end = start.perturbed_right(DVec3::new(0.01, 0.02, 0.0), DVec3::new(0.1, -0.2, 0.05));
        let kept = keep_axes(start, end, &[1, 5]);
        let delta = start.inverse() * kept;
        let omega = so3::log(delta.rotation);
        assert!(
            (omega.x - 0.01).abs() < 1e-4 && omega.y.abs() < 1e-12,
            "{omega:?}"
        );
        assert!((delta.translation - DVec3::new(0.1, -0.2, 0.0)).length() < 1e-12);
        assert_eq!(keep_axes(start, end, &[]), end);
    }

    #[test]
    fn sigmas_are_classified_by_their_size() {
        assert_eq!(classify(0.05, true), Observed::Observed);
        assert_eq!(classify(0.3, true), Observed::Weak);
        assert_eq!(classify(f64::INFINITY, false), Observed::NotObserved);
        assert_eq!(classify(5.0, false), Observed::Weak);
    }
}
