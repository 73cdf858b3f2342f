//! Studio state: the open drive, the extrinsics being edited (with undo/redo and axis locks),
//! what the viewport shows, the selected segments, and the session that is autosaved after
//! every change.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::calib::{CalibrationFile, Rig};
use crate::geometry::Rigid;
use crate::log::Drive;
use crate::session::{AxisLocks, RecentFiles, Session};

mod session;

/// Which set of extrinsics the overlay uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ExtrinsicsView {
    Initial,
    Current,
    /// The optimiser's best so far.
    Best,
    GroundTruth,
}

impl ExtrinsicsView {
    pub fn label(self) -> &'static str {
        match self {
            ExtrinsicsView::Initial => "initial",
            ExtrinsicsView::Current => "current",
            ExtrinsicsView::Best => "best",
            ExtrinsicsView::GroundTruth => "ground truth",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorBy {
    Range,
    Intensity,
    /// Height above the vehicle origin (vehicle z).
    Height,
    /// One colour per LiDAR.
    Lidar,
}

/// How LiDAR points are drawn over the images.
#[derive(Clone, Debug, PartialEq)]
pub struct OverlaySettings {
    pub color_by: ColorBy,
    pub point_size: f32,
    pub opacity: f32,
    pub min_range_m: f32,
    pub max_range_m: f32,
    pub height_range_m: [f32; 2],
    /// Keep every n-th point.
    pub stride: usize,
    /// Sweeps drawn on each side of the one nearest the image (each through the trajectory at
    /// its own firing times), for a denser overlay.
    pub accumulate: usize,
    /// Depth-tested splats: hide points behind nearer surfaces.
    pub occlusion: bool,
    pub occlusion_px: f32,
}

impl Default for OverlaySettings {
    fn default() -> Self {
        Self {
            color_by: ColorBy::Range,
            point_size: 2.0,
            opacity: 1.0,
            min_range_m: 0.0,
            max_range_m: 80.0,
            height_range_m: [-2.5, 3.5],
            stride: 1,
            accumulate: 0,
            occlusion: true,
            occlusion_px: 4.0,
        }
    }
}

/// Zoom and pan of the single-camera view: the image pixel at the centre and the zoom factor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewZoom {
    pub center_px: [f32; 2],
    pub zoom: f32,
}

impl Default for ViewZoom {
    fn default() -> Self {
        Self {
            center_px: [f32::NAN; 2],
            zoom: 1.0,
        }
    }
}

/// What is under the cursor in the viewport.
#[derive(Clone, Debug, PartialEq)]
pub struct HoverReadout {
    pub u: f32,
    pub v: f32,
    /// Nearest drawn LiDAR point within a few pixels: its depth (m) and LiDAR.
    pub point: Option<(f32, String)>,
}

/// Right-hand panel tabs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Tab {
    #[default]
    Optimise,
    Checks,
    Export,
}

