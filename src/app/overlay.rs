//! The camera viewport: images with LiDAR sweeps projected through the shown extrinsics.
//!
//! One camera (zoom with the wheel, pan by dragging, double-click to reset; u, v and the depth
//! of the point under the cursor are read out) or a grid of every camera, each at its frame
//! nearest in time to the scrubber. With a wgpu renderer the points are projected and
//! occlusion-tested on the GPU ([`super::gpu_overlay`]), one offscreen target per camera tile.
//! Otherwise, and for the hover readout, projection and occlusion run in the library
//! ([`crate::geometry::projection`]) and are cached until the frame or the extrinsics change.

use std::sync::Arc;

use egui::{Color32, Pos2, Rect, Vec2};

use super::gpu_overlay::{
    GpuPoint, OverlayCallback, Uniforms, pack_bucket, paint_callback, transforms_f32,
};
use super::state::{ColorBy, ExtrinsicsView, HoverReadout, Studio};
use crate::calib::{Rig, SensorKind};
use crate::geometry::Rigid;
use crate::geometry::projection::{
    ProjectedPoint, bucket_count, camera_from_lidar_rows, point_buckets, project_sweep_rolling,
    shutter_rows, visible_points,
};
use crate::log::{Drive, LidarSweep};

mod points;
pub(crate) use points::points_in_images;
use points::*;

/// Sweeps decoded for the overlay, shared by every camera.
#[derive(Default)]
pub(crate) struct SweepCache {
    sweeps: Vec<(String, usize, Arc<LidarSweep>)>,
}

const SWEEP_CACHE: usize = 128;

impl SweepCache {
    fn get(&mut self, drive: &Drive, lidar: &str, index: usize) -> Result<Arc<LidarSweep>, String> {
        if let Some(i) = self
            .sweeps
            .iter()
            .position(|(n, k, _)| n == lidar && *k == index)
        {
            let entry = self.sweeps.remove(i);
            let s = entry.2.clone();
            self.sweeps.push(entry);
            return Ok(s);
        }
        let s = Arc::new(drive.load_sweep(lidar, index).map_err(|e| e.to_string())?);
        self.sweeps.push((lidar.to_string(), index, s.clone()));
        if self.sweeps.len() > SWEEP_CACHE {
            self.sweeps.remove(0);
        }
        Ok(s)
    }
}

/// A LiDAR point projected on the CPU, with what colouring needs.
#[derive(Clone, Copy, Debug)]
struct CpuPoint {
    p: ProjectedPoint,
    lidar: u8,
    height_m: f32,
    visible: bool,
}

/// Per camera: its texture, the sweeps drawn over it and their projections.
#[derive(Default)]
pub(crate) struct OverlayCache {
    /// The camera this slot holds: the camera list shifts when a loaded calibration gives a
    /// camera intrinsics (or an undo takes them away), and a slot must not keep another's.
    camera: String,
    /// Frame, stride, accumulated sweeps and the readout (ms bits) the points were made for.
    key: Option<(usize, usize, usize, Option<[u64; 2]>)>,
    /// Camera poses per firing-time bucket in `gpu_transforms` (1, or a rolling shutter's).
    gpu_rows: u32,
    rig: Option<Rig>,
    texture: Option<(usize, egui::TextureHandle)>,
    sweeps: Vec<(usize, Arc<LidarSweep>)>,
    /// GPU path: points (far to near) with packed bucket/LiDAR indices, and the bucket
    /// transforms.
    gpu_points: Arc<Vec<GpuPoint>>,
    gpu_points_key: u64,
    /// The sweeps and stride `gpu_points` were built from.
    gpu_base_key: u64,
    gpu_transforms: Vec<[[f32; 4]; 4]>,
    /// Per sweep: the camera's optical axis in the LiDAR frame when the points were culled
    /// to the camera's view cone (re-culled when it turns by more than `RECULL_DEG`).
    gpu_cone_axes: Vec<glam::DVec3>,
    intensity_max: f32,
    /// CPU projection (fallback path, hover readout), far to near; valid for `cpu_key`.
    cpu: Vec<CpuPoint>,
    cpu_key: Option<(bool, u32)>,
}

impl OverlayCache {
    pub(crate) fn state(&self) -> (&[[[f32; 4]; 4]], Vec<[f32; 2]>) {
        (
            &self.gpu_transforms,
            self.cpu.iter().map(|p| p.p.pixel).collect(),
        )
    }
}

