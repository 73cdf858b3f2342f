//! The LiDARs' part of the report: the reference (fitted to the trajectory), a LiDAR registered
//! to it by ICP (σ per axis from the point-to-plane information, the pair's residual before and
//! after), and a LiDAR UniCal moved with the scene (the pair's residual only).

use glam::DMat3;

use crate::calib::Rig;
use crate::geometry::{Rigid, so3};
use crate::log::Drive;

use super::{
    Check, Observed, SensorReport, Verdict, WORSE_FRACTION, WORSE_PLANE_CM, axis_names, fill_axes,
    keep_axes,
};
use crate::pipeline::run::LidarEvidence;

pub(super) fn reference_report(lidars: &LidarEvidence, report: &mut SensorReport) {
    // The fit's axes are the vehicle's; a LiDAR mounted level shares them.
    let vehicle_axes = ["roll", "pitch", "yaw", "x", "y", "z"];
    match &lidars.reference_fit {
        Some(Ok(unobserved)) => {
            for (k, a) in report.axes.iter_mut().enumerate() {
                a.observed = if unobserved.contains(&vehicle_axes[k]) {
                    Observed::NotObserved
                } else {
                    Observed::Observed
                };
            }
            (report.verdict, report.why) = if unobserved.is_empty() {
                (
                    Verdict::Good,
                    "the reference: fitted to the trajectory, every axis observed".into(),
                )
            } else {
                (
                    Verdict::CheckIt,
                    format!(
                        "the reference: fitted to the trajectory; the drive does not observe its {} (vehicle axes): kept at the initial guess",
                        unobserved.join(", ")
                    ),
                )
            };
        }
        Some(Err(why)) => held_reference_report(
            format!("the reference, kept at the initial guess: {why}"),
            report,
        ),
        None => held_reference_report(
            "the reference: not fitted to the trajectory (the plan says why): kept at the initial guess".into(),
            report,
        ),
    }
}

/// The reference LiDAR kept at the initial guess, for the reason `why`: every axis
/// unobserved, "check it".
pub(super) fn held_reference_report(why: String, report: &mut SensorReport) {
    report.verdict = Verdict::CheckIt;
    report.why = why;
    report
        .axes
        .iter_mut()
        .for_each(|a| a.observed = Observed::NotObserved);
}

/// A LiDAR UniCal moved with the scene (`--method unical`, no registration first): the
/// reference gets no independent check; any other is checked by its point-to-plane residual
/// against the reference under the initial guess and under the result. Where it registers
/// worse, its pose relative to the reference goes back to the initial guess's (the reference
/// keeps UniCal's pose), with the verdict "failed". Returns the pose to write.
pub(super) fn unical_lidar_report(
    drive: &Drive,
    (initial, result): (&Rig, &Rig),
    lidar: &str,
    reference: &str,
    (start, end): (Rigid, Rigid),
    report: &mut SensorReport,
) -> Rigid {
    report.verdict = Verdict::CheckIt;
    report.why = "moved by UniCal with the scene; no independent check of its axes".into();
    if lidar == reference {
        return end;
    }
    let (Some(reference_start), Some(reference_end)) =
        (initial.sensor(reference), result.sensor(reference))
    else {
        return end;
    };
    let Some((check, worse)) = plane_check(drive, (initial, result), lidar, reference) else {
        return end;
    };
    let (b, a) = (check.before, check.after);
    report.checks.push(check);
    if worse {
        report.verdict = Verdict::Failed;
        report.why = format!(
            "UniCal left it registering worse against {reference} than the initial guess ({a:.2} cm against {b:.2} cm): its pose relative to {reference} is the initial guess's"
        );
        let reference_from_lidar = reference_start.vehicle_from_sensor.inverse() * start;
        return reference_end.vehicle_from_sensor * reference_from_lidar;
    }
    report.why = format!(
        "moved by UniCal with the scene; it registers against {reference} at least as well as at the initial guess ({a:.2} cm against {b:.2} cm), its axes not checked one by one"
    );
    end
}

