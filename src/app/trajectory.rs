//! The trajectory panel: a top-down map of the drive (trajectory coloured by time over the
//! aggregated LiDAR map, built on a worker thread), a timeline on which dragging selects the
//! time segments to calibrate on, and each segment's motion summary
//! ([`crate::geometry::motion::MotionSummary`]) so a user sees that straight driving
//! constrains less.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, channel};

use egui::{Color32, Pos2, Rect, Sense, Stroke, Vec2};
use egui_plot::{Line, Plot, PlotImage, PlotPoint, PlotPoints, Points};

use super::Studio;
use super::overlay::colormap;
use crate::calib::Rig;
use crate::geometry::Trajectory;
use crate::geometry::motion::MotionSummary;
use crate::geometry::projection::world_points;
use crate::log::Drive;

/// The top-down map: aggregated LiDAR points rasterised into a density image (drawn as one
/// texture, cheap on software renderers), and the trajectory.
pub struct MapData {
    /// (stamp, x, y) every 0.1 s (more sparsely past 20 000 samples).
    pub trajectory: Vec<(i64, [f64; 2])>,
    /// World rectangle the raster covers: min x, min y, size (square), and the raster.
    pub raster_min: [f64; 2],
    pub raster_size_m: f64,
    pub raster: Option<egui::ColorImage>,
}

const RASTER_PX: usize = 512;
/// LiDAR surroundings shown around the trajectory on the map.
const MAP_MARGIN_M: f64 = 40.0;

impl MapData {
    fn rasterise(&mut self, points_xy: &[[f64; 2]]) {
        // The trajectory's bounding box with a margin of LiDAR surroundings.
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for (_, p) in &self.trajectory {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k] - MAP_MARGIN_M);
                hi[k] = hi[k].max(p[k] + MAP_MARGIN_M);
            }
        }
        if lo[0] > hi[0] {
            return;
        }
        let size = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1.0) * 1.02;
        let center = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        self.raster_min = [center[0] - size / 2.0, center[1] - size / 2.0];
        self.raster_size_m = size;
        let mut count = vec![0u32; RASTER_PX * RASTER_PX];
        for p in points_xy {
            let x = ((p[0] - self.raster_min[0]) / size * RASTER_PX as f64) as usize;
            let y = ((p[1] - self.raster_min[1]) / size * RASTER_PX as f64) as usize;
            if x < RASTER_PX && y < RASTER_PX {
                // Image rows go down, world y goes up.
                count[(RASTER_PX - 1 - y) * RASTER_PX + x] += 1;
            }
        }
        let pixels: Vec<egui::Color32> = count
            .iter()
            .map(|&c| {
                let v = if c == 0 {
                    0
                } else {
                    (70.0 + 40.0 * (c as f32).ln()).min(200.0) as u8
                };
                egui::Color32::from_rgba_unmultiplied(v, v, v, if c == 0 { 0 } else { 255 })
            })
            .collect();
        self.raster = Some(egui::ColorImage::new([RASTER_PX, RASTER_PX], pixels));
    }
}

#[derive(Default)]
pub struct TrajectoryPanel {
    pub map: Option<Arc<MapData>>,
    texture: Option<egui::TextureHandle>,
    job: Option<Receiver<Result<MapData, String>>>,
    drag_from: Option<i64>,
}

const MAP_POINTS: usize = 60_000;

