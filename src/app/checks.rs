//! Reprojection checks: for every camera–LiDAR pair the target-free edge-alignment score
//! (mean distance in px from projected LiDAR depth discontinuities to the nearest image edge,
//! [`crate::optim::edge_align::EdgeAlignment`]) with the initial and the current extrinsics,
//! worst pair first, a histogram of the per-point distances of the selected pair, and pose
//! errors when the ground truth is known. Scoring runs on a worker thread with progress.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, channel};

use egui_plot::{Bar, BarChart, Legend, Plot};

use super::Studio;
use crate::calib::Rig;
use crate::eval::checkerboard::{BoardSpec, CornerError, pair_corner_error};
use crate::optim::edge_align::EdgeAlignment;

/// One camera–LiDAR pair scored with two rigs.
#[derive(Clone, Debug)]
pub struct PairScore {
    pub camera: String,
    pub lidar: String,
    pub initial_px: f64,
    pub current_px: f64,
    pub initial_distances: Vec<f32>,
    pub current_distances: Vec<f32>,
}

enum Msg {
    Progress(usize, usize),
    Pair(PairScore),
    Skipped(String),
    Done,
}

/// Checkerboard corner error of one camera–LiDAR pair with two rigs.
#[derive(Clone, Debug)]
pub struct CornerRow {
    pub camera: String,
    pub lidar: String,
    pub initial: Option<CornerError>,
    pub current: Option<CornerError>,
}

#[derive(Default)]
pub struct ChecksPanel {
    pub results: Vec<PairScore>,
    /// The (initial, current) rigs `results` were scored with: an export writes a score only
    /// for the rig it was measured on.
    pub scored: Option<(Rig, Rig)>,
    pub spec: Option<BoardSpec>,
    pub corners: Vec<CornerRow>,
    pub corners_progress: (usize, usize),
    pub corners_running: bool,
    corner_job: Option<Receiver<Option<CornerRow>>>,
    pub selected: Option<(String, String)>,
    pub progress: (usize, usize),
    pub running: bool,
    pub skipped: Vec<String>,
    job: Option<Receiver<Msg>>,
    cancel: Option<Arc<AtomicBool>>,
}

/// Every (camera with intrinsics, LiDAR) pair of a rig.
fn camera_lidar_pairs(rig: &Rig) -> Vec<(String, String)> {
    rig.cameras()
        .filter(|c| c.camera.is_some())
        .flat_map(|c| rig.lidars().map(move |l| (c.name.clone(), l.name.clone())))
        .collect()
}

fn pair_progress_ui(ui: &mut egui::Ui, (k, n): (usize, usize)) {
    ui.add(
        egui::ProgressBar::new(k as f32 / n.max(1) as f32)
            .text(format!("pair {k}/{n}"))
            .desired_width(200.0),
    );
}

pub fn start(studio: &mut Studio) {
    let Some(drive) = studio.drive.clone() else {
        return;
    };
    let (initial, current) = (studio.initial.clone(), studio.current.clone());
    studio.checks.scored = Some((initial.clone(), current.clone()));
    let segments = studio.segments.clone();
    let readout = studio.readout();
    let pairs = camera_lidar_pairs(&current);
    let (tx, rx) = channel();
    let cancel = Arc::new(AtomicBool::new(false));
    let stop = cancel.clone();
    std::thread::spawn(move || {
        let total = pairs.len();
        for (k, (cam, lidar)) in pairs.into_iter().enumerate() {
            if stop.load(Ordering::Relaxed) {
                break;
            }
            let _ = tx.send(Msg::Progress(k, total));
            let score = |rig| {
                let pair = (cam.as_str(), lidar.as_str());
                EdgeAlignment::score_rig(&drive, rig, pair, 3, &segments, readout)
            };
            let (before, after) = (score(&initial), score(&current));
            let msg = match (before, after) {
                (Ok(b), Ok(a)) => Msg::Pair(PairScore {
                    camera: cam,
                    lidar,
                    initial_px: b.0,
                    current_px: a.0,
                    initial_distances: b.1,
                    current_distances: a.1,
                }),
                (Err(e), _) | (_, Err(e)) => Msg::Skipped(e.to_string()),
            };
            let _ = tx.send(msg);
        }
        let _ = tx.send(Msg::Done);
    });
    let c = &mut studio.checks;
    c.results.clear();
    c.skipped.clear();
    c.running = true;
    c.progress = (0, 0);
    c.job = Some(rx);
    c.cancel = Some(cancel);
}

