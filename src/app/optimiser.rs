//! Optimiser panel: choose the method, the reference LiDAR and the cameras, start / pause /
//! resume / stop a background run, watch progress, loss curves and per-camera alignment scores.
//!
//! The run lives in [`crate::optim::runner::Run`]; every frame [`poll`] drains its packets
//! (never blocking), shows the live extrinsics in the overlay and records the loss history.
//! When a run ends, its best rig becomes the current one as a single undoable edit.

use egui_plot::{Legend, Line, Plot, PlotPoints};

use crate::calib::{Rig, SensorKind};
use crate::geometry::{RowTimes, rig_errors};
use crate::optim::edge_refine::EdgeRefiner;
use crate::optim::runner::{Calibrator, Run};

use super::Studio;

mod readouts;
pub(crate) use readouts::ground_truth_errors_ui;
use readouts::*;

/// Methods the panel offers. UniCal and the classical calibrators join as they land.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Method {
    /// The automatic pipeline, as `rigcal calibrate LOG --out FILE` runs it.
    #[default]
    Pipeline,
    EdgeAlign,
    Icp,
    MutualInformation,
    Target,
    PoseGraph,
    UnicalLidar,
    Unical,
}

impl Method {
    /// Every method, in the panel's order.
    pub const ALL: [Method; 8] = [
        Method::Pipeline,
        Method::EdgeAlign,
        Method::Icp,
        Method::MutualInformation,
        Method::Target,
        Method::PoseGraph,
        Method::UnicalLidar,
        Method::Unical,
    ];

    /// The name a session file stores (`rigcal calibrate --method`'s where there is one).
    pub fn key(self) -> &'static str {
        match self {
            Method::Pipeline => "auto",
            Method::EdgeAlign => "edge",
            Method::Icp => "icp",
            Method::MutualInformation => "mi",
            Method::Target => "target",
            Method::PoseGraph => "pose-graph",
            Method::UnicalLidar => "unical-lidar",
            Method::Unical => "unical",
        }
    }

    /// The method a session's key names, `None` for an unknown one.
    pub fn from_key(key: &str) -> Option<Method> {
        Self::ALL.into_iter().find(|m| m.key() == key)
    }

    fn label(self) -> &'static str {
        match self {
            Method::Pipeline => "Calibrate everything (the pipeline: every LiDAR and camera)",
            Method::EdgeAlign => "Edge alignment (cameras vs LiDAR, rotation)",
            Method::Icp => "Point-to-plane ICP (LiDARs vs the reference LiDAR)",
            Method::MutualInformation => {
                "Mutual information (cameras vs LiDAR reflectivity, ±2° / ±20 cm)"
            }
            Method::Target => {
                "Checkerboards, edge-and-plane (cameras vs LiDAR; checkerboard scenes)"
            }
            Method::PoseGraph => {
                "Pairwise + pose graph (ICP, checkerboards or MI; every sensor, reference fixed)"
            }
            Method::UnicalLidar => "UniCal, LiDAR terms (scene + LiDARs; slow on CPU)",
            Method::Unical => {
                "UniCal, LiDARs + cameras (the fast quality: 1/8-size images, 500 steps)"
            }
        }
    }
}

#[derive(Default)]
pub struct OptimiserPanel {
    pub method: Method,
    pub reference_lidar: Option<String>,
    /// Cameras to optimise (empty = all).
    pub cameras: Vec<String>,
    /// UniCal with cameras: every LiDAR keeps its extrinsic (e.g. registered by ICP first).
    pub hold_lidars: bool,
    /// UniCal with cameras: fit each camera to its own motion first (hand-eye against the
    /// trajectory; for starts degrees off).
    pub hand_eye: bool,
    /// What the hand-eye did to each camera, written by the run's preparation and moved to
    /// the status bar by [`poll`].
    pub hand_eye_notes: std::sync::Arc<std::sync::Mutex<Vec<String>>>,
    pub frames: usize,
    pub run: Option<Run>,
    /// The rig when the run started (restored by undo).
    pub started_from: Option<Rig>,
    /// (step, losses) of the current or last run.
    pub history: Vec<(usize, Vec<(String, f64)>)>,
    /// (step, sensor, rotation change deg) against the start.
    pub pose_change: Vec<(usize, String, f64)>,
    pub progress: (usize, usize, f64),
    pub message: Option<String>,
    /// The best rig of the current or last run (shown as "best" in the viewport).
    pub best: Option<Rig>,
    /// The pipeline's report of its last run (the checks tab shows it).
    pub report: crate::pipeline::calibrator::ReportSink,
}