/// `img` shrunk (keeping its aspect) so neither side exceeds `max_side` px, if it must be: the
/// GPU refuses larger textures, and the overlay maps the image by normalised coordinates, so a
/// smaller picture lines up the same.
fn fit_texture_side(img: &image::RgbImage, max_side: usize) -> Option<image::RgbImage> {
    let longest = img.width().max(img.height()) as usize;
    if longest <= max_side || max_side == 0 {
        return None;
    }
    let scale = max_side as f64 / longest as f64;
    let w = ((img.width() as f64 * scale).floor() as u32).clamp(1, max_side as u32);
    let h = ((img.height() as f64 * scale).floor() as u32).clamp(1, max_side as u32);
    Some(image::imageops::resize(
        img,
        w,
        h,
        image::imageops::FilterType::Triangle,
    ))
}

/// A perceptual rainbow (turbo-like) for t in [0, 1].
pub fn colormap(t: f32) -> Color32 {
    let t = f64::from(t.clamp(0.0, 1.0));
    let r = (0.13572138
        + t * (4.6153926
            + t * (-42.66032258 + t * (132.13108234 + t * (-152.94239396 + t * 59.28637943)))))
        .clamp(0.0, 1.0);
    let g = (0.09140261
        + t * (2.19418839
            + t * (4.84296658 + t * (-14.18503333 + t * (4.27729857 + t * 2.82956604)))))
        .clamp(0.0, 1.0);
    let b = (0.1066733
        + t * (12.64194608
            + t * (-60.58204836 + t * (110.36276771 + t * (-89.90310912 + t * 27.34824973)))))
        .clamp(0.0, 1.0);
    Color32::from_rgb((r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8)
}

/// The same palette as the shader's colour-by-LiDAR.
const LIDAR_COLORS: [[u8; 3]; 8] = [
    [255, 89, 51],
    [51, 204, 255],
    [115, 255, 77],
    [255, 217, 38],
    [217, 102, 255],
    [255, 255, 255],
    [255, 128, 179],
    [128, 153, 255],
];

pub(crate) fn camera_names(rig: &Rig) -> Vec<String> {
    rig.sensors
        .iter()
        .filter(|s| s.kind == SensorKind::Camera && s.camera.is_some())
        .map(|s| s.name.clone())
        .collect()
}

/// The frame of `camera` nearest in time to `stamp`.
fn nearest_frame(drive: &Drive, camera: &str, stamp: i64) -> Option<usize> {
    let frames = &drive.stream(camera)?.frames;
    frames
        .iter()
        .enumerate()
        .min_by_key(|(_, f)| (f.stamp_nanos - stamp).abs())
        .map(|(i, _)| i)
}

pub(crate) fn viewport_ui(studio: &mut Studio, ui: &mut egui::Ui) {
    if let Some(job) = &studio.demo {
        super::demo::progress_ui(job, ui);
        return;
    }
    let Some(drive) = studio.drive.clone() else {
        ui.centered_and_justified(|ui| {
            ui.heading("Open a drive (File > Open log…, or drop an .mcap here)")
        });
        return;
    };
    let cameras = camera_names(&studio.current);
    if cameras.is_empty() {
        ui.label("This drive has no camera with intrinsics.");
        return;
    }
    studio.camera = studio.camera.min(cameras.len() - 1);
    if studio.overlays.len() < cameras.len() {
        studio.overlays.resize_with(cameras.len(), Default::default);
    }
    let camera = cameras[studio.camera].clone();
    let n_frames = drive.stream(&camera).map_or(0, |s| s.frames.len());
    toolbar_ui(studio, ui, &cameras, &drive, n_frames);
    studio.frame = studio.frame.min(n_frames.saturating_sub(1));
    if n_frames == 0 {
        ui.label(format!("{camera} has no images in this log."));
        return;
    }
    if studio.blink {
        studio.blink_phase = (ui.input(|i| i.time) * 2.0) as i64 % 2 == 1;
        ui.ctx()
            .request_repaint_after(std::time::Duration::from_millis(100));
    }
    if studio.grid {
        grid_ui(studio, ui, &cameras, &drive);
    } else {
        single_ui(studio, ui, &camera, &drive);
    }
}

fn toolbar_ui(
    studio: &mut Studio,
    ui: &mut egui::Ui,
    cameras: &[String],
    drive: &Drive,
    n_frames: usize,
) {
    ui.horizontal_wrapped(|ui| {
        egui::ComboBox::from_label("camera")
            .selected_text(&cameras[studio.camera])
            .show_ui(ui, |ui| {
                for (i, c) in cameras.iter().enumerate() {
                    ui.selectable_value(&mut studio.camera, i, c);
                }
            });
        ui.checkbox(&mut studio.grid, "all cameras");
        if n_frames > 0 {
            let t0 = drive.time_range_nanos().map_or(0, |r| r.0);
            let stamps: Vec<i64> = drive
                .stream(&cameras[studio.camera])
                .map(|s| s.frames.iter().map(|f| f.stamp_nanos).collect())
                .unwrap_or_default();
            ui.add(
                egui::Slider::new(&mut studio.frame, 0..=n_frames - 1)
                    .text("frame")
                    .custom_formatter(|v, _| {
                        let i = (v as usize).min(stamps.len().saturating_sub(1));
                        let t = stamps.get(i).map_or(0.0, |s| (s - t0) as f64 * 1e-9);
                        format!("{i} · t = {t:.2} s")
                    }),
            );
        }
        ui.separator();
        let mut views = vec![ExtrinsicsView::Initial, ExtrinsicsView::Current];
        if studio.optimiser.best.is_some() {
            views.push(ExtrinsicsView::Best);
        }
        if studio.ground_truth.is_some() {
            views.push(ExtrinsicsView::GroundTruth);
        }
        for v in &views {
            ui.selectable_value(&mut studio.view, *v, v.label());
        }
        ui.checkbox(&mut studio.blink, "blink")
            .on_hover_text("alternate the shown extrinsics twice a second");
        egui::ComboBox::from_label("with")
            .selected_text(studio.blink_with.label())
            .show_ui(ui, |ui| {
                for v in &views {
                    ui.selectable_value(&mut studio.blink_with, *v, v.label());
                }
            });
    });
    ui.horizontal_wrapped(|ui| {
        let o = &mut studio.overlay;
        egui::ComboBox::from_label("colour")
            .selected_text(match o.color_by {
                ColorBy::Range => "range",
                ColorBy::Intensity => "intensity",
                ColorBy::Height => "height",
                ColorBy::Lidar => "LiDAR",
            })
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut o.color_by, ColorBy::Range, "range");
                ui.selectable_value(&mut o.color_by, ColorBy::Intensity, "intensity");
                ui.selectable_value(&mut o.color_by, ColorBy::Height, "height");
                ui.selectable_value(&mut o.color_by, ColorBy::Lidar, "LiDAR");
            });
        ui.add(egui::Slider::new(&mut o.point_size, 0.5..=6.0).text("size"));
        ui.add(egui::Slider::new(&mut o.opacity, 0.1..=1.0).text("opacity"));
        ui.add(
            egui::DragValue::new(&mut o.min_range_m)
                .range(0.0..=o.max_range_m)
                .prefix("range ")
                .suffix(" m"),
        );
        ui.add(
            egui::DragValue::new(&mut o.max_range_m)
                .range(o.min_range_m.max(1.0)..=300.0)
                .prefix("– ")
                .suffix(" m"),
        );
        ui.add(
            egui::DragValue::new(&mut o.stride)
                .range(1..=64)
                .prefix("every ")
                .suffix(" pts"),
        );
        ui.add(
            egui::DragValue::new(&mut o.accumulate)
                .range(0..=30)
                .prefix("± ")
                .suffix(" sweeps"),
        )
        .on_hover_text("draw neighbouring sweeps too, each through the trajectory");
        ui.checkbox(&mut o.occlusion, "occlusion")
            .on_hover_text("depth-tested splats: hide points behind nearer surfaces");
        if o.occlusion {
            ui.add(
                egui::DragValue::new(&mut o.occlusion_px)
                    .range(1.0..=12.0)
                    .suffix(" px"),
            );
        }
        super::optimiser::readout_ui(&mut studio.camera_readout_ms, ui);
    });
}