/// Aggregate up to ~`MAP_POINTS` LiDAR points (every LiDAR, sweeps spread over the drive).
pub fn build_map(drive: &Drive, rig: &Rig) -> Result<MapData, crate::RunError> {
    let (t0, t1) = drive
        .trajectory
        .time_range_nanos()
        .ok_or_else(|| crate::RunError::NotEnoughData("the drive has no trajectory".into()))?;
    let trajectory: Vec<(i64, [f64; 2])> = Trajectory::sample_stamps(t0, t1, 100_000_000, 20_000)
        .into_iter()
        .filter_map(|t| {
            let p = drive.trajectory.world_from_vehicle(t).ok()?.translation;
            Some((t, [p.x, p.y]))
        })
        .collect();
    let mut points_xy = Vec::new();
    let lidars: Vec<_> = rig.lidars().collect();
    let per_lidar = MAP_POINTS / lidars.len().max(1);
    for lidar in lidars {
        let Some(stream) = drive.stream(&lidar.name) else {
            continue;
        };
        let n = stream.frames.len();
        let sweeps: Vec<usize> = (0..n).step_by((n / 16).max(1)).collect();
        let per_sweep = per_lidar / sweeps.len().max(1);
        for i in sweeps {
            let Ok(s) = drive.load_sweep(&lidar.name, i) else {
                continue;
            };
            let stride = (s.points_in_sensor.len() / per_sweep.max(1)).max(1);
            let view = s.view();
            if let Ok(pts) =
                world_points(&view, &drive.trajectory, lidar.vehicle_from_sensor, stride)
            {
                points_xy.extend(pts.iter().map(|p| [p.x, p.y]));
            }
        }
    }
    let mut map = MapData {
        trajectory,
        raster_min: [0.0; 2],
        raster_size_m: 1.0,
        raster: None,
    };
    map.rasterise(&points_xy);
    Ok(map)
}

pub fn poll(studio: &mut Studio, ctx: &egui::Context) {
    let panel = &mut studio.trajectory_panel;
    if panel.map.is_none()
        && panel.job.is_none()
        && let Some(drive) = studio.drive.clone()
    {
        let (tx, rx) = channel();
        let rig = studio.current.clone();
        std::thread::spawn(move || {
            let _ = tx.send(build_map(&drive, &rig).map_err(|e| e.to_string()));
        });
        panel.job = Some(rx);
    }
    if let Some(rx) = &panel.job {
        let result = match rx.try_recv() {
            Ok(result) => result,
            Err(std::sync::mpsc::TryRecvError::Empty) => {
                ctx.request_repaint_after(std::time::Duration::from_millis(200));
                return;
            }
            Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                Err("its worker stopped without a result".to_string())
            }
        };
        match result {
            Ok(map) => {
                panel.texture = map.raster.clone().map(|img| {
                    ctx.load_texture("trajectory-map", img, egui::TextureOptions::NEAREST)
                });
                panel.map = Some(Arc::new(map));
            }
            Err(e) => {
                studio.status.push(format!("error: trajectory map: {e}"));
                panel.map = Some(Arc::new(MapData {
                    trajectory: Vec::new(),
                    raster_min: [0.0; 2],
                    raster_size_m: 1.0,
                    raster: None,
                }));
            }
        }
        panel.job = None;
    }
}

pub(crate) fn trajectory_ui(studio: &mut Studio, ui: &mut egui::Ui) {
    let Some(drive) = studio.drive.clone() else {
        ui.weak("Trajectory: open a drive.");
        return;
    };
    let Some((t0, t1)) = drive.trajectory.time_range_nanos() else {
        ui.weak("This drive has no trajectory.");
        return;
    };
    let image_stamp = super::overlay::camera_names(&studio.current)
        .get(studio.camera)
        .and_then(|c| drive.stream(c))
        .and_then(|s| s.frames.get(studio.frame))
        .map(|f| f.stamp_nanos);
    ui.columns(2, |cols| {
        map_ui(studio, &mut cols[0], t0, t1, image_stamp);
        segments_ui(studio, &mut cols[1], &drive, t0, t1, image_stamp);
    });
}