impl OptimiserPanel {
    pub fn method_label(&self) -> &'static str {
        self.method.label()
    }
}

/// Drain packets from a running optimiser (non-blocking).
pub fn poll(studio: &mut Studio, ctx: &egui::Context) {
    let notes: Vec<String> = match studio.optimiser.hand_eye_notes.lock() {
        Ok(mut notes) => notes.drain(..).collect(),
        Err(_) => Vec::new(),
    };
    studio.status.extend(notes);
    let Some(run) = studio.optimiser.run.as_ref() else {
        return;
    };
    let (packets, worker_gone) = super::drain(&run.packets);
    let mut finished = false;
    if worker_gone && !packets.iter().any(|p| p.finished || p.error.is_some()) {
        // The worker ended without its last packet (it panicked): end the run here, keeping
        // the best result it sent, rather than a progress bar forever.
        let e = "the optimiser's worker stopped without a result; the last extrinsics it sent stay (Undo restores the start)";
        studio.optimiser.message = Some(format!("error: {e}"));
        studio.status.push(format!("error: {e}"));
        finished = true;
    }
    for p in packets {
        if let Some(e) = p.error {
            studio.optimiser.message = Some(format!("error: {e}"));
            studio.status.push(format!("error: optimiser: {e}"));
            finished = true;
            continue;
        }
        studio.optimiser.progress = (p.step, p.max_steps, p.steps_per_sec);
        // The Stop packet carries no losses: the curves and the table keep the last ones.
        if !p.losses.is_empty() {
            studio.optimiser.history.push((p.step, p.losses.clone()));
        }
        if let Some(start) = &studio.optimiser.started_from {
            for s in p.current.sensors.iter() {
                if let Some(s0) = start.sensor(&s.name) {
                    let (rot, _) = s0.vehicle_from_sensor.difference(s.vehicle_from_sensor);
                    if rot > 0.0 {
                        studio.optimiser.pose_change.push((
                            p.step,
                            s.name.clone(),
                            rot.to_degrees(),
                        ));
                    }
                }
            }
        }
        // Live extrinsics in the overlay (not an undo step each time); locked axes stay put.
        let start = studio
            .optimiser
            .started_from
            .clone()
            .unwrap_or_else(|| studio.current.clone());
        studio.current = studio.respect_locks(&start, &p.current);
        studio.optimiser.best = Some(studio.respect_locks(&start, &p.best));
        if p.finished {
            studio.current = studio.respect_locks(&start, &p.best);
            finished = true;
            if let Some(note) = &p.note {
                studio.optimiser.message = Some(format!("error: {note}"));
                studio.status.push(format!("error: optimiser: {note}"));
            }
        }
    }
    if finished {
        studio.optimiser.run = None;
        if let Some(start) = studio.optimiser.started_from.take()
            && start != studio.current
        {
            studio.undo.push(start);
            studio.redo.clear();
            studio
                .status
                .push("optimiser finished (Undo restores the start)".into());
        }
    }
    if studio.optimiser.run.is_some() {
        ctx.request_repaint_after(std::time::Duration::from_millis(100));
    }
}

/// What the run says of a rolling-shutter readout: the rows' times, and the cameras that lose
/// images to it (rows before the trajectory's start or after its end).
fn readout_note(
    global: &crate::log::Drive,
    rolling: &crate::log::Drive,
    cameras: &[String],
    segments: &[(i64, i64)],
    readout: RowTimes,
) -> String {
    let lost: Vec<String> = cameras
        .iter()
        .filter_map(|c| {
            let (kept, all) = (
                rolling.frames_within(c, segments).len(),
                global.frames_within(c, segments).len(),
            );
            (kept < all).then(|| format!("{c} {kept} of {all}"))
        })
        .collect();
    format!(
        "rolling shutter: image rows exposed from {:+.1} to {:+.1} ms after each stamp; \
         UniCal places each row at its own time{}",
        readout.first_row_nanos as f64 * 1e-6,
        readout.last_row_nanos as f64 * 1e-6,
        if lost.is_empty() {
            String::new()
        } else {
            format!(
                "; images with rows outside the trajectory left out: {}",
                lost.join(", ")
            )
        }
    )
}

