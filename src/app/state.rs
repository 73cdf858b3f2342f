//! Studio state: the open drive, the extrinsics being edited (with undo/redo), the selection.

use std::path::Path;
use std::sync::Arc;

use crate::calib::{CalibrationFile, Rig};
use crate::geometry::Rigid;
use crate::log::Drive;

/// Which set of extrinsics the overlay uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExtrinsicsView {
    Initial,
    Current,
    GroundTruth,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorBy {
    Range,
    Intensity,
}

pub struct Studio {
    pub drive: Option<Arc<Drive>>,
    /// The rig as loaded (initial guess).
    pub initial: Rig,
    /// The rig being edited.
    pub current: Rig,
    pub undo: Vec<Rig>,
    pub redo: Vec<Rig>,
    pub camera: usize,
    pub frame: usize,
    pub view: ExtrinsicsView,
    pub color_by: ColorBy,
    pub point_size: f32,
    pub max_range_m: f32,
    pub stride: usize,
    pub selected_sensor: Option<String>,
    pub nudge_step_m: f64,
    pub nudge_step_deg: f64,
    /// Messages for the user; errors are shown, never fatal.
    pub status: Vec<String>,
    pub(crate) overlay_cache: super::overlay::OverlayCache,
    pub optimiser: super::optimiser::OptimiserPanel,
    /// Known ground truth (the simulator's demo), for the overlay and pose errors.
    pub ground_truth: Option<Rig>,
    pub demo: Option<super::demo::DemoJob>,
    /// The overlay is drawn by the wgpu paint callback (false: CPU-projected egui mesh).
    pub gpu: bool,
}

impl Default for Studio {
    fn default() -> Self {
        Self {
            drive: None,
            initial: Rig::default(),
            current: Rig::default(),
            undo: Vec::new(),
            redo: Vec::new(),
            camera: 0,
            frame: 0,
            view: ExtrinsicsView::Current,
            color_by: ColorBy::Range,
            point_size: 2.0,
            max_range_m: 80.0,
            stride: 1,
            selected_sensor: None,
            nudge_step_m: 0.01,
            nudge_step_deg: 0.1,
            status: Vec::new(),
            overlay_cache: Default::default(),
            optimiser: Default::default(),
            ground_truth: None,
            demo: None,
            gpu: false,
        }
    }
}

impl Studio {
    pub fn open_log(&mut self, path: &Path) {
        match Drive::open(path) {
            Ok(drive) => {
                self.initial = drive.rig.clone();
                self.current = drive.rig.clone();
                self.undo.clear();
                self.redo.clear();
                self.camera = 0;
                self.frame = 0;
                self.status.push(format!(
                    "opened {} ({} sensors, {} problems)",
                    path.display(),
                    drive.rig.sensors.len(),
                    drive.problems.len()
                ));
                self.drive = Some(Arc::new(drive));
                self.ground_truth = None;
                self.optimiser = Default::default();
                self.overlay_cache = Default::default();
            }
            Err(e) => self.status.push(format!("error: {e}")),
        }
    }

    /// Replace the current extrinsics with those of a calibration file (sensors matched by name).
    pub fn load_calibration(&mut self, path: &Path) {
        match CalibrationFile::load_rig(path) {
            Ok(rig) => {
                let mut next = self.current.clone();
                let mut matched = 0;
                for s in &rig.sensors {
                    if let Some(t) = next.sensor_mut(&s.name) {
                        t.vehicle_from_sensor = s.vehicle_from_sensor;
                        if s.camera.is_some() {
                            t.camera = s.camera.clone();
                        }
                        matched += 1;
                    }
                }
                self.edit(next);
                self.status.push(format!(
                    "loaded {} ({matched} of {} sensors matched)",
                    path.display(),
                    rig.sensors.len()
                ));
            }
            Err(e) => self.status.push(format!("error: {e}")),
        }
    }

    /// Apply an edit to the current rig, recording undo.
    pub fn edit(&mut self, next: Rig) {
        if next != self.current {
            self.undo.push(std::mem::replace(&mut self.current, next));
            self.redo.clear();
        }
    }

    pub fn set_extrinsic(&mut self, sensor: &str, vehicle_from_sensor: Rigid) {
        let mut next = self.current.clone();
        if let Some(s) = next.sensor_mut(sensor) {
            s.vehicle_from_sensor = vehicle_from_sensor;
            self.edit(next);
        }
    }

