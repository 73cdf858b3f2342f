//! The window: panel layout, the File menu (open, recent, calibration, sessions), undo/redo
//! shortcuts, drag-and-drop and the status line. Each frame also drains the workers' packets
//! and autosaves the session when it changed.

use std::path::PathBuf;

use super::state::{Studio, Tab};
use crate::calib::CalibrationFile;
use crate::session::Session;

impl eframe::App for Studio {
    fn on_exit(&mut self) {
        self.autosave_on_exit();
    }

    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.pictures = (0, 0);
        self.handle_dropped_files(ui.ctx());
        self.handle_shortcuts(ui.ctx());
        super::optimiser::poll(self, ui.ctx());
        super::checks::poll(self, ui.ctx());
        super::trajectory::poll(self, ui.ctx());
        super::demo::poll(self, ui.ctx());
        self.poll_opening(ui.ctx());
        egui::Panel::top("menu").show(ui, |ui| self.menu_ui(ui));
        egui::Panel::bottom("status").show(ui, |ui| self.status_ui(ui));
        egui::Panel::bottom("trajectory")
            .resizable(true)
            .default_size(230.0)
            .show(ui, |ui| super::trajectory::trajectory_ui(self, ui));
        egui::Panel::left("sensors")
            .default_size(340.0)
            .show(ui, |ui| super::sensors::sensors_ui(self, ui));
        egui::Panel::right("tabs")
            .default_size(400.0)
            .show(ui, |ui| {
                ui.horizontal(|ui| {
                    ui.selectable_value(&mut self.tab, Tab::Optimise, "Optimise");
                    ui.selectable_value(&mut self.tab, Tab::Checks, "Checks");
                    ui.selectable_value(&mut self.tab, Tab::Export, "Export");
                });
                ui.separator();
                egui::ScrollArea::vertical().show(ui, |ui| match self.tab {
                    Tab::Optimise => super::optimiser::optimiser_ui(self, ui),
                    Tab::Checks => super::checks::checks_ui(self, ui),
                    Tab::Export => super::export::export_ui(self, ui),
                });
            });
        egui::CentralPanel::default().show(ui, |ui| super::overlay::viewport_ui(self, ui));
        self.autosave_if_changed();
        if let Some(p) = &mut self.profile {
            let (pictures, points) = self.pictures;
            if let Some(report) = p.on_frame(pictures, points, pictures) {
                println!("{report}");
                let (inside, visible) = super::overlay::points_in_images(self);
                println!("LiDAR points inside the shown images: {inside} ({visible} not occluded)");
                ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
                self.profile = None;
            } else {
                ui.ctx().request_repaint();
            }
        }
    }
}