/// The pipeline's configuration from the studio's state: the defaults `rigcal calibrate`
/// starts from, with the studio's rolling-shutter readout.
pub fn pipeline_config(studio: &Studio) -> crate::pipeline::PipelineConfig {
    let mut config = crate::pipeline::PipelineConfig::default();
    config.cameras.readout_ms = studio.camera_readout_ms;
    config
}

/// What the pipeline is asked to calibrate from the studio's state: the ticked cameras (none
/// ticked: all) and every LiDAR, within the selected segments.
pub fn pipeline_request(studio: &Studio) -> crate::pipeline::PlanRequest {
    let sensors = if studio.optimiser.cameras.is_empty() {
        Vec::new()
    } else {
        studio
            .current
            .sensors
            .iter()
            .filter(|s| s.kind == SensorKind::Lidar || studio.optimiser.cameras.contains(&s.name))
            .map(|s| s.name.clone())
            .collect()
    };
    crate::pipeline::PlanRequest {
        root: None,
        sensors,
        segments_nanos: studio.segments.clone(),
    }
}

/// Start the pipeline on the current rig: the plan is made and its stages before UniCal run
/// while the run prepares; its decisions and notes reach the status bar, its report the
/// checks tab.
fn start_pipeline(studio: &mut Studio, drive: std::sync::Arc<crate::log::Drive>) {
    let config = pipeline_config(studio);
    let request = pipeline_request(studio);
    let rig = studio.current.clone();
    let notes = studio.optimiser.hand_eye_notes.clone();
    let sink = studio.optimiser.report.clone();
    if let Ok(mut slot) = sink.lock() {
        *slot = None;
    }
    studio.optimiser.message =
        Some("planning: reading the drive's motion and checking the cameras' start…".into());
    studio.optimiser.run = Some(Run::spawn_preparing(move |preparing| {
        let started = std::time::Instant::now();
        let drive = match config.cameras.readout_ms {
            Some((first, last)) => {
                std::sync::Arc::new(drive.with_camera_readout(RowTimes::from_millis(first, last)))
            }
            None => drive,
        };
        preparing.report("planning", 0, 1);
        let plan = crate::pipeline::Plan::build(&drive, &rig, &request, &config)?;
        if let Ok(mut notes) = notes.lock() {
            notes.extend(plan.decisions.iter().map(|d| format!("plan: {d}")));
        }
        let run = crate::pipeline::calibrator::PipelineCalibrator::prepare(
            drive,
            rig,
            plan,
            started,
            &|phase, done, total| preparing.report(phase, done, total),
        )?
        .with_report_sink(sink);
        if let Ok(mut notes) = notes.lock() {
            notes.extend(run.notes().iter().cloned());
        }
        Ok::<_, crate::RunError>(Box::new(run) as Box<dyn Calibrator>)
    }));
}