/// Measure the checkerboard corner error of every camera–LiDAR pair (initial and current).
pub fn start_corners(studio: &mut Studio) {
    let Some(drive) = studio.drive.clone() else {
        return;
    };
    let spec = studio.checks.spec.unwrap_or_default();
    let (initial, current) = (studio.initial.clone(), studio.current.clone());
    let pairs = camera_lidar_pairs(&current);
    let (tx, rx) = channel();
    studio.checks.corners_progress = (0, pairs.len());
    std::thread::spawn(move || {
        for (camera, lidar) in pairs {
            let a = pair_corner_error(&drive, &initial, &camera, &lidar, 2, &spec);
            let b = pair_corner_error(&drive, &current, &camera, &lidar, 2, &spec);
            let row = CornerRow {
                camera,
                lidar,
                initial: a.ok().flatten(),
                current: b.ok().flatten(),
            };
            if tx.send(Some(row)).is_err() {
                return;
            }
        }
        let _ = tx.send(None);
    });
    studio.checks.corners.clear();
    studio.checks.corners_running = true;
    studio.checks.corner_job = Some(rx);
}

pub fn poll(studio: &mut Studio, ctx: &egui::Context) {
    let c = &mut studio.checks;
    if let Some(rx) = &c.corner_job {
        let (messages, gone) = super::drain(rx);
        for msg in messages {
            match msg {
                Some(row) => {
                    c.corners_progress.0 += 1;
                    c.corners.push(row);
                }
                None => c.corners_running = false,
            }
        }
        if gone && c.corners_running {
            c.corners_running = false;
            studio
                .status
                .push("error: the corner check's worker stopped without finishing".into());
        }
        if c.corners_running {
            ctx.request_repaint_after(std::time::Duration::from_millis(150));
        } else {
            c.corner_job = None;
        }
    }
    let Some(rx) = &c.job else {
        return;
    };
    let (messages, gone) = super::drain(rx);
    for msg in messages {
        match msg {
            Msg::Progress(k, n) => c.progress = (k, n),
            Msg::Pair(p) => {
                c.progress.0 += 1;
                c.results.push(p);
                c.results
                    .sort_by(|a, b| b.current_px.total_cmp(&a.current_px));
            }
            Msg::Skipped(e) => c.skipped.push(e),
            Msg::Done => c.running = false,
        }
    }
    if gone && c.running {
        c.running = false;
        studio
            .status
            .push("error: the checks' worker stopped without finishing".into());
    }
    if c.running {
        ctx.request_repaint_after(std::time::Duration::from_millis(150));
    } else {
        c.job = None;
    }
}