pub struct Studio {
    pub drive: Option<Arc<Drive>>,
    /// The rig as loaded (initial guess).
    pub initial: Rig,
    /// The rig being edited.
    pub current: Rig,
    pub undo: Vec<Rig>,
    pub redo: Vec<Rig>,
    /// The sensor whose field is being dragged, once the drag has made its undo entry.
    pub(crate) drag_undo_open: Option<String>,
    /// Index into the cameras with intrinsics, and the frame of that camera.
    pub camera: usize,
    pub frame: usize,
    pub view: ExtrinsicsView,
    /// Blink: alternate `view` with `blink_with` twice a second.
    pub blink: bool,
    pub blink_with: ExtrinsicsView,
    pub(crate) blink_phase: bool,
    pub overlay: OverlaySettings,
    /// The cameras' rolling shutter: their first and last image rows were exposed this many
    /// milliseconds after each image's stamp (`rigcal calibrate --camera-readout-ms`); the
    /// overlay and UniCal's runs place each row at its own time. `None`: a global shutter.
    pub camera_readout_ms: Option<(f64, f64)>,
    /// Show every camera at once (each at its frame nearest in time).
    pub grid: bool,
    pub zoom: ViewZoom,
    pub hover: Option<HoverReadout>,
    /// Where the single-camera image was drawn last frame (screen points).
    pub image_rect: Option<egui::Rect>,
    pub selected_sensor: Option<String>,
    pub nudge_step_m: f64,
    pub nudge_step_deg: f64,
    /// Per sensor: x, y, z, roll, pitch, yaw locked against edits and optimisers.
    pub locks: BTreeMap<String, AxisLocks>,
    /// Text typed or pasted into a sensor's "paste" box.
    pub paste_text: String,
    /// Time ranges to calibrate on (nanoseconds; empty = the whole drive).
    pub segments: Vec<(i64, i64)>,
    pub tab: Tab,
    /// Messages for the user; errors are shown, never fatal.
    pub status: Vec<String>,
    pub(crate) overlays: Vec<super::overlay::OverlayCache>,
    pub(crate) sweep_cache: super::overlay::SweepCache,
    pub optimiser: super::optimiser::OptimiserPanel,
    pub checks: super::checks::ChecksPanel,
    pub trajectory_panel: super::trajectory::TrajectoryPanel,
    pub export: super::export::ExportPanel,
    /// Known ground truth (the simulator's demo), for the overlay and pose errors.
    pub ground_truth: Option<Rig>,
    pub demo: Option<super::demo::DemoJob>,
    /// A log being opened on a worker thread ([`Self::open_log_in_background`]).
    pub opening: Option<(
        PathBuf,
        std::sync::mpsc::Receiver<Result<Drive, crate::log::LogError>>,
    )>,
    /// The overlay is drawn by the wgpu paint callback (false: CPU-projected egui mesh).
    pub gpu: bool,
    pub recent: RecentFiles,
    /// Where the session is autosaved after every change (None: no autosave, e.g. in tests).
    pub autosave: Option<PathBuf>,
    pub(crate) saved_session: Option<Session>,
    /// When the autosave last compared the session (it runs at most once a second).
    pub(crate) autosave_checked: Option<std::time::Instant>,
    /// The last autosave write failed (retried every second).
    pub(crate) autosave_failing: bool,
    /// Frame-time measurement (RIGCAL_PROFILE_FRAMES).
    pub profile: Option<super::profile::Profile>,
    /// Camera views drawn with their overlay this frame, and the LiDAR points they submitted.
    pub(crate) pictures: (usize, usize),
}

impl Default for Studio {
    fn default() -> Self {
        Self {
            drive: None,
            initial: Rig::default(),
            current: Rig::default(),
            undo: Vec::new(),
            redo: Vec::new(),
            drag_undo_open: None,
            camera: 0,
            frame: 0,
            view: ExtrinsicsView::Current,
            blink: false,
            blink_with: ExtrinsicsView::Initial,
            blink_phase: false,
            overlay: OverlaySettings::default(),
            camera_readout_ms: None,
            grid: false,
            zoom: ViewZoom::default(),
            hover: None,
            image_rect: None,
            selected_sensor: None,
            nudge_step_m: 0.01,
            nudge_step_deg: 0.1,
            locks: BTreeMap::new(),
            paste_text: String::new(),
            segments: Vec::new(),
            tab: Tab::default(),
            status: Vec::new(),
            overlays: Vec::new(),
            sweep_cache: Default::default(),
            optimiser: Default::default(),
            checks: Default::default(),
            trajectory_panel: Default::default(),
            export: Default::default(),
            ground_truth: None,
            demo: None,
            opening: None,
            gpu: false,
            recent: RecentFiles::default(),
            autosave: None,
            saved_session: None,
            autosave_checked: None,
            autosave_failing: false,
            profile: None,
            pictures: (0, 0),
        }
    }
}

const AXES: [&str; 6] = ["x", "y", "z", "roll", "pitch", "yaw"];

impl Studio {
    /// Open a log now (blocking: start-up, sessions, tests).
    pub fn open_log(&mut self, path: &Path) {
        let opened = Drive::open(path);
        self.install_drive(path, opened);
    }