/// Start a run with the panel's settings.
pub fn start(studio: &mut Studio) {
    let Some(drive) = studio.drive.clone() else {
        studio.optimiser.message = Some("open a drive first".into());
        return;
    };
    let rig = studio.current.clone();
    let Some(lidar) = studio
        .optimiser
        .reference_lidar
        .clone()
        .or_else(|| rig.lidars().next().map(|l| l.name.clone()))
    else {
        studio.optimiser.message = Some("this drive has no LiDAR".into());
        return;
    };
    let cameras: Vec<String> = if studio.optimiser.cameras.is_empty() {
        rig.cameras().map(|c| c.name.clone()).collect()
    } else {
        studio.optimiser.cameras.clone()
    };
    let frames = studio.optimiser.frames.max(1);
    let prepare_rig = rig.clone();
    let segments = studio.segments.clone();
    studio.optimiser.history.clear();
    studio.optimiser.pose_change.clear();
    studio.optimiser.progress = (0, 0, 0.0);
    studio.optimiser.message = Some(format!(
        "preparing {} camera(s) on {frames} frame(s){}…",
        cameras.len(),
        if segments.is_empty() {
            ""
        } else {
            " of the selected segments"
        }
    ));
    studio.optimiser.started_from = Some(rig);
    let method = studio.optimiser.method;
    if method == Method::Pipeline {
        start_pipeline(studio, drive);
        return;
    }
    if matches!(method, Method::UnicalLidar | Method::Unical) {
        studio.optimiser.message = Some(format!(
            "preparing the neural scene from {frames} sweep(s) per LiDAR{}…",
            if method == Method::Unical {
                " and image(s) per camera"
            } else {
                ""
            }
        ));
        // The reference LiDAR is the root: its extrinsic stays fixed; so do the cameras not
        // ticked (when some are) and, if asked, every LiDAR.
        let held_sensors = prepare_rig
            .sensors
            .iter()
            .filter(|s| match s.kind {
                SensorKind::Lidar => method == Method::Unical && studio.optimiser.hold_lidars,
                _ => !studio.optimiser.cameras.is_empty() && !cameras.contains(&s.name),
            })
            .map(|s| s.name.clone())
            .collect();
        // The single-method UniCal run is the quick look: the fast quality's steps and scale.
        let mut config = crate::unical::depth_calib::DepthCalibConfig {
            iterations: crate::pipeline::Quality::Fast.preset().iterations,
            frozen_sensor: Some(lidar),
            held_sensors,
            correspondence_cache: Some(crate::session::state_dir().join("matches")),
            ..Default::default()
        };
        let hand_eye = method == Method::Unical && studio.optimiser.hand_eye;
        let readout = studio
            .camera_readout_ms
            .filter(|_| method == Method::Unical)
            .map(|(first, last)| RowTimes::from_millis(first, last));
        let notes = studio.optimiser.hand_eye_notes.clone();
        studio.optimiser.run = Some(Run::spawn_preparing(move |preparing| {
            // The studio's drive has a global shutter: the run sees the same log with the
            // readout, for its images and the hand-eye.
            let drive = match readout {
                Some(readout) => {
                    let rolling = drive.with_camera_readout(readout);
                    if let Ok(mut notes) = notes.lock() {
                        notes.push(readout_note(&drive, &rolling, &cameras, &segments, readout));
                    }
                    std::sync::Arc::new(rolling)
                }
                None => drive,
            };
            let prepare_rig = if hand_eye {
                use crate::classical::camera_motion;
                let map = camera_motion::lidar_map(&drive, &prepare_rig);
                if let (Err(e), Ok(mut notes)) = (&map, notes.lock()) {
                    notes.push(format!(
                        "camera hand-eye: no LiDAR map to measure translations against: {e}"
                    ));
                }
                let (fitted, outcomes) = camera_motion::fit_rig_cameras(
                    &drive,
                    &prepare_rig,
                    &cameras,
                    camera_motion::DEFAULT_FRAMES,
                    &segments,
                    map.as_ref().ok(),
                    &|phase, done, total| preparing.report(phase, done, total),
                );
                if let Ok(mut notes) = notes.lock() {
                    notes.extend(outcomes.iter().map(|o| o.summary()));
                }
                // Fitted cameras get the hand-eye schedule and bound.
                let names: Vec<String> = outcomes
                    .iter()
                    .filter(|o| o.fit.is_ok())
                    .map(|o| o.name.clone())
                    .collect();
                config = config
                    .after_hand_eye(&names, crate::classical::camera_motion::ROTATION_BOUND_DEG);
                fitted
            } else {
                prepare_rig
            };
            let covered = if method == Method::Unical {
                crate::unical::calibrator::training_stamps(&drive, &prepare_rig, frames, &segments)
            } else {
                Vec::new()
            };
            let stage = crate::unical::calibrator::UnicalLidarStage::from_drive_covering(
                &drive,
                &prepare_rig,
                frames,
                &segments,
                &covered,
                config,
            )?;
            let stage = if method == Method::Unical {
                stage.with_cameras_reporting(
                    &drive,
                    frames,
                    &segments,
                    crate::pipeline::Quality::Fast.preset().image_scale,
                    &|phase, done, total| preparing.report(phase, done, total),
                )?
            } else {
                stage
            };
            Ok::<_, crate::RunError>(Box::new(stage) as Box<dyn Calibrator>)
        }));
        return;
    }
    if method == Method::Icp {
        studio.optimiser.message = Some(format!(
            "registering every LiDAR against {lidar} on {frames} sweep(s)…"
        ));
        studio.optimiser.run = Some(Run::spawn_with(move || {
            crate::classical::icp_calibrator::IcpCalibrator::from_drive(
                &drive,
                &prepare_rig,
                &lidar,
                frames,
                &segments,
                crate::classical::icp::IcpConfig::default(),
            )
            .map(|c| Box::new(c) as Box<dyn Calibrator>)
        }));
        return;
    }
    if method == Method::PoseGraph {
        studio.optimiser.message = Some(format!(
            "preparing every LiDAR pair and camera–LiDAR pair ({lidar} fixed)…"
        ));
        let config = crate::classical::pose_graph_calibrator::PoseGraphConfig {
            frames,
            ..Default::default()
        };
        studio.optimiser.run = Some(Run::spawn_with(move || {
            crate::classical::pose_graph_calibrator::PoseGraphCalibrator::from_drive(
                &drive,
                &prepare_rig,
                &lidar,
                &segments,
                config,
            )
            .map(|c| Box::new(c) as Box<dyn Calibrator>)
        }));
        return;
    }
    if method == Method::Target {
        studio.optimiser.message = Some(format!(
            "finding checkerboards in {} camera(s) and {lidar}…",
            cameras.len()
        ));
        let config = crate::classical::target::TargetConfig {
            frames,
            ..Default::default()
        };
        studio.optimiser.run = Some(Run::spawn_with(move || {
            crate::classical::target_calibrator::TargetCalibrator::from_drive(
                &drive,
                &prepare_rig,
                &lidar,
                &cameras,
                &segments,
                config,
                &Default::default(),
            )
            .map(|c| Box::new(c) as Box<dyn Calibrator>)
        }));
        return;
    }
    if method == Method::MutualInformation {
        studio.optimiser.run = Some(Run::spawn_with(move || {
            crate::classical::mi_calibrator::MiCalibrator::from_drive(
                &drive,
                &prepare_rig,
                &lidar,
                &cameras,
                frames,
                &segments,
                crate::classical::mutual_info::MiConfig::default(),
            )
            .map(|c| Box::new(c) as Box<dyn Calibrator>)
        }));
        return;
    }
    let readout = studio.readout();
    studio.optimiser.run = Some(Run::spawn_with(move || {
        EdgeRefiner::new(
            &drive,
            &prepare_rig,
            (&lidar, &cameras),
            frames,
            &segments,
            readout,
        )
        .map(|r| Box::new(r) as Box<dyn Calibrator>)
        .map_err(|e| e.to_string())
    }));
}

