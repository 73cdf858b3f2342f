//! The cameras' part of the report: a camera checked against the reference LiDAR by edge
//! alignment ([`EdgeCheck`]: the score before and after, and the per-axis σ that rates the
//! result), by mutual information where the edge check is not independent of the fit
//! ([`MiCheck`]), and its verdict. A result either check scores worse than the initial guess
//! goes back to the initial guess and fails.

use glam::DVec3;

use crate::calib::Rig;
use crate::geometry::Rigid;
use crate::log::Drive;
use crate::pipeline::edge_check::EdgeCheck;
use crate::pipeline::mi_check::MiCheck;

use super::{
    CHECK_FRAMES, Check, Observed, SensorReport, Verdict, WORSE_EDGE_PX, WORSE_FRACTION,
    axis_names, fill_axes,
};

/// The sensor-frame translation axes a vehicle-frame direction `d` lies along (each at least
/// half of it).
fn axes_along(vehicle_from_sensor: Rigid, d: DVec3) -> Vec<usize> {
    let in_sensor = vehicle_from_sensor.rotation.inverse() * d.normalize_or_zero();
    (0..3)
        .filter(|&k| in_sensor[k].abs() >= 0.5)
        .map(|k| k + 3)
        .collect()
}

/// Where a camera's result is judged from, and where a failed one goes back to.
#[derive(Clone, Copy, Debug)]
pub(super) enum Start<'a> {
    /// The initial guess on the vehicle.
    Initial(Rigid),
    /// The initial guess's pose relative to a LiDAR that UniCal moved with the scene
    /// (`--method unical`): `pose` is the camera's vehicle pose that keeps it so.
    RelativeTo { pose: Rigid, lidar: &'a str },
}

impl Start<'_> {
    /// The vehicle pose the result is judged against.
    pub(super) fn pose(&self) -> Rigid {
        match *self {
            Start::Initial(pose) | Start::RelativeTo { pose, .. } => pose,
        }
    }

    /// What a failed camera keeps, in a report's words.
    pub(super) fn kept(&self) -> String {
        match self {
            Start::Initial(_) => "the initial guess is kept".into(),
            Start::RelativeTo { lidar, .. } => format!(
                "its initial pose relative to {lidar} is kept (UniCal moved {lidar} with the scene)"
            ),
        }
    }
}

#[allow(clippy::too_many_arguments)]
pub(super) fn camera_report(
    drive: &Drive,
    result: &Rig,
    camera: &str,
    reference: &str,
    (from, end): (Start, Rigid),
    straight_travel: Option<DVec3>,
    (segments, fitted_images): (&[(i64, i64)], &[usize]),
    fitted_edges: bool,
    report: &mut SensorReport,
) -> Rigid {
    let start = from.pose();
    let check = match EdgeCheck::new(
        drive,
        result,
        (camera, reference),
        CHECK_FRAMES,
        segments,
        fitted_images,
    ) {
        Ok(c) => c,
        Err(e) => {
            report.verdict = Verdict::CheckIt;
            report.why = format!("no target-free check: {e}");
            return end;
        }
    };
    // The edge check's σ rates the result; it does not move it: on a figure-8 with eight
    // frames it called directions of side cameras unobserved that UniCal had right, and
    // putting them back at the initial guess cost degrees (BENCHMARKS.md, "The pipeline").
    let mut unobserved = fill_axes(report, check.sigmas(end).0);
    // A straight drive: the camera's position along the travel is at best weakly observed,
    // whatever the edges say (a shift along it looks like an image delay).
    let along = straight_travel.map_or(Vec::new(), |d| axes_along(end, d));
    for &k in &along {
        if report.axes[k].observed == Observed::Observed {
            report.axes[k].observed = Observed::Weak;
        }
    }
    unobserved.retain(|k| !along.contains(k));
    let (before, after) = (check.score(start), check.score(end));
    report.checks.push(Check {
        what: format!(
            "edge alignment against {reference} ({} frames, {})",
            check.frame_count(),
            if check.held_out() {
                "none of them fitted"
            } else {
                "the ones fitted: the log has no others"
            }
        ),
        before,
        after,
        unit: "px",
    });
    // The second measure, reflectivity against grey (its module doc), where the edge check
    // is not independent of the fit: it judged the frames the fit used, or the fit was edge
    // alignment itself. A fit of other measures (UniCal's, mutual information's) the edges
    // judge alone: mutual information on the real logs also rejected some of UniCal's true
    // improvements (docs/experiments/real-camera-methods.md, "A second check").
    let (mi, no_mi) = if fitted_edges || !check.held_out() {
        match MiCheck::new(
            drive,
            result,
            (camera, reference),
            (CHECK_FRAMES, segments, fitted_images),
            (start, end),
        ) {
            Ok(m) => (Some(m), String::new()),
            Err(e) => (None, format!("; no second check ({e})")),
        }
    } else {
        (None, String::new())
    };
    if let Some(m) = &mi {
        report.checks.push(Check {
            what: format!(
                "mutual information of {reference}'s reflectivity and the image ({} frames)",
                m.frames
            ),
            before: m.before,
            after: m.after,
            unit: "nats",
        });
    }
    let edges_worse = after > before * (1.0 + WORSE_FRACTION) + WORSE_EDGE_PX;
    let mi_worse = mi.filter(MiCheck::worse);
    if edges_worse || mi_worse.is_some() {
        report.verdict = Verdict::Failed;
        report.why = match mi_worse {
            Some(m) if !edges_worse => format!(
                "its LiDAR reflectivity matches the image worse than at the initial guess (mutual information {:.4} against {:.4}; edges {before:.2} → {after:.2} px): {}",
                m.after,
                m.before,
                from.kept(),
            ),
            _ => format!(
                "its edges align worse than at the initial guess ({after:.2} px against {before:.2} px): {}",
                from.kept()
            ),
        };
        for c in &mut report.checks {
            c.after = c.before;
        }
        return start;
    }
    let weak: Vec<usize> = (0..6)
        .filter(|&k| report.axes[k].observed == Observed::Weak)
        .collect();
    let straight = if along.is_empty() {
        String::new()
    } else {
        format!(
            "the drive is too straight to pin its position along the travel ({}, confounded with an image delay); ",
            axis_names(&along)
        )
    };
    (report.verdict, report.why) = if !straight.is_empty() {
        let rest: Vec<usize> = unobserved
            .iter()
            .chain(weak.iter())
            .copied()
            .filter(|k| !along.contains(k))
            .collect();
        (
            Verdict::CheckIt,
            format!(
                "{straight}{}edges {before:.2} → {after:.2} px",
                if rest.is_empty() {
                    String::new()
                } else {
                    format!("its edges also leave {} loose; ", axis_names(&rest))
                }
            ),
        )
    } else if !unobserved.is_empty() {
        (
            Verdict::CheckIt,
            format!(
                "its edges do not pin {} down (edges {before:.2} → {after:.2} px): look at its overlay",
                axis_names(&unobserved)
            ),
        )
    } else if !weak.is_empty() {
        (
            Verdict::CheckIt,
            format!(
                "weakly observed: {} (edges {before:.2} → {after:.2} px)",
                axis_names(&weak)
            ),
        )
    } else {
        (
            Verdict::Good,
            format!("every axis observed; edges {before:.2} → {after:.2} px"),
        )
    };
    report.why.push_str(&no_mi);
    if !check.held_out() {
        // Judged on its own frames a fit of the images' noise looks as good as a fit of the
        // scene.
        report.verdict = Verdict::CheckIt;
        report.why = format!(
            "checked only on the frames it fitted (the log has no others); {}",
            report.why
        );
    }
    end
}