fn grid_ui(studio: &mut Studio, ui: &mut egui::Ui, cameras: &[String], drive: &Drive) {
    let Some(stamp) = drive
        .stream(&cameras[studio.camera])
        .and_then(|s| s.frames.get(studio.frame))
        .map(|f| f.stamp_nanos)
    else {
        return;
    };
    let n = cameras.len();
    let area = ui.available_rect_before_wrap();
    // The column count that makes the tiles largest for the first camera's aspect.
    let aspect = studio
        .current
        .sensor(&cameras[0])
        .and_then(|s| s.camera.as_ref())
        .map_or(16.0 / 9.0, |c| c.width as f32 / c.height.max(1) as f32);
    let cols = (1..=n)
        .max_by(|&a, &b| {
            let scale = |c: usize| {
                let (w, h) = (
                    area.width() / c as f32,
                    area.height() / n.div_ceil(c) as f32,
                );
                (w / aspect).min(h)
            };
            scale(a).total_cmp(&scale(b))
        })
        .unwrap_or(1);
    let rows = n.div_ceil(cols);
    let cell = Vec2::new(area.width() / cols as f32, area.height() / rows as f32);
    ui.allocate_rect(area, egui::Sense::hover());
    for (i, cam) in cameras.iter().enumerate() {
        let Some(frame) = nearest_frame(drive, cam, stamp) else {
            continue;
        };
        let Some(intr) = studio.current.sensor(cam).and_then(|s| s.camera.clone()) else {
            continue;
        };
        let origin = area.min + Vec2::new((i % cols) as f32 * cell.x, (i / cols) as f32 * cell.y);
        let tile = Rect::from_min_size(origin, cell).shrink(2.0);
        let rect = fit(tile, intr.width as f32 / intr.height as f32);
        let image_rect =
            Rect::from_min_max(Pos2::ZERO, Pos2::new(intr.width as f32, intr.height as f32));
        let response = ui.interact(
            rect,
            ui.scope_id().with(("camera tile", i)),
            egui::Sense::click(),
        );
        draw_camera(studio, ui, i, cam, frame, rect, image_rect);
        let painter = ui.painter_at(tile);
        painter.text(
            rect.min + Vec2::splat(4.0),
            egui::Align2::LEFT_TOP,
            cam,
            egui::FontId::proportional(13.0),
            if i == studio.camera {
                Color32::YELLOW
            } else {
                Color32::WHITE
            },
        );
        if response.double_clicked() {
            studio.camera = i;
            studio.frame = frame;
            studio.grid = false;
        } else if response.clicked() {
            studio.camera = i;
            studio.frame = frame;
        }
    }
}