/// The pipeline's report of its last run: per sensor, the verdict, how far it moved, each
/// axis's observability and 1-σ, and the checks before and after.
fn report_ui(studio: &Studio, ui: &mut egui::Ui) {
    let report = match studio.optimiser.report.lock() {
        Ok(slot) => slot.clone(),
        Err(_) => None,
    };
    let Some(report) = report else {
        return;
    };
    use crate::pipeline::report::{Observed, Verdict};
    ui.heading("Calibration report (the pipeline's last run)");
    ui.weak(&report.method);
    egui::Grid::new("pipeline_report")
        .striped(true)
        .show(ui, |ui| {
            for h in [
                "sensor",
                "verdict",
                "moved",
                "axes (1-σ, ° and cm)",
                "checks",
                "why",
            ] {
                ui.strong(h);
            }
            ui.end_row();
            for s in &report.sensors {
                ui.label(&s.name);
                let colour = match s.verdict {
                    Verdict::Good => egui::Color32::LIGHT_GREEN,
                    Verdict::CheckIt => egui::Color32::YELLOW,
                    Verdict::Failed => egui::Color32::LIGHT_RED,
                };
                ui.colored_label(colour, s.verdict.label());
                ui.label(format!("{:.3}° / {:.2} cm", s.moved_deg, s.moved_cm));
                let axes: Vec<String> = s
                    .axes
                    .iter()
                    .map(|a| {
                        let mark = match a.observed {
                            Observed::Observed => "✔",
                            Observed::Weak => "~",
                            Observed::NotObserved => "✘",
                            Observed::Fixed => "fixed",
                            Observed::Unknown => "?",
                        };
                        match a.sigma {
                            Some(v) => format!("{} {mark} ±{v:.2}", a.axis),
                            None => format!("{} {mark}", a.axis),
                        }
                    })
                    .collect();
                ui.label(axes.join("  "));
                let checks: Vec<String> = s
                    .checks
                    .iter()
                    .map(|c| format!("{:.2} → {:.2} {}", c.before, c.after, c.unit))
                    .collect();
                ui.label(checks.join("; "));
                ui.label(&s.why);
                ui.end_row();
            }
        });
    ui.separator();
}

pub(crate) fn checks_ui(studio: &mut Studio, ui: &mut egui::Ui) {
    report_ui(studio, ui);
    ui.heading("Reprojection checks");
    ui.label(
        "Edge alignment per camera–LiDAR pair: mean px from projected LiDAR depth \
         discontinuities to the nearest image edge (truncated at 20 px; lower is better), \
         with the initial and the current extrinsics, on 3 frames of the selected segments.",
    );
    ui.horizontal(|ui| {
        if studio.checks.running {
            pair_progress_ui(ui, studio.checks.progress);
            if ui.button("Cancel").clicked()
                && let Some(c) = &studio.checks.cancel
            {
                c.store(true, Ordering::Relaxed);
            }
        } else if ui
            .add_enabled(
                studio.drive.is_some(),
                egui::Button::new("Score every pair"),
            )
            .clicked()
        {
            start(studio);
        }
    });
    let results = studio.checks.results.clone();
    if !results.is_empty() {
        egui::Grid::new("pair_scores").striped(true).show(ui, |ui| {
            for h in ["camera", "LiDAR", "initial px", "current px", ""] {
                ui.strong(h);
            }
            ui.end_row();
            for p in &results {
                let key = (p.camera.clone(), p.lidar.clone());
                let selected = studio.checks.selected.as_ref() == Some(&key);
                if ui.selectable_label(selected, &p.camera).clicked() {
                    studio.checks.selected = Some(key);
                }
                ui.label(&p.lidar);
                ui.label(format!("{:.2}", p.initial_px));
                ui.label(format!("{:.2}", p.current_px));
                let better = p.current_px < p.initial_px - 0.05;
                let worse = p.current_px > p.initial_px + 0.05;
                if better {
                    ui.colored_label(egui::Color32::LIGHT_GREEN, "better");
                } else if worse {
                    ui.colored_label(egui::Color32::LIGHT_RED, "worse");
                } else {
                    ui.weak("same");
                }
                ui.end_row();
            }
        });
        let shown = studio
            .checks
            .selected
            .as_ref()
            .and_then(|(c, l)| results.iter().find(|p| p.camera == *c && p.lidar == *l))
            .or(results.first());
        if let Some(p) = shown {
            histogram_ui(p, ui);
        }
    }
    for s in &studio.checks.skipped {
        ui.weak(format!("skipped: {s}"));
    }
    ui.separator();
    corners_ui(studio, ui);
    super::optimiser::ground_truth_errors_ui(studio, ui);
}