    pub fn undo(&mut self) {
        if let Some(prev) = self.undo.pop() {
            self.redo.push(std::mem::replace(&mut self.current, prev));
        }
    }

    pub fn redo(&mut self) {
        if let Some(next) = self.redo.pop() {
            self.undo.push(std::mem::replace(&mut self.current, next));
        }
    }

    /// The overlay's current `camera_from_lidar` table (GPU path) and CPU-projected pixels
    /// (fallback path): what the viewport draws, for tests and diagnostics.
    pub fn overlay_state(&self) -> (&[[[f32; 4]; 4]], Vec<[f32; 2]>) {
        self.overlay_cache.state()
    }

    /// The rig the overlay draws with.
    pub fn shown_rig(&self) -> &Rig {
        match self.view {
            ExtrinsicsView::Initial => &self.initial,
            ExtrinsicsView::Current => &self.current,
            ExtrinsicsView::GroundTruth => self.ground_truth.as_ref().unwrap_or(&self.current),
        }
    }
}

impl eframe::App for Studio {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.handle_dropped_files(ui.ctx());
        super::optimiser::poll(self, ui.ctx());
        super::demo::poll(self, ui.ctx());
        egui::Panel::top("menu").show(ui, |ui| self.menu_ui(ui));
        egui::Panel::bottom("status").show(ui, |ui| self.status_ui(ui));
        egui::Panel::left("sensors")
            .default_size(340.0)
            .show(ui, |ui| super::sensors::sensors_ui(self, ui));
        egui::Panel::right("optimiser")
            .default_size(380.0)
            .show(ui, |ui| super::optimiser::optimiser_ui(self, ui));
        egui::CentralPanel::default().show(ui, |ui| super::overlay::viewport_ui(self, ui));
    }
}

impl Studio {
    fn menu_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            if ui.button("Open log…").clicked()
                && let Some(path) = rfd::FileDialog::new()
                    .add_filter("MCAP", &["mcap"])
                    .pick_file()
            {
                self.open_log(&path);
            }
            if ui.button("Load calibration…").clicked()
                && let Some(path) = rfd::FileDialog::new()
                    .add_filter("YAML", &["yaml", "yml"])
                    .pick_file()
            {
                self.load_calibration(&path);
            }
            if ui.button("Save calibration…").clicked()
                && let Some(path) = rfd::FileDialog::new()
                    .add_filter("YAML", &["yaml"])
                    .save_file()
            {
                match CalibrationFile::from_rig(&self.current).save(&path) {
                    Ok(()) => self.status.push(format!("saved {}", path.display())),
                    Err(e) => self.status.push(format!("error: {e}")),
                }
            }
            ui.separator();
            if ui
                .add_enabled(!self.undo.is_empty(), egui::Button::new("Undo"))
                .clicked()
            {
                self.undo();
            }
            if ui
                .add_enabled(!self.redo.is_empty(), egui::Button::new("Redo"))
                .clicked()
            {
                self.redo();
            }
            ui.separator();
            ui.label("Drop an .mcap or calibration .yaml anywhere to open it.");
        });
    }

    fn status_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            match self.status.last() {
                Some(s) if s.starts_with("error") => ui.colored_label(egui::Color32::LIGHT_RED, s),
                Some(s) => ui.label(s),
                None => ui.label("ready"),
            };
            if let Some(d) = &self.drive {
                ui.separator();
                ui.label(format!("{} · {}", d.path().display(), d.trajectory_source));
                if !d.problems.is_empty() {
                    ui.colored_label(
                        egui::Color32::YELLOW,
                        format!("{} problems", d.problems.len()),
                    )
                    .on_hover_text(
                        d.problems
                            .iter()
                            .take(20)
                            .map(|p| p.to_string())
                            .collect::<Vec<_>>()
                            .join("\n"),
                    );
                }
            }
        });
    }

    fn handle_dropped_files(&mut self, ctx: &egui::Context) {
        let dropped: Vec<_> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        });
        for path in dropped {
            match path.extension().and_then(|e| e.to_str()) {
                Some("mcap") => self.open_log(&path),
                Some("yaml" | "yml") => self.load_calibration(&path),
                _ => self.status.push(format!(
                    "error: {}: not an .mcap or .yaml file",
                    path.display()
                )),
            }
        }
    }
}
