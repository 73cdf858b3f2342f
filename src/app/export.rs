//! The export panel: choose which extrinsics to write (current, best, initial), see exactly
//! what will be written, with the direction of every transform spelled out, and save it
//! atomically or copy it. The native file now; other formats join with the export issue.

use super::Studio;
use super::state::ExtrinsicsView;
use crate::calib::{CalibrationFile, Rig};

#[derive(Default)]
pub struct ExportPanel {
    pub which: Option<ExtrinsicsView>,
}

/// The native calibration document for `rig`, with provenance and the checks' metrics.
pub fn document(studio: &Studio, rig: &Rig, which: ExtrinsicsView) -> CalibrationFile {
    let mut doc = CalibrationFile::from_rig(rig);
    let v = |s: String| serde_yaml::Value::String(s);
    if let Some(d) = &studio.drive {
        doc.provenance
            .insert("input".into(), v(d.path().display().to_string()));
        doc.provenance
            .insert("trajectory".into(), v(d.trajectory_source.clone()));
    }
    if !studio.segments.is_empty() {
        let t0 = studio
            .drive
            .as_ref()
            .and_then(|d| d.time_range_nanos())
            .map_or(0, |r| r.0);
        let segs: Vec<String> = studio
            .segments
            .iter()
            .map(|&(a, b)| {
                format!(
                    "{:.3}-{:.3} s",
                    (a - t0) as f64 * 1e-9,
                    (b - t0) as f64 * 1e-9
                )
            })
            .collect();
        doc.provenance
            .insert("time_range".into(), v(segs.join(", ")));
    }
    doc.provenance.insert(
        "method".into(),
        v(match which {
            ExtrinsicsView::Initial => "initial guess (as loaded)".into(),
            ExtrinsicsView::Best => format!("optimiser best ({})", studio.optimiser.method_label()),
            ExtrinsicsView::GroundTruth => "ground truth".into(),
            ExtrinsicsView::Current => "studio (hand edits and optimiser runs)".into(),
        }),
    );
    doc.provenance.insert(
        "version".into(),
        v(format!("rigcal {}", env!("CARGO_PKG_VERSION"))),
    );
    for p in &studio.checks.results {
        doc.metrics.insert(
            format!("edge_alignment_px/{}/{}", p.camera, p.lidar),
            serde_yaml::Value::from(match which {
                ExtrinsicsView::Initial => p.initial_px,
                _ => p.current_px,
            }),
        );
    }
    doc
}

pub(crate) fn export_ui(studio: &mut Studio, ui: &mut egui::Ui) {
    ui.heading("Export");
    let mut views = vec![ExtrinsicsView::Current, ExtrinsicsView::Initial];
    if studio.optimiser.best.is_some() {
        views.insert(1, ExtrinsicsView::Best);
    }
    let mut which = studio.export.which.unwrap_or(ExtrinsicsView::Current);
    ui.horizontal(|ui| {
        ui.label("extrinsics:");
        for v in &views {
            ui.selectable_value(&mut which, *v, v.label());
        }
    });
    studio.export.which = Some(which);
    egui::ComboBox::from_label("format")
        .selected_text("rigcal native (YAML)")
        .show_ui(ui, |ui| {
            ui.label("rigcal native (YAML)");
        });
    ui.label(
        "Every transform is vehicle_from_sensor: it maps a point from the sensor's frame into \
         the vehicle frame, p_vehicle = R · p_sensor + t (t = the sensor's origin in the \
         vehicle frame). Camera frames are OpenCV optical frames: x right, y down, z forward.",
    );
    let doc = document(studio, studio.rig_for(which), which);
    let text = doc.to_yaml();
    ui.horizontal(|ui| {
        if ui.button("Save…").clicked()
            && let Some(path) = rfd::FileDialog::new()
                .add_filter("YAML", &["yaml"])
                .set_file_name("calibration.yaml")
                .save_file()
        {
            match doc.save(&path) {
                Ok(()) => studio.status.push(format!("exported {}", path.display())),
                Err(e) => studio.status.push(format!("error: {e}")),
            }
        }
        if ui.button("Copy").clicked() {
            ui.ctx().copy_text(text.clone());
            studio.status.push("copied the calibration file".into());
        }
    });
    egui::ScrollArea::vertical()
        .id_salt("export_preview")
        .max_height(420.0)
        .show(ui, |ui| {
            ui.add(
                egui::TextEdit::multiline(&mut text.as_str())
                    .font(egui::TextStyle::Monospace)
                    .desired_width(f32::INFINITY),
            );
        });
}