/// The checkerboard corner error (paper's re-projection metric) per camera–LiDAR pair.
fn corners_ui(studio: &mut Studio, ui: &mut egui::Ui) {
    ui.strong("Checkerboard corner error (target scenes)");
    ui.label(
        "Board corners derived from LiDAR points, projected into the image, against the \
         corners detected there (px, mean). Boards stand upright; the pattern is centred.",
    );
    let mut spec = studio.checks.spec.unwrap_or_default();
    ui.horizontal(|ui| {
        ui.add(
            egui::DragValue::new(&mut spec.squares_u)
                .range(2..=30)
                .suffix(" ×"),
        );
        ui.add(
            egui::DragValue::new(&mut spec.squares_v)
                .range(2..=30)
                .suffix(" squares"),
        );
        let mut sq_cm = spec.square_m * 100.0;
        let mut margin_cm = spec.margin_m * 100.0;
        ui.add(
            egui::DragValue::new(&mut sq_cm)
                .range(1.0..=50.0)
                .speed(0.1)
                .suffix(" cm"),
        );
        ui.add(
            egui::DragValue::new(&mut margin_cm)
                .range(0.0..=50.0)
                .speed(0.1)
                .prefix("margin ")
                .suffix(" cm"),
        );
        spec.square_m = sq_cm / 100.0;
        spec.margin_m = margin_cm / 100.0;
    });
    studio.checks.spec = Some(spec);
    if studio.checks.corners_running {
        pair_progress_ui(ui, studio.checks.corners_progress);
    } else if ui
        .add_enabled(
            studio.drive.is_some(),
            egui::Button::new("Measure corner error"),
        )
        .clicked()
    {
        start_corners(studio);
    }
    let rows: Vec<&CornerRow> = studio
        .checks
        .corners
        .iter()
        .filter(|r| r.initial.is_some() || r.current.is_some())
        .collect();
    if rows.is_empty() {
        if !studio.checks.corners.is_empty() && !studio.checks.corners_running {
            ui.weak("no checkerboard found in any camera–LiDAR pair");
        }
        return;
    }
    let px = |e: &Option<CornerError>| {
        e.as_ref()
            .map_or("–".into(), |e| format!("{:.2}", e.mean_px))
    };
    egui::Grid::new("corner_errors")
        .striped(true)
        .show(ui, |ui| {
            for h in [
                "camera",
                "LiDAR",
                "boards",
                "corners",
                "initial px",
                "current px",
            ] {
                ui.strong(h);
            }
            ui.end_row();
            for r in rows {
                let shown = r.current.as_ref().or(r.initial.as_ref());
                ui.label(&r.camera);
                ui.label(&r.lidar);
                ui.label(shown.map_or(0, |e| e.boards).to_string());
                ui.label(shown.map_or(0, |e| e.corners).to_string());
                ui.label(px(&r.initial));
                ui.label(px(&r.current));
                ui.end_row();
            }
        });
}

/// Histogram of per-point edge distances (1 px bins), initial against current.
fn histogram_ui(p: &PairScore, ui: &mut egui::Ui) {
    ui.label(format!(
        "{} × {}: distance to the nearest image edge (px), share of points",
        p.camera, p.lidar
    ));
    let bins = 21;
    let hist = |d: &[f32]| {
        let mut h = vec![0.0f64; bins];
        for &x in d {
            h[(x.max(0.0) as usize).min(bins - 1)] += 1.0;
        }
        let n = d.len().max(1) as f64;
        h.iter().map(|c| c / n).collect::<Vec<_>>()
    };
    let (a, b) = (hist(&p.initial_distances), hist(&p.current_distances));
    let bars = |h: &[f64], offset: f64| -> Vec<Bar> {
        h.iter()
            .enumerate()
            .map(|(i, v)| Bar::new(i as f64 + offset, *v).width(0.4))
            .collect()
    };
    Plot::new(("edge_hist", &p.camera, &p.lidar))
        .height(150.0)
        .legend(Legend::default())
        .x_axis_label("px (last bin: ≥ 20, truncated)")
        .show(ui, |plot| {
            plot.bar_chart(
                BarChart::new("initial", bars(&a, -0.2)).color(egui::Color32::LIGHT_RED),
            );
            plot.bar_chart(
                BarChart::new("current", bars(&b, 0.2)).color(egui::Color32::LIGHT_GREEN),
            );
        });
}