impl Studio {
    fn menu_ui(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| self.file_menu(ui));
            ui.separator();
            if ui
                .add_enabled(!self.undo.is_empty(), egui::Button::new("Undo"))
                .on_hover_text("Ctrl+Z")
                .clicked()
            {
                self.undo();
            }
            if ui
                .add_enabled(!self.redo.is_empty(), egui::Button::new("Redo"))
                .on_hover_text("Ctrl+Shift+Z")
                .clicked()
            {
                self.redo();
            }
            ui.separator();
            ui.weak(
                "Drop an .mcap, calibration .yaml / .urdf or session .json anywhere to open it.",
            );
        });
    }

    fn file_menu(&mut self, ui: &mut egui::Ui) {
        if ui.button("Open log…").clicked()
            && let Some(path) = rfd::FileDialog::new()
                .add_filter("MCAP", &["mcap"])
                .pick_file()
        {
            self.open_log_in_background(&path);
        }
        ui.menu_button("Open recent", |ui| {
            if self.recent.paths.is_empty() {
                ui.weak("(nothing yet)");
            }
            for path in self.recent.paths.clone() {
                if ui.button(path.display().to_string()).clicked() {
                    self.open_any(path);
                }
            }
        });
        ui.separator();
        if ui
            .button("Load calibration…")
            .on_hover_text(
                "a rigcal calibration, URDF, ROS camera_info YAML or the /tf_static of an MCAP; \
                 sensors are matched by name or frame id",
            )
            .clicked()
            && let Some(path) = rfd::FileDialog::new()
                .add_filter("calibration", &["yaml", "yml", "urdf", "xml", "mcap"])
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
        if ui.button("Open session…").clicked()
            && let Some(path) = rfd::FileDialog::new()
                .add_filter("rigcal session", &["json"])
                .pick_file()
        {
            self.restore_session(&path);
        }
        if ui
            .add_enabled(self.drive.is_some(), egui::Button::new("Save session…"))
            .clicked()
            && let Some(path) = rfd::FileDialog::new()
                .add_filter("rigcal session", &["json"])
                .set_file_name("calibration.rigcal-session.json")
                .save_file()
        {
            self.save_session(&path);
        }
        let previous = crate::session::previous_session_path();
        if ui
            .add_enabled(previous.exists(), egui::Button::new("Restore last session"))
            .on_hover_text(format!(
                "the previous run's session, autosaved after every change: {} (the {} runs before it: previous-1 … previous-{} beside it, with File ▸ Open session)",
                previous.display(),
                crate::session::EARLIER_SESSIONS_KEPT,
                crate::session::EARLIER_SESSIONS_KEPT
            ))
            .clicked()
        {
            self.restore_session(&previous);
        }
    }

    /// Open a file by its kind: log, calibration or session.
    pub fn open_any(&mut self, path: PathBuf) {
        let name = path.to_string_lossy().to_lowercase();
        if name.ends_with(".mcap") {
            self.open_log_in_background(&path);
        } else if [".yaml", ".yml", ".urdf"].iter().any(|e| name.ends_with(e)) {
            self.load_calibration(&path);
        } else if name.ends_with(".json") {
            self.restore_session(&path);
        } else {
            self.status.push(format!(
                "error: {}: not an .mcap, calibration .yaml / .urdf or session .json file",
                path.display()
            ));
        }
    }

    fn status_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            match self.status.last() {
                Some(s) if s.starts_with("error") => ui.colored_label(egui::Color32::LIGHT_RED, s),
                Some(s) => ui.label(s),
                None => ui.label("ready"),
            };
            if let Some((path, _)) = &self.opening {
                ui.separator();
                ui.spinner();
                ui.label(format!("opening {}…", path.display()));
            }
            if self.autosave_failing {
                ui.separator();
                ui.colored_label(egui::Color32::LIGHT_RED, "autosave failing")
                    .on_hover_text("the session could not be written (a full disk?); retried every second; File ▸ Save session… elsewhere keeps your work");
            }
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

    fn handle_shortcuts(&mut self, ctx: &egui::Context) {
        let (undo, redo) = ctx.input_mut(|i| {
            let redo = i.consume_key(
                egui::Modifiers::COMMAND | egui::Modifiers::SHIFT,
                egui::Key::Z,
            );
            let undo = i.consume_key(egui::Modifiers::COMMAND, egui::Key::Z);
            (undo, redo)
        });
        if redo {
            self.redo();
        } else if undo {
            self.undo();
        }
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
            self.open_any(path);
        }
    }

    /// At start-up: remember recent files, set the previous run's autosave aside for File ▸
    /// Restore last session, and autosave from now on.
    pub fn enable_persistence(&mut self) {
        use crate::session::{
            RecentFiles, autosave_path, previous_session_path, set_autosave_aside,
        };
        self.recent = RecentFiles::load(&RecentFiles::default_path());
        match set_autosave_aside() {
            Ok(()) => self.autosave = Some(autosave_path()),
            Err(e) => self.status.push(format!(
                "error: could not set the last run's autosave aside ({e}), so this run does not autosave; the last run's is still at {}",
                autosave_path().display()
            )),
        }
        if let Some(d) = self.drive.clone() {
            self.remember(d.path());
        }
        if let Ok(s) = Session::load(&previous_session_path())
            && let Some(log) = s.log
        {
            self.status.push(format!(
                "File > Restore last session reopens {} with your edits",
                log.display()
            ));
        }
    }
}