/// The largest rectangle of `aspect` centred in `area`.
fn fit(area: Rect, aspect: f32) -> Rect {
    let size = if area.width() / area.height().max(1.0) > aspect {
        Vec2::new(area.height() * aspect, area.height())
    } else {
        Vec2::new(area.width(), area.width() / aspect)
    };
    Rect::from_center_size(area.center(), size)
}

fn single_ui(studio: &mut Studio, ui: &mut egui::Ui, camera: &str, drive: &Drive) {
    let Some(intr) = studio.current.sensor(camera).and_then(|s| s.camera.clone()) else {
        return;
    };
    let (w, h) = (intr.width as f32, intr.height as f32);
    let readout_height = 18.0;
    let mut area = ui.available_rect_before_wrap();
    area.max.y -= readout_height;
    let rect = fit(area, w / h);
    let response = ui.allocate_rect(rect, egui::Sense::click_and_drag());
    studio.image_rect = Some(rect);
    // Zoom about the cursor with the wheel, pan by dragging, double-click resets.
    let z = &mut studio.zoom;
    if z.center_px[0].is_nan() || response.double_clicked() {
        *z = super::state::ViewZoom {
            center_px: [w / 2.0, h / 2.0],
            zoom: 1.0,
        };
    }
    let to_image = |zoom: &super::state::ViewZoom, pos: Pos2| -> [f32; 2] {
        let view = Vec2::new(w, h) / zoom.zoom;
        let rel = (pos - rect.min) / rect.size();
        [
            zoom.center_px[0] - view.x / 2.0 + rel.x * view.x,
            zoom.center_px[1] - view.y / 2.0 + rel.y * view.y,
        ]
    };
    if let Some(pos) = response.hover_pos() {
        let scroll = ui.input(|i| i.smooth_scroll_delta.y);
        if scroll != 0.0 {
            let before = to_image(z, pos);
            z.zoom = (z.zoom * (scroll * 0.004).exp()).clamp(1.0, 40.0);
            let after = to_image(z, pos);
            z.center_px[0] += before[0] - after[0];
            z.center_px[1] += before[1] - after[1];
        }
    }
    if response.dragged() {
        let d = response.drag_delta() / rect.size() * Vec2::new(w, h) / z.zoom;
        z.center_px[0] -= d.x;
        z.center_px[1] -= d.y;
    }
    let half = Vec2::new(w, h) / z.zoom / 2.0;
    z.center_px[0] = z.center_px[0].clamp(half.x, w - half.x);
    z.center_px[1] = z.center_px[1].clamp(half.y, h - half.y);
    let view = Rect::from_center_size(Pos2::from(z.center_px), half * 2.0);
    let zoom = *z;
    draw_camera(studio, ui, studio.camera, camera, studio.frame, rect, view);
    studio.hover = response.hover_pos().map(|pos| {
        let [u, v] = to_image(&zoom, pos);
        let radius_px = 4.0 * w / rect.width() / zoom.zoom;
        let point = hover_point(studio, camera, drive, [u, v], radius_px.max(1.5));
        HoverReadout { u, v, point }
    });
    let text = match &studio.hover {
        Some(hv) => match &hv.point {
            Some((d, lidar)) => format!(
                "u {:.1}  v {:.1}  ·  depth {d:.2} m ({lidar})  ·  zoom {:.1}×",
                hv.u, hv.v, zoom.zoom
            ),
            None => format!("u {:.1}  v {:.1}  ·  zoom {:.1}×", hv.u, hv.v, zoom.zoom),
        },
        None => format!(
            "zoom {:.1}× · wheel zooms, drag pans, double-click resets",
            zoom.zoom
        ),
    };
    ui.label(text);
}