pub fn optimiser_ui(studio: &mut Studio, ui: &mut egui::Ui) {
    ui.heading("Optimiser");
    if studio.optimiser.frames == 0 {
        studio.optimiser.frames = 4;
    }
    let running = studio.optimiser.run.is_some();
    ui.add_enabled_ui(!running, |ui| {
        egui::ComboBox::from_label("method")
            .selected_text(studio.optimiser.method.label())
            .show_ui(ui, |ui| {
                for m in Method::ALL {
                    ui.selectable_value(&mut studio.optimiser.method, m, m.label());
                }
            });
        let lidars: Vec<String> = studio
            .current
            .sensors
            .iter()
            .filter(|s| s.kind == SensorKind::Lidar)
            .map(|s| s.name.clone())
            .collect();
        let shown = studio
            .optimiser
            .reference_lidar
            .clone()
            .or_else(|| lidars.first().cloned())
            .unwrap_or_default();
        egui::ComboBox::from_label("reference LiDAR (fixed)")
            .selected_text(shown)
            .show_ui(ui, |ui| {
                for l in &lidars {
                    ui.selectable_value(&mut studio.optimiser.reference_lidar, Some(l.clone()), l);
                }
            });
        ui.label("cameras to optimise (none ticked = all):");
        let cams: Vec<String> = studio.current.cameras().map(|c| c.name.clone()).collect();
        ui.horizontal_wrapped(|ui| {
            for c in cams {
                let mut on = studio.optimiser.cameras.contains(&c);
                if ui.checkbox(&mut on, &c).changed() {
                    if on {
                        studio.optimiser.cameras.push(c.clone());
                    } else {
                        studio.optimiser.cameras.retain(|x| *x != c);
                    }
                }
            }
        });
        if studio.optimiser.method == Method::Pipeline {
            ui.weak(
                "the plan, its images, scale and steps are rigcal calibrate's (quality default, \
                 10 min budget); its decisions appear in the status bar, its report under Checks",
            );
        } else {
            ui.add(egui::Slider::new(&mut studio.optimiser.frames, 1..=12).text("frames"));
        }
        if studio.optimiser.method == Method::Unical {
            ui.checkbox(
                &mut studio.optimiser.hold_lidars,
                "hold every LiDAR (e.g. registered by ICP first)",
            );
            ui.checkbox(
                &mut studio.optimiser.hand_eye,
                "fit each camera to its own motion first (hand-eye; for starts degrees off, \
                 on a drive that turns)",
            )
            .on_hover_text(
                "Matches each camera's images a few metres apart and fits its rotation (and the \
                 translation the turns observe) to the vehicle's motion before the scene is \
                 learned. Takes about 5 s per camera; a straight drive keeps the cameras.",
            );
        }
        if matches!(
            studio.optimiser.method,
            Method::Unical | Method::EdgeAlign | Method::Pipeline
        ) && let Some((first, last)) = studio.camera_readout_ms
        {
            ui.weak(format!(
                "rolling shutter: rows from {first:+.1} to {last:+.1} ms after each stamp \
                 (set under the image)"
            ));
        }
    });
    ui.horizontal(|ui| {
        if !running {
            if ui
                .add_enabled(studio.drive.is_some(), egui::Button::new("Start"))
                .clicked()
            {
                start(studio);
            }
        } else if let Some(run) = &studio.optimiser.run {
            if run.is_paused() {
                if ui.button("Resume").clicked() {
                    run.resume();
                }
            } else if ui.button("Pause").clicked() {
                run.pause();
            }
            if ui.button("Stop").clicked() {
                run.stop();
            }
        }
    });
    let (step, max, rate) = studio.optimiser.progress;
    if running || step > 0 {
        let frac = if max > 0 {
            step as f32 / max as f32
        } else {
            0.0
        };
        let eta = if rate > 0.0 && max > step {
            format!("≤ {:.0} s left", (max - step) as f64 / rate)
        } else {
            String::new()
        };
        ui.add(
            egui::ProgressBar::new(frac).text(format!("step {step}/{max} · {rate:.1} it/s {eta}")),
        );
    }
    if let Some(m) = &studio.optimiser.message {
        if m.starts_with("error") {
            ui.colored_label(egui::Color32::LIGHT_RED, m);
        } else if running && step == 0 {
            ui.label(m);
        }
    }
    let preparing = studio
        .optimiser
        .run
        .as_ref()
        .and_then(|run| run.preparing.get());
    if let Some((phase, done, total)) = preparing.filter(|_| running && step == 0) {
        ui.add(
            egui::ProgressBar::new(done as f32 / total.max(1) as f32)
                .text(format!("{phase} {done}/{total}")),
        );
    }
    ui.separator();
    losses_ui(studio, ui);
    ui.separator();
    alignment_table_ui(studio, ui);
    ground_truth_errors_ui(studio, ui);
}