    /// Open a log on a worker thread, the window staying responsive (a large log takes a
    /// while to index); [`Self::poll_opening`] installs it when it is ready. A second request
    /// replaces the first.
    pub fn open_log_in_background(&mut self, path: &Path) {
        let (tx, rx) = std::sync::mpsc::channel();
        let worker_path = path.to_path_buf();
        std::thread::spawn(move || {
            let _ = tx.send(Drive::open(&worker_path));
        });
        self.opening = Some((path.to_path_buf(), rx));
    }

    /// Install a log opened in the background once its worker is done.
    pub fn poll_opening(&mut self, ctx: &egui::Context) {
        let Some((path, rx)) = &self.opening else {
            return;
        };
        match rx.try_recv() {
            Ok(opened) => {
                let path = path.clone();
                self.opening = None;
                self.install_drive(&path, opened);
            }
            Err(std::sync::mpsc::TryRecvError::Empty) => {
                ctx.request_repaint_after(std::time::Duration::from_millis(100));
            }
            Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                self.status.push(format!(
                    "error: opening {} stopped without a result",
                    path.display()
                ));
                self.opening = None;
            }
        }
    }

    fn install_drive(&mut self, path: &Path, opened: Result<Drive, crate::log::LogError>) {
        match opened {
            Ok(drive) => {
                self.set_edits_aside(path);
                // A demo still being generated would replace this drive when ready.
                self.demo = None;
                self.initial = drive.rig.clone();
                self.current = drive.rig.clone();
                self.undo.clear();
                self.redo.clear();
                self.camera = 0;
                self.frame = 0;
                self.segments.clear();
                self.locks.clear();
                self.status.push(format!(
                    "opened {} ({} sensors, {} problems)",
                    path.display(),
                    drive.rig.sensors.len(),
                    drive.problems.len()
                ));
                self.drive = Some(Arc::new(drive));
                self.ground_truth = None;
                self.optimiser = Default::default();
                self.checks = Default::default();
                self.trajectory_panel = Default::default();
                self.overlays.clear();
                self.sweep_cache = Default::default();
                self.remember(path);
            }
            Err(e) => self.status.push(format!("error: {e}")),
        }
    }

    /// Before another log replaces the open one: if the open one has edits, an optimiser
    /// result or segments, keep its session beside the autosave (which the new log's session
    /// overwrites within a second) and say where. Only with persistence on.
    fn set_edits_aside(&mut self, next_log: &Path) {
        let Some(drive) = &self.drive else { return };
        let edited = !self.undo.is_empty()
            || self.current != self.initial
            || self.optimiser.best.is_some()
            || !self.segments.is_empty();
        if self.autosave.is_none() || !edited || drive.path() == next_log {
            return;
        }
        let path = crate::session::set_aside_path(drive.path());
        match self.session().save(&path) {
            Ok(()) => self.status.push(format!(
                "the session of {} (with your edits) is kept in {}: File ▸ Open session… restores it",
                drive.path().display(),
                path.display()
            )),
            Err(e) => self.status.push(format!(
                "error: could not keep the session of {}: {e}",
                drive.path().display()
            )),
        }
    }

    pub(crate) fn remember(&mut self, path: &Path) {
        self.recent.push(path);
        if self.autosave.is_some() {
            let _ = self.recent.save(&RecentFiles::default_path());
        }
    }

    /// Take the extrinsics (and intrinsics) a calibration file gives the current sensors, as one
    /// edit: the native file, a URDF, a ROS camera_info YAML or the /tf_static of an MCAP
    /// (sensors matched by name or frame id, see [`crate::interop::import`]).
    pub fn load_calibration(&mut self, path: &Path) {
        if self.optimiser_owns_the_rig() {
            return;
        }
        match crate::interop::import::load_initial_guess(path, &self.current) {
            Ok(imported) => {
                self.apply_rig(&imported.rig);
                self.status.push(format!(
                    "loaded {} ({}): {} of {} sensors matched ({})",
                    path.display(),
                    imported.format,
                    imported.matched.len(),
                    self.current.sensors.len(),
                    imported.matched.join(", ")
                ));
                // An MCAP read for its /tf_static is not listed: Open recent opens an MCAP as
                // a log, which would replace the drive this calibration was loaded into.
                let is_mcap = path
                    .extension()
                    .is_some_and(|e| e.eq_ignore_ascii_case("mcap"));
                if !is_mcap {
                    self.remember(path);
                }
            }
            Err(e) => self.status.push(format!("error: {e}")),
        }
    }

    /// Take the extrinsics (and intrinsics) of `rig`'s sensors that this rig has, as one edit.
    fn apply_rig(&mut self, rig: &Rig) -> usize {
        let matched = rig
            .sensors
            .iter()
            .filter(|s| self.current.sensor(&s.name).is_some())
            .count();
        let next = self.merged(rig);
        self.edit(next);
        matched
    }

    /// Whether an optimiser run owns the current rig (it replaces it with every packet, so an
    /// edit now would be lost); says so in the status line when it does.
    fn optimiser_owns_the_rig(&mut self) -> bool {
        let running = self.optimiser.run.is_some();
        if running {
            self.status
                .push("error: the optimiser is running; stop it (or let it finish) to edit".into());
        }
        running
    }

    /// Apply an edit to the current rig, recording undo (refused while an optimiser runs).
    /// Returns whether it was taken (an edit that changes nothing is, without an undo entry).
    pub fn edit(&mut self, next: Rig) -> bool {
        if self.optimiser_owns_the_rig() {
            return false;
        }
        if next != self.current {
            self.undo.push(std::mem::replace(&mut self.current, next));
            self.redo.clear();
        }
        true
    }

    /// Set a sensor's extrinsic; locked axes keep their current values. A transform that is
    /// not finite, or puts the sensor farther from the vehicle frame than a calibration file
    /// may ([`crate::calib::file::MAX_SENSOR_OFFSET_M`]), is refused with an error in the
    /// status line: the rig could not be saved or autosaved.
    /// Returns whether the edit was taken.
    pub fn set_extrinsic(&mut self, sensor: &str, vehicle_from_sensor: Rigid) -> bool {
        match self.with_extrinsic(sensor, vehicle_from_sensor) {
            Some(next) => self.edit(next),
            None => false,
        }
    }

    /// As [`Self::set_extrinsic`], but without an undo entry of its own: the later frames of
    /// one drag, whose first frame made the entry.
    pub fn amend_extrinsic(&mut self, sensor: &str, vehicle_from_sensor: Rigid) {
        if let Some(next) = self.with_extrinsic(sensor, vehicle_from_sensor) {
            if self.undo.is_empty() || self.optimiser.run.is_some() {
                self.edit(next);
            } else {
                self.current = next;
                self.redo.clear();
            }
        }
    }

    /// The current rig with `sensor`'s extrinsic set (locks respected), if it is usable.
    fn with_extrinsic(&mut self, sensor: &str, vehicle_from_sensor: Rigid) -> Option<Rig> {
        let offset_m = vehicle_from_sensor.translation.length();
        let finite = vehicle_from_sensor.rotation.is_finite() && offset_m.is_finite();
        if !finite || offset_m > crate::calib::file::MAX_SENSOR_OFFSET_M {
            self.status.push(format!(
                "error: {sensor}: a transform that is not finite or puts the sensor more than {} m from the vehicle frame is not taken",
                crate::calib::file::MAX_SENSOR_OFFSET_M
            ));
            return None;
        }
        let mut next = self.current.clone();
        let s = next.sensor_mut(sensor)?;
        s.vehicle_from_sensor = match self.locks.get(sensor) {
            Some(locks) => apply_locks(s.vehicle_from_sensor, vehicle_from_sensor, locks),
            None => vehicle_from_sensor,
        };
        Some(next)
    }

    /// `candidate` with every locked axis of every sensor taken from `reference`.
    pub fn respect_locks(&self, reference: &Rig, candidate: &Rig) -> Rig {
        let mut out = candidate.clone();
        for s in &mut out.sensors {
            if let (Some(locks), Some(r)) = (self.locks.get(&s.name), reference.sensor(&s.name)) {
                s.vehicle_from_sensor =
                    apply_locks(r.vehicle_from_sensor, s.vehicle_from_sensor, locks);
            }
        }
        out
    }

    /// Names of a sensor's locked axes, for messages.
    pub fn locked_axes(&self, sensor: &str) -> Vec<&'static str> {
        self.locks.get(sensor).map_or_else(Vec::new, |l| {
            AXES.iter()
                .zip(l)
                .filter(|(_, on)| **on)
                .map(|(a, _)| *a)
                .collect()
        })
    }

    pub fn undo(&mut self) {
        self.drag_undo_open = None;
        if self.optimiser_owns_the_rig() {
            return;
        }
        if let Some(prev) = self.undo.pop() {
            self.redo.push(std::mem::replace(&mut self.current, prev));
        }
    }

    pub fn redo(&mut self) {
        self.drag_undo_open = None;
        if self.optimiser_owns_the_rig() {
            return;
        }
        if let Some(next) = self.redo.pop() {
            self.undo.push(std::mem::replace(&mut self.current, next));
        }
    }

    /// The overlay's current `camera_from_lidar` table (GPU path) and CPU-projected pixels
    /// (fallback path) for the selected camera: what the viewport draws, for tests.
    pub fn overlay_state(&self) -> (&[[[f32; 4]; 4]], Vec<[f32; 2]>) {
        match self.overlays.get(self.camera) {
            Some(c) => c.state(),
            None => (&[], Vec::new()),
        }
    }

    /// The GPU overlay's `camera_from_lidar` table of camera `index` (empty until drawn).
    pub fn overlay_transforms(&self, index: usize) -> &[[[f32; 4]; 4]] {
        self.overlays.get(index).map_or(&[], |c| c.state().0)
    }

    /// The view the overlay shows this frame (blink alternates two).
    pub fn effective_view(&self) -> ExtrinsicsView {
        if self.blink && self.blink_phase {
            self.blink_with
        } else {
            self.view
        }
    }

    /// The rig for a view (falls back to the current rig when that view has none).
    pub fn rig_for(&self, view: ExtrinsicsView) -> &Rig {
        match view {
            ExtrinsicsView::Initial => &self.initial,
            ExtrinsicsView::Current => &self.current,
            ExtrinsicsView::Best => self.optimiser.best.as_ref().unwrap_or(&self.current),
            ExtrinsicsView::GroundTruth => self.ground_truth.as_ref().unwrap_or(&self.current),
        }
    }

    /// The rig the overlay draws with.
    pub fn shown_rig(&self) -> &Rig {
        self.rig_for(self.effective_view())
    }
}