fn map_ui(studio: &Studio, ui: &mut egui::Ui, t0: i64, t1: i64, now: Option<i64>) {
    let Some(map) = studio.trajectory_panel.map.clone() else {
        ui.horizontal(|ui| {
            ui.spinner();
            ui.label("building the top-down map…");
        });
        return;
    };
    let span = (t1 - t0).max(1) as f64;
    // Highlight only selected segments (none selected: nothing is highlighted).
    let in_segment =
        |t: i64| !studio.segments.is_empty() && crate::log::in_segments(&studio.segments, t);
    Plot::new("topdown")
        .data_aspect(1.0)
        .show_axes([false, false])
        .show_grid(false)
        .allow_scroll(false)
        .show(ui, |plot| {
            if let Some(tex) = &studio.trajectory_panel.texture {
                let half = map.raster_size_m / 2.0;
                plot.image(PlotImage::new(
                    "LiDAR map",
                    tex.id(),
                    PlotPoint::new(map.raster_min[0] + half, map.raster_min[1] + half),
                    Vec2::splat(map.raster_size_m as f32),
                ));
            }
            // Trajectory coloured by time, thicker inside selected segments.
            // Chunks of 1 s, each in its time colour (one line per chunk keeps this cheap).
            let mut start = 0;
            while start + 1 < map.trajectory.len() {
                let end = (start + 10).min(map.trajectory.len() - 1);
                let (ta, _) = map.trajectory[start];
                let c = colormap(((ta - t0) as f64 / span) as f32);
                let width = if in_segment(ta) { 5.0 } else { 2.0 };
                let pts: Vec<[f64; 2]> = map.trajectory[start..=end].iter().map(|x| x.1).collect();
                plot.line(Line::new("", PlotPoints::from(pts)).color(c).width(width));
                start = end;
            }
            if let Some(t) = now
                && let Some((_, p)) = map.trajectory.iter().min_by_key(|(s, _)| (s - t).abs())
            {
                plot.points(
                    Points::new("now", PlotPoints::from(vec![*p]))
                        .color(Color32::WHITE)
                        .radius(5.0),
                );
            }
        });
}

fn segments_ui(
    studio: &mut Studio,
    ui: &mut egui::Ui,
    drive: &Drive,
    t0: i64,
    t1: i64,
    now: Option<i64>,
) {
    ui.label("Segments to calibrate on: drag on the timeline (none = the whole drive)");
    let (rect, response) =
        ui.allocate_exact_size(Vec2::new(ui.available_width(), 26.0), Sense::drag());
    let span = (t1 - t0).max(1) as f64;
    let to_x = |t: i64| rect.left() + ((t - t0) as f64 / span) as f32 * rect.width();
    let to_t =
        |x: f32| t0 + (((x - rect.left()) / rect.width()).clamp(0.0, 1.0) as f64 * span) as i64;
    let painter = ui.painter_at(rect);
    // Timeline coloured by time like the map, with yaw rate as a trace.
    let steps = 120;
    for k in 0..steps {
        let a = rect.left() + rect.width() * k as f32 / steps as f32;
        let b = rect.left() + rect.width() * (k + 1) as f32 / steps as f32;
        painter.rect_filled(
            Rect::from_min_max(
                Pos2::new(a, rect.bottom() - 5.0),
                Pos2::new(b, rect.bottom()),
            ),
            0.0,
            colormap(k as f32 / steps as f32),
        );
    }
    for &(a, b) in &studio.segments {
        painter.rect_filled(
            Rect::from_min_max(
                Pos2::new(to_x(a), rect.top()),
                Pos2::new(to_x(b), rect.bottom() - 6.0),
            ),
            2.0,
            Color32::from_rgba_unmultiplied(80, 160, 255, 160),
        );
    }
    if let (Some(from), Some(pos)) = (
        studio.trajectory_panel.drag_from,
        response.interact_pointer_pos(),
    ) {
        let (a, b) = (from.min(to_t(pos.x)), from.max(to_t(pos.x)));
        painter.rect_stroke(
            Rect::from_min_max(
                Pos2::new(to_x(a), rect.top()),
                Pos2::new(to_x(b), rect.bottom() - 6.0),
            ),
            2.0,
            Stroke::new(1.5, Color32::WHITE),
            egui::StrokeKind::Inside,
        );
    }
    if let Some(t) = now {
        painter.vline(to_x(t), rect.y_range(), Stroke::new(2.0, Color32::WHITE));
    }
    painter.rect_stroke(
        rect,
        2.0,
        Stroke::new(1.0, Color32::GRAY),
        egui::StrokeKind::Inside,
    );
    if response.drag_started()
        && let Some(pos) = response.interact_pointer_pos()
    {
        studio.trajectory_panel.drag_from = Some(to_t(pos.x));
    }
    if response.drag_stopped() {
        if let (Some(from), Some(pos)) = (
            studio.trajectory_panel.drag_from,
            response.interact_pointer_pos(),
        ) {
            let (a, b) = (from.min(to_t(pos.x)), from.max(to_t(pos.x)));
            if b - a > 200_000_000 {
                add_segment(&mut studio.segments, (a, b));
            }
        }
        studio.trajectory_panel.drag_from = None;
    }
    ui.horizontal(|ui| {
        if ui.button("clear").clicked() {
            studio.segments.clear();
        }
        ui.weak(format!("drive: {:.1} s", span * 1e-9));
    });
    let rows: Vec<(Option<usize>, i64, i64)> = if studio.segments.is_empty() {
        vec![(None, t0, t1)]
    } else {
        studio
            .segments
            .iter()
            .enumerate()
            .map(|(i, &(a, b))| (Some(i), a, b))
            .collect()
    };
    let log_range = drive.time_range_nanos().unwrap_or((t0, t1));
    let mut remove = None;
    egui::Grid::new("segments").striped(true).show(ui, |ui| {
        for h in ["segment", "s", "km/h", "max °/s", "turn °", "turns", "", ""] {
            ui.strong(h);
        }
        ui.end_row();
        for (i, a, b) in rows {
            // Summarised where there is sensor data, as labelled.
            let (ca, cb) = (
                a.clamp(log_range.0, log_range.1),
                b.clamp(log_range.0, log_range.1),
            );
            let (sa, sb) = if cb > ca { (ca, cb) } else { (a, b) };
            let Some(m) = MotionSummary::of(&drive.trajectory, sa, sb) else {
                continue;
            };
            ui.label(segment_label((a, b), log_range));
            ui.label(format!("{:.1}", m.duration_s));
            ui.label(format!("{:.0}", m.mean_speed_mps * 3.6));
            ui.label(format!("{:.1}", m.max_abs_yaw_rate_deg_s));
            ui.label(format!("{:.0}", m.total_turn_deg));
            ui.label(format!("{}", m.turns));
            let verdict = m.verdict();
            let short = verdict.split(':').next().unwrap_or(verdict);
            let color = match short {
                "turning" => Color32::LIGHT_GREEN,
                "gentle curves" => Color32::LIGHT_YELLOW,
                _ => Color32::from_rgb(255, 170, 90),
            };
            ui.colored_label(color, short).on_hover_text(verdict);
            match i {
                Some(i) => {
                    if ui.small_button("remove").clicked() {
                        remove = Some(i);
                    }
                }
                None => {
                    ui.weak("whole drive");
                }
            }
            ui.end_row();
        }
    });
    if let Some(i) = remove {
        studio.segments.remove(i);
    }
}

