//! The optimiser panel's readouts while a run goes: the loss curves and each sensor's rotation
//! change against the step, the edge-alignment table, and the errors against a loaded ground
//! truth.

use super::*;

/// Loss curves (log10 scale) and per-sensor rotation change against the step.
pub(super) fn losses_ui(studio: &Studio, ui: &mut egui::Ui) {
    ui.label("Loss (log₁₀ px) against step");
    let mut names: Vec<String> = Vec::new();
    for (_, l) in &studio.optimiser.history {
        for (n, _) in l {
            if !names.contains(n) {
                names.push(n.clone());
            }
        }
    }
    Plot::new("losses")
        .height(180.0)
        .legend(Legend::default())
        .x_axis_label("step")
        .y_axis_label("log₁₀ loss")
        .show(ui, |plot| {
            for n in &names {
                let pts: Vec<[f64; 2]> = studio
                    .optimiser
                    .history
                    .iter()
                    .filter_map(|(s, l)| {
                        l.iter()
                            .find(|(k, _)| k == n)
                            .filter(|(_, v)| *v > 0.0)
                            .map(|(_, v)| [*s as f64, v.log10()])
                    })
                    .collect();
                plot.line(Line::new(n.clone(), PlotPoints::from(pts)));
            }
        });
    ui.label("Rotation change from the start (log₁₀ deg, floor 0.001°)");
    let mut sensors: Vec<String> = Vec::new();
    for (_, s, _) in &studio.optimiser.pose_change {
        if !sensors.contains(s) {
            sensors.push(s.clone());
        }
    }
    Plot::new("pose_change")
        .height(140.0)
        .legend(Legend::default())
        .x_axis_label("step")
        .y_axis_label("log₁₀ deg")
        .show(ui, |plot| {
            for s in &sensors {
                let pts: Vec<[f64; 2]> = studio
                    .optimiser
                    .pose_change
                    .iter()
                    .filter(|(_, n, _)| n == s)
                    .map(|(k, _, v)| [*k as f64, v.max(1e-3).log10()])
                    .collect();
                plot.line(Line::new(s.clone(), PlotPoints::from(pts)));
            }
        });
}

/// Per camera: the edge-alignment score at the start and now, worst first.
pub(super) fn alignment_table_ui(studio: &Studio, ui: &mut egui::Ui) {
    ui.label("Alignment score: mean px from LiDAR silhouettes to image edges");
    let (Some((_, first)), Some((_, last))) = (
        studio.optimiser.history.first(),
        studio.optimiser.history.last(),
    ) else {
        ui.weak("(run the optimiser to score each camera)");
        return;
    };
    let mut rows: Vec<(String, f64, f64)> = last
        .iter()
        .filter_map(|(n, now)| {
            let cam = n.strip_prefix("edge_px/")?;
            let before = first.iter().find(|(k, _)| k == n).map_or(*now, |x| x.1);
            Some((cam.to_string(), before, *now))
        })
        .collect();
    rows.sort_by(|a, b| b.2.total_cmp(&a.2));
    egui::Grid::new("scores").striped(true).show(ui, |ui| {
        ui.strong("camera");
        ui.strong("start");
        ui.strong("now");
        ui.end_row();
        for (cam, before, now) in rows {
            ui.label(cam);
            ui.label(format!("{before:.2}"));
            ui.label(format!("{now:.2}"));
            ui.end_row();
        }
    });
}

/// Pose errors against the ground truth when it is known, root = the reference LiDAR.
pub(crate) fn ground_truth_errors_ui(studio: &Studio, ui: &mut egui::Ui) {
    if let Some(gt) = &studio.ground_truth {
        ui.separator();
        let root = studio
            .optimiser
            .reference_lidar
            .clone()
            .or_else(|| studio.current.lidars().next().map(|l| l.name.clone()))
            .unwrap_or_default();
        pose_errors_ui(&studio.current, gt, &root, ui);
    }
}

/// Per sensor: rotation (deg) and translation (cm) error of the current rig against the known
/// ground truth after aligning the root sensor (method.md §13), the reference LiDAR here.
pub(super) fn pose_errors_ui(current: &Rig, gt: &Rig, root: &str, ui: &mut egui::Ui) {
    ui.label(format!(
        "Error against the ground truth (current rig, root {root} aligned)"
    ));
    let Some(errors) = rig_errors(&gt.extrinsics(), &current.extrinsics(), root) else {
        ui.weak("(the root sensor is missing from the ground truth)");
        return;
    };
    egui::Grid::new("gt_errors").striped(true).show(ui, |ui| {
        ui.strong("sensor");
        ui.strong("rotation °");
        ui.strong("translation cm");
        ui.end_row();
        for e in errors {
            ui.label(&e.sensor);
            ui.label(format!("{:.3}", e.rotation_deg));
            ui.label(format!("{:.1}", e.translation_m * 100.0));
            ui.end_row();
        }
    });
}