/// `candidate` with the locked axes (x, y, z, roll, pitch, yaw) of `reference`.
pub fn apply_locks(reference: Rigid, candidate: Rigid, locks: &AxisLocks) -> Rigid {
    if !locks.iter().any(|&l| l) {
        return candidate;
    }
    let mut xyz = candidate.translation.to_array();
    let r = reference.translation.to_array();
    for i in 0..3 {
        if locks[i] {
            xyz[i] = r[i];
        }
    }
    let mut rpy = candidate.roll_pitch_yaw_rad();
    let r_rpy = reference.roll_pitch_yaw_rad();
    for i in 0..3 {
        if locks[3 + i] {
            rpy[i] = r_rpy[i];
        }
    }
    Rigid::new(
        glam::DQuat::from_euler(glam::EulerRot::ZYX, rpy[2], rpy[1], rpy[0]),
        glam::DVec3::from_array(xyz),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DQuat, DVec3, EulerRot};

    #[test]
    fn locked_axes_keep_the_reference_values() {
        let a = Rigid::new(
            DQuat::from_euler(EulerRot::ZYX, 0.1, 0.02, -0.03),
            DVec3::new(1.0, 2.0, 3.0),
        );
        let b = Rigid::new(
            DQuat::from_euler(EulerRot::ZYX, 0.2, 0.05, 0.01),
            DVec3::new(1.5, 2.5, 3.5),
        );
        let out = apply_locks(a, b, &[true, false, false, false, false, true]);
        assert_eq!(out.translation, DVec3::new(1.0, 2.5, 3.5));
        let [r, p, y] = out.roll_pitch_yaw_rad();
        assert!((y - 0.1).abs() < 1e-12 && (p - 0.05).abs() < 1e-12 && (r - 0.01).abs() < 1e-12);
        assert_eq!(apply_locks(a, b, &[false; 6]), b);
    }
}