#[allow(clippy::too_many_arguments)]
pub(super) fn lidar_report(
    drive: &Drive,
    result: &Rig,
    lidar: &str,
    reference: &str,
    start: Rigid,
    end: Rigid,
    lidars: &LidarEvidence,
    report: &mut SensorReport,
) -> Rigid {
    let mut unobserved = Vec::new();
    if let Some((_, info)) = lidars.icp_information.iter().find(|(n, _)| n == lidar) {
        unobserved = fill_axes(report, lidar_sigmas(info, end));
    }
    let kept = keep_axes(start, end, &unobserved);
    let mut initial = result.clone();
    let mut final_rig = result.clone();
    if let (Some(a), Some(b)) = (initial.sensor_mut(lidar), final_rig.sensor_mut(lidar)) {
        a.vehicle_from_sensor = start;
        b.vehicle_from_sensor = kept;
    }
    if let Some((check, worse)) = plane_check(drive, (&initial, &final_rig), lidar, reference) {
        let (b, a) = (check.before, check.after);
        report.checks.push(check);
        if worse {
            report.verdict = Verdict::Failed;
            report.why = format!(
                "it registers worse than at the initial guess ({a:.2} cm against {b:.2} cm): the initial guess is kept"
            );
            return start;
        }
    }
    let weak: Vec<usize> = (0..6)
        .filter(|&k| report.axes[k].observed == Observed::Weak)
        .collect();
    (report.verdict, report.why) = if report.axes.iter().all(|a| a.observed == Observed::Unknown) {
        (Verdict::CheckIt, "no independent check of its axes".into())
    } else if !unobserved.is_empty() {
        (
            Verdict::CheckIt,
            format!(
                "the overlap does not observe {}: kept at the initial guess",
                axis_names(&unobserved)
            ),
        )
    } else if !weak.is_empty() {
        (
            Verdict::CheckIt,
            format!("weakly observed: {}", axis_names(&weak)),
        )
    } else {
        (
            Verdict::Good,
            format!("every axis observed by its overlap with {reference}"),
        )
    };
    kept
}

/// Per-axis σ (rad, m) in the LiDAR's own frame from ICP information in the vehicle frame
/// (left perturbation, rotation first) at `vehicle_from_lidar`.
fn lidar_sigmas(info: &[f64; 36], vehicle_from_lidar: Rigid) -> [f64; 6] {
    // Left perturbation (ω_v, v_v) to right (ω_s, v_s): ω_s = Rᵀ ω_v,
    // v_s = Rᵀ v_v − Rᵀ [t]× ω_v.
    let r = vehicle_from_lidar.rotation_matrix();
    let rt = r.transpose();
    let t = vehicle_from_lidar.translation;
    let lower = -(rt * so3::hat(t));
    let mut j = [[0.0; 6]; 6];
    let put = |j: &mut [[f64; 6]; 6], m: DMat3, row: usize, col: usize| {
        for a in 0..3 {
            for b in 0..3 {
                j[row + a][col + b] = m.col(b)[a];
            }
        }
    };
    put(&mut j, rt, 0, 0);
    put(&mut j, lower, 3, 0);
    put(&mut j, rt, 3, 3);
    let h: [[f64; 6]; 6] = std::array::from_fn(|a| std::array::from_fn(|b| info[a * 6 + b]));
    let (cov, unobserved, largest) = crate::geometry::spd::observed_inverse(h, 1e-9);
    // Σ_s = J Σ_v Jᵀ.
    let jc: [[f64; 6]; 6] =
        std::array::from_fn(|a| std::array::from_fn(|b| (0..6).map(|k| j[a][k] * cov[k][b]).sum()));
    std::array::from_fn(|a| {
        // An unobserved vehicle direction leaks into the sensor axes it maps to.
        let touched = (0..6).any(|k| unobserved[k] && j[a][k].abs() > 0.3);
        if touched || largest <= 0.0 {
            f64::INFINITY
        } else {
            (0..6)
                .map(|k| jc[a][k] * j[a][k])
                .sum::<f64>()
                .max(0.0)
                .sqrt()
        }
    })
}

/// The mean point-to-plane residual of `lidar` against `reference` under the rig before and
/// after, as a check, and whether it rose past the margin of a real change. `None` when the
/// drive gives no overlap to measure.
fn plane_check(
    drive: &Drive,
    (before, after): (&Rig, &Rig),
    lidar: &str,
    reference: &str,
) -> Option<(Check, bool)> {
    let residuals = crate::eval::registration::pair_registration_errors(
        drive,
        &[before, after],
        lidar,
        reference,
        3,
        4,
    )
    .ok()?;
    let (Some(b), Some(a)) = (residuals.first()?, residuals.get(1)?) else {
        return None;
    };
    let worse = a.mean_cm > b.mean_cm * (1.0 + WORSE_FRACTION) + WORSE_PLANE_CM;
    let check = Check {
        what: format!("point-to-plane against {reference}"),
        before: b.mean_cm,
        after: a.mean_cm,
        unit: "cm",
    };
    Some((check, worse))
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;

    #[test]
    fn a_lidars_sigmas_move_into_its_own_frame() {
        // Information 1e4 on every rotation and 1e4 on x, y of the vehicle; z flat.
        let mut info = [0.0; 36];
        for k in 0..5 {
            info[k * 6 + k] = 1e4;
        }
        // A LiDAR turned 90° about the vehicle's x axis: its y is the vehicle's z.
        let at = Rigid::new(
            so3::exp(DVec3::X * std::f64::consts::FRAC_PI_2),
            DVec3::ZERO,
        );
        let s = lidar_sigmas(&info, at);
        assert!((s[0] - 0.01).abs() < 1e-9, "{s:?}");
        assert!(
            s[4].is_infinite() && s[3].is_finite() && s[5].is_finite(),
            "{s:?}"
        );
    }
}