/// A segment as seconds from the start of the log, as `rigcal calibrate --segment` counts
/// them, shown within the sensor data (`log_range`): the trajectory may start before the first
/// sensor frame or end after the last, where there is nothing to calibrate on.
fn segment_label((a, b): (i64, i64), (log_t0, log_t1): (i64, i64)) -> String {
    let seconds = |t: i64| (t.clamp(log_t0, log_t1) - log_t0) as f64 * 1e-9;
    format!("{:.1}–{:.1} s", seconds(a), seconds(b))
}

/// Add a segment, merging overlapping ones and keeping them sorted.
pub fn add_segment(segments: &mut Vec<(i64, i64)>, new: (i64, i64)) {
    segments.push(new);
    segments.sort();
    let mut merged: Vec<(i64, i64)> = Vec::with_capacity(segments.len());
    for &(a, b) in segments.iter() {
        match merged.last_mut() {
            Some(last) if a <= last.1 => last.1 = last.1.max(b),
            _ => merged.push((a, b)),
        }
    }
    *segments = merged;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_are_labelled_within_the_sensor_data() {
        // The demo drive's trajectory starts 0.2 s before its first sensor frame.
        let log = (1_000_000_000, 9_000_000_000);
        assert_eq!(
            segment_label((800_000_000, 9_000_000_000), log),
            "0.0–8.0 s"
        );
        assert_eq!(
            segment_label((3_000_000_000, 5_500_000_000), log),
            "2.0–4.5 s"
        );
        assert_eq!(
            segment_label((3_000_000_000, 9_500_000_000), log),
            "2.0–8.0 s"
        );
    }

    #[test]
    fn overlapping_segments_merge() {
        let mut s = vec![(10, 20)];
        add_segment(&mut s, (30, 40));
        add_segment(&mut s, (15, 32));
        assert_eq!(s, vec![(10, 40)]);
        add_segment(&mut s, (0, 5));
        assert_eq!(s, vec![(0, 5), (10, 40)]);
    }
}
