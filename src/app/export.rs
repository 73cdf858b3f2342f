//! The export panel: choose which extrinsics to write (current, best, initial) and the format,
//! see exactly what will be written with the direction of every transform spelled out, and
//! save it atomically (a folder for the per-camera formats) or copy it. The files come from
//! [`crate::interop`], the same code as `rigcal export`.

use super::Studio;
use super::state::ExtrinsicsView;
use crate::calib::{CalibrationFile, Rig};
use crate::interop::{self, Export, ExportFormat, ExportOptions};

#[derive(Default)]
pub struct ExportPanel {
    pub which: Option<ExtrinsicsView>,
    pub format: Option<ExportFormat>,
    /// Reference LiDAR (OpenCV, KITTI) and camera (KITTI, Kalibr); `None`: the first.
    pub lidar: Option<String>,
    pub camera: Option<String>,
    /// Sensors left out of the export (by name); empty: every sensor.
    pub left_out: Vec<String>,
    /// The last export and what it was made from (an MCAP export writes a file: not every frame).
    cache: Option<(String, Result<Export, interop::ExportError>)>,
}

impl ExportPanel {
    /// The export the panel shows (made on the last frame), or why it could not be made.
    pub fn last(&self) -> Option<&Result<Export, interop::ExportError>> {
        self.cache.as_ref().map(|(_, e)| e)
    }
}