/// Depth and LiDAR of the nearest visible point within `radius_px` of `uv` (CPU projection,
/// computed on demand and cached with the overlay).
fn hover_point(
    studio: &mut Studio,
    camera: &str,
    drive: &Drive,
    uv: [f32; 2],
    radius_px: f32,
) -> Option<(f32, String)> {
    let lidars: Vec<String> = studio
        .shown_rig()
        .lidars()
        .map(|l| l.name.clone())
        .collect();
    ensure_cpu(studio, studio.camera, camera, drive).ok()?;
    let cache = studio.overlays.get(studio.camera)?;
    let r2 = radius_px * radius_px;
    cache
        .cpu
        .iter()
        .filter(|p| p.visible && p.p.depth_m <= studio.overlay.max_range_m)
        .map(|p| {
            let (dx, dy) = (p.p.pixel[0] - uv[0], p.p.pixel[1] - uv[1]);
            (dx * dx + dy * dy, p)
        })
        .filter(|(d2, _)| *d2 <= r2)
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, p)| {
            (
                p.p.depth_m,
                lidars.get(p.lidar as usize).cloned().unwrap_or_default(),
            )
        })
}

/// Draw one camera's image (the `view` part of it, in image pixels) with its overlay in `rect`.
fn draw_camera(
    studio: &mut Studio,
    ui: &mut egui::Ui,
    index: usize,
    camera: &str,
    frame: usize,
    rect: Rect,
    view: Rect,
) {
    let Some(drive) = studio.drive.clone() else {
        return;
    };
    if let Err(e) = refresh(studio, index, camera, frame, &drive, ui.ctx()) {
        let msg = format!("error: {e}");
        if studio.status.last() != Some(&msg) {
            studio.status.push(msg);
        }
    }
    let rig = studio.shown_rig().clone();
    let Some(intr) = rig.sensor(camera).and_then(|s| s.camera.clone()) else {
        return;
    };
    let (w, h) = (intr.width as f32, intr.height as f32);
    let painter = ui.painter_at(rect);
    let Some(cache) = studio.overlays.get(index) else {
        return;
    };
    if let Some((_, texture)) = &cache.texture {
        let uv = Rect::from_min_max(
            Pos2::new(view.min.x / w, view.min.y / h),
            Pos2::new(view.max.x / w, view.max.y / h),
        );
        painter.image(texture.id(), rect, uv, Color32::WHITE);
    }
    let o = studio.overlay.clone();
    if studio.gpu {
        let ppp = ui.ctx().pixels_per_point();
        let mut u = Uniforms::camera(&intr);
        u.viewport_size_px = [rect.width() * ppp, rect.height() * ppp];
        u.view_min = [view.min.x, view.min.y];
        u.view_size = [view.width(), view.height()];
        u.color_mode = match o.color_by {
            ColorBy::Range => 0,
            ColorBy::Intensity => 1,
            ColorBy::Height => 2,
            ColorBy::Lidar => 3,
        };
        // Splat radius in physical pixels (the CPU path draws squares of side `point_size`).
        u.point_size_px = (o.point_size * 0.6).max(0.75) * ppp;
        u.occlusion_px = if o.occlusion {
            o.occlusion_px * ppp
        } else {
            0.0
        };
        u.opacity = o.opacity;
        u.range_min_m = o.min_range_m;
        u.range_max_m = o.max_range_m;
        u.height_min_m = o.height_range_m[0];
        u.height_max_m = o.height_range_m[1];
        u.intensity_max = cache.intensity_max;
        for (i, l) in rig.lidars().enumerate() {
            u.set_height_row(i, l.vehicle_from_sensor);
        }
        u.rows = cache.gpu_rows.max(1);
        if cache.texture.is_some() && !cache.gpu_points.is_empty() {
            studio.pictures.0 += 1;
            studio.pictures.1 += cache.gpu_points.len();
        }
        painter.add(paint_callback(
            rect,
            OverlayCallback {
                slot: index as u64,
                points_key: cache.gpu_points_key,
                points: cache.gpu_points.clone(),
                transforms: cache.gpu_transforms.clone(),
                uniforms: u,
            },
        ));
        return;
    }
    if ensure_cpu(studio, index, camera, &drive).is_err() {
        return;
    }
    let Some(cache) = studio.overlays.get(index) else {
        return;
    };
    let scale = rect.width() / view.width();
    let half = o.point_size * 0.5;
    let alpha = (o.opacity * 255.0) as u8;
    let mut mesh = egui::Mesh::default();
    for p in cache.cpu.iter().filter(|p| {
        p.visible
            && p.p.depth_m >= o.min_range_m
            && p.p.depth_m <= o.max_range_m
            && view.expand(2.0).contains(Pos2::from(p.p.pixel))
    }) {
        let t = |v: f32, lo: f32, hi: f32| (v - lo) / (hi - lo).max(1e-6);
        let c = match o.color_by {
            ColorBy::Range => colormap(t(p.p.depth_m, o.min_range_m, o.max_range_m)),
            ColorBy::Intensity => colormap(t(p.p.intensity, 0.0, cache.intensity_max)),
            ColorBy::Height => colormap(t(p.height_m, o.height_range_m[0], o.height_range_m[1])),
            ColorBy::Lidar => {
                let [r, g, b] = LIDAR_COLORS[(p.lidar as usize).min(7)];
                Color32::from_rgb(r, g, b)
            }
        };
        let c = Color32::from_rgba_unmultiplied(c.r(), c.g(), c.b(), alpha);
        let center = rect.min
            + Vec2::new(
                (p.p.pixel[0] + 0.5 - view.min.x) * scale,
                (p.p.pixel[1] + 0.5 - view.min.y) * scale,
            );
        mesh.add_colored_rect(Rect::from_center_size(center, Vec2::splat(2.0 * half)), c);
    }
    if !mesh.is_empty() {
        studio.pictures.0 += 1;
        studio.pictures.1 += mesh.vertices.len() / 4;
    }
    painter.add(egui::Shape::mesh(mesh));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rolling_shutters_rows_thin_out_to_bound_the_table() {
        use crate::geometry::RowTimes;
        let rolling = RowTimes::from_millis(-30.0, 10.0);
        assert_eq!(overlay_rows(RowTimes::GLOBAL, 12_200), 1);
        // One sweep of each of two LiDARs (100 buckets each): every row.
        assert_eq!(overlay_rows(rolling, 200), 33);
        // ± 10 sweeps: 4200 buckets, 15 rows; ± 30: 12 200 buckets, 5 rows; odd, at least 3.
        assert_eq!(overlay_rows(rolling, 4_200), 15);
        assert_eq!(overlay_rows(rolling, 12_200), 5);
        assert_eq!(overlay_rows(rolling, 1_000_000), 3);
        for buckets in 1..20_000 {
            let rows = overlay_rows(rolling, buckets);
            assert!(rows % 2 == 1 && (rows * buckets <= MAX_OVERLAY_TRANSFORMS || rows == 3));
        }
    }

    #[test]
    fn an_image_larger_than_the_gpu_allows_is_shrunk_keeping_its_aspect() {
        let img = image::RgbImage::new(10_000, 5_000);
        let small = fit_texture_side(&img, 8192).unwrap();
        assert_eq!((small.width(), small.height()), (8192, 4096));
        assert!(fit_texture_side(&image::RgbImage::new(1920, 1080), 8192).is_none());
    }
}