/// The rolling-shutter setting: a tick, then when the first and the last row were exposed.
pub(crate) fn readout_ui(readout_ms: &mut Option<(f64, f64)>, ui: &mut egui::Ui) {
    let mut rolling = readout_ms.is_some();
    let help = "Each image row was exposed at its own time, evenly from the first (top edge) \
                to the last (bottom edge), in milliseconds after the image's stamp (negative: \
                before it). The overlay then projects every point from where the vehicle was \
                when the row it falls on was exposed, and UniCal casts every ray so. As \
                `rigcal calibrate --camera-readout-ms FIRST..LAST`. The alignment scores \
                (Reprojection checks, the optimiser's table) and edge alignment do so too; \
                mutual information and the checkerboards still project each image at its \
                stamp.";
    if ui
        .checkbox(&mut rolling, "rolling-shutter cameras")
        .on_hover_text(help)
        .changed()
    {
        *readout_ms = rolling.then_some(DEFAULT_READOUT_MS);
    }
    if let Some((first, last)) = readout_ms {
        let ms = |v| {
            egui::DragValue::new(v)
                .range(-1000.0..=1000.0)
                .speed(0.5)
                .suffix(" ms")
        };
        ui.horizontal(|ui| {
            ui.label("rows exposed from");
            ui.add(ms(first));
            ui.label("to");
            ui.add(ms(last));
            ui.label("after each stamp");
        });
    }
}

/// The readout the rolling-shutter tick starts from: 30 ms, centred on the stamp.
pub const DEFAULT_READOUT_MS: (f64, f64) = (-15.0, 15.0);