/// The native calibration document for `rig`, with provenance and the checks' metrics.
pub fn document(studio: &Studio, rig: &Rig, which: ExtrinsicsView) -> CalibrationFile {
    let mut doc = CalibrationFile::from_rig(rig);
    let v = |s: String| serde_yaml::Value::String(s);
    if let Some(d) = &studio.drive {
        let input = std::path::absolute(d.path()).unwrap_or_else(|_| d.path().to_path_buf());
        doc.provenance
            .insert("input".into(), v(input.display().to_string()));
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
                // As `rigcal calibrate --segment` takes it.
                format!(
                    "{:.3}..{:.3} s",
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
    // The day only: the preview is made again whenever its document changes, and a time to
    // the second would change it every second.
    doc.provenance
        .insert("date".into(), v(crate::util::today_utc()));
    // The checks' scores, only where they were measured on this very rig.
    let scored = studio.checks.scored.as_ref();
    let measured_initial = scored.is_some_and(|(initial, _)| initial == rig);
    let measured_current = scored.is_some_and(|(_, current)| current == rig);
    for p in &studio.checks.results {
        let px = if measured_current {
            p.current_px
        } else if measured_initial {
            p.initial_px
        } else {
            continue;
        };
        doc.metrics.insert(
            format!("edge_alignment_px/{}/{}", p.camera, p.lidar),
            serde_yaml::Value::from(px),
        );
    }
    doc
}

/// A reference-sensor picker: "first" or one of `names`.
fn reference_combo(ui: &mut egui::Ui, label: &str, choice: &mut Option<String>, names: &[String]) {
    egui::ComboBox::from_label(label)
        .selected_text(choice.clone().unwrap_or_else(|| "(the first)".into()))
        .show_ui(ui, |ui| {
            ui.selectable_value(choice, None, "(the first)");
            for n in names {
                ui.selectable_value(choice, Some(n.clone()), n);
            }
        });
}

pub(crate) fn export_ui(studio: &mut Studio, ui: &mut egui::Ui) {
    ui.heading("Export");
    let mut views = vec![ExtrinsicsView::Current, ExtrinsicsView::Initial];
    if studio.optimiser.best.is_some() {
        views.insert(1, ExtrinsicsView::Best);
    }
    // A choice no longer offered (the best went with a newly opened log) falls back.
    let mut which = studio
        .export
        .which
        .filter(|w| views.contains(w))
        .unwrap_or(ExtrinsicsView::Current);
    ui.horizontal(|ui| {
        ui.label("extrinsics:");
        for v in &views {
            ui.selectable_value(&mut which, *v, v.label());
        }
    });
    studio.export.which = Some(which);
    let mut format = studio.export.format.unwrap_or(ExportFormat::Native);
    egui::ComboBox::from_label("format")
        .selected_text(format.label())
        .width(320.0)
        .show_ui(ui, |ui| {
            for f in ExportFormat::ALL {
                ui.selectable_value(&mut format, f, f.label());
            }
        });
    studio.export.format = Some(format);
    let rig = studio.rig_for(which).clone();
    ui.label("sensors to write:");
    ui.horizontal_wrapped(|ui| {
        for sensor in &rig.sensors {
            let mut on = !studio.export.left_out.contains(&sensor.name);
            if ui.checkbox(&mut on, &sensor.name).changed() {
                if on {
                    studio.export.left_out.retain(|n| *n != sensor.name);
                } else {
                    studio.export.left_out.push(sensor.name.clone());
                }
            }
        }
    });
    let sensors: Vec<String> = rig
        .sensors
        .iter()
        .filter(|s| !studio.export.left_out.contains(&s.name))
        .map(|s| s.name.clone())
        .collect();
    if sensors.is_empty() {
        ui.colored_label(egui::Color32::LIGHT_RED, "tick at least one sensor");
        return;
    }
    let sensors = if sensors.len() == rig.sensors.len() {
        Vec::new()
    } else {
        sensors
    };
    if format.takes_lidar() {
        let lidars: Vec<String> = rig.lidars().map(|s| s.name.clone()).collect();
        reference_combo(ui, "reference LiDAR", &mut studio.export.lidar, &lidars);
    }
    if format.takes_camera() {
        let cameras: Vec<String> = rig.cameras().map(|s| s.name.clone()).collect();
        reference_combo(
            ui,
            "reference camera (cam0)",
            &mut studio.export.camera,
            &cameras,
        );
    }
    ui.label(format.describe());
    ui.weak(
        "rigcal keeps vehicle_from_sensor: it maps a point from the sensor's frame into the \
         vehicle frame, p_vehicle = R · p_sensor + t. Camera frames are OpenCV optical frames: \
         x right, y down, z forward.",
    );
    let doc = document(studio, &rig, which);
    let options = ExportOptions {
        sensors,
        // What one format chose stays for it; the others would refuse it.
        lidar: studio.export.lidar.clone().filter(|_| format.takes_lidar()),
        camera: studio
            .export
            .camera
            .clone()
            .filter(|_| format.takes_camera()),
    };
    let key = format!("{}|{:?}|{}", format.name(), options, doc.to_yaml());
    if studio.export.cache.as_ref().is_none_or(|(k, _)| *k != key) {
        let made = interop::export(&doc, format, &options);
        studio.export.cache = Some((key, made));
    }
    let Some((_, made)) = &studio.export.cache else {
        return;
    };
    let export = match made {
        Ok(e) => e.clone(),
        Err(e) => {
            ui.colored_label(egui::Color32::LIGHT_RED, format!("cannot export: {e}"));
            return;
        }
    };
    let preview = export.preview();
    ui.horizontal(|ui| {
        let label = if format.is_directory() {
            "Save to folder…"
        } else {
            "Save…"
        };
        if ui.button(label).clicked() {
            let dialog = rfd::FileDialog::new();
            let path = if format.is_directory() {
                dialog.pick_folder()
            } else {
                dialog.set_file_name(format.default_file_name()).save_file()
            };
            if let Some(path) = path {
                match interop::write(&export, &path) {
                    Ok(files) => studio.status.push(format!(
                        "exported {} ({} file{})",
                        path.display(),
                        files.len(),
                        if files.len() == 1 { "" } else { "s" }
                    )),
                    Err(e) => studio.status.push(format!("error: {e}")),
                }
            }
        }
        if ui
            .add_enabled(format != ExportFormat::Mcap, egui::Button::new("Copy"))
            .clicked()
        {
            ui.ctx().copy_text(preview.clone());
            studio
                .status
                .push(format!("copied the {} export", format.name()));
        }
        ui.weak(format!(
            "{} file{}",
            export.files.len(),
            if export.files.len() == 1 { "" } else { "s" }
        ));
    });
    egui::ScrollArea::vertical()
        .id_salt("export_preview")
        .max_height(420.0)
        .show(ui, |ui| {
            ui.add(
                egui::TextEdit::multiline(&mut preview.as_str())
                    .font(egui::TextStyle::Monospace)
                    .desired_width(f32::INFINITY),
            );
        });
}
