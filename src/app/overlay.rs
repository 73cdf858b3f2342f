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

/// Recompute a camera's texture, sweeps and GPU transforms when its frame or the extrinsics
/// changed.
fn refresh(
    studio: &mut Studio,
    index: usize,
    camera: &str,
    frame: usize,
    drive: &Drive,
    ctx: &egui::Context,
) -> Result<(), String> {
    if let Some(cache) = studio.overlays.get_mut(index)
        && cache.camera != camera
    {
        *cache = OverlayCache {
            camera: camera.to_string(),
            ..Default::default()
        };
    }
    let key = (
        frame,
        studio.overlay.stride,
        studio.overlay.accumulate,
        studio
            .camera_readout_ms
            .map(|(a, b)| [a.to_bits(), b.to_bits()]),
    );
    let readout = studio.readout();
    // Every frame: compare without cloning the rig.
    let unchanged = studio
        .overlays
        .get(index)
        .is_some_and(|c| c.key == Some(key) && c.rig.as_ref() == Some(studio.shown_rig()));
    if unchanged {
        return Ok(());
    }
    let rig = studio.shown_rig().clone();
    let Some(cache) = studio.overlays.get_mut(index) else {
        return Ok(());
    };
    let stream = drive.stream(camera).ok_or("no such camera")?;
    let image_stamp = stream
        .frames
        .get(frame)
        .ok_or_else(|| format!("{camera} has no frame {frame}"))?
        .stamp_nanos;
    if cache.texture.as_ref().map(|(f, _)| *f) != Some(frame) {
        let img = drive.load_image(camera, frame).map_err(|e| e.to_string())?;
        let smaller = fit_texture_side(&img, ctx.input(|i| i.max_texture_side));
        let img = smaller.as_ref().unwrap_or(&img);
        let color =
            egui::ColorImage::from_rgb([img.width() as usize, img.height() as usize], img.as_raw());
        let tex = ctx.load_texture(
            format!("{camera}-{frame}"),
            color,
            egui::TextureOptions::LINEAR,
        );
        cache.texture = Some((frame, tex));
    }
    let cam = rig.sensor(camera).ok_or("no such camera")?;
    // Which sweeps: per LiDAR the one nearest the image, ± `accumulate`.
    let mut wanted: Vec<(usize, String, usize)> = Vec::new();
    for (li, lidar) in rig.lidars().enumerate() {
        let Some(ls) = drive.stream(&lidar.name) else {
            continue;
        };
        let Some(idx) = nearest_frame(drive, &lidar.name, image_stamp) else {
            continue;
        };
        let k = studio.overlay.accumulate;
        for i in idx.saturating_sub(k)..=(idx + k).min(ls.frames.len() - 1) {
            wanted.push((li, lidar.name.clone(), i));
        }
    }
    let mut sweeps = Vec::with_capacity(wanted.len());
    for (li, name, i) in &wanted {
        // Studio-wide cache: sweeps are shared by every camera.
        let s = studio.sweep_cache.get(drive, name, *i)?;
        sweeps.push((*li, s));
    }
    let Some(cache) = studio.overlays.get_mut(index) else {
        return Ok(());
    };
    let lidars: Vec<_> = rig.lidars().collect();
    let intrinsics = cam.camera.as_ref().ok_or("camera has no intrinsics")?;
    let buckets: usize = sweeps
        .iter()
        .map(|(_, s)| bucket_count(&LidarSweep::view(s)))
        .sum();
    let rows = overlay_rows(readout, buckets);
    let mut transforms = Vec::with_capacity(sweeps.len());
    for (li, s) in &sweeps {
        let view = LidarSweep::view(s);
        let t = match camera_from_lidar_rows(
            &view,
            &drive.trajectory,
            lidars[*li].vehicle_from_sensor,
            cam.vehicle_from_sensor,
            (image_stamp, readout),
            rows,
        ) {
            Ok(t) => t,
            Err(e) => {
                // The image is new: draw no points rather than the last frame's over it.
                cache.gpu_points = Arc::new(Vec::new());
                cache.gpu_transforms.clear();
                cache.cpu.clear();
                cache.cpu_key = None;
                return Err(format!("{camera} frame {frame}: {e}"));
            }
        };
        transforms.push(t);
    }
    cache.sweeps = sweeps;
    let cone_cos = view_cone_cos(intrinsics);
    cache.gpu_rows = rows as u32;
    upload_gpu_points(cache, &transforms, studio.overlay.stride, cone_cos);
    cache.cpu.clear();
    cache.cpu_key = None;
    cache.key = Some(key);
    cache.rig = Some(rig);
    Ok(())
}

/// Transforms one camera's overlay table may hold (4 MiB as f32): the rows of a rolling
/// shutter thin out when many sweeps are accumulated (30 each side of two LiDARs), instead of
/// 26 MB per camera on every refresh.
const MAX_OVERLAY_TRANSFORMS: usize = 1 << 16;

/// Camera poses per firing-time bucket for `buckets` buckets: one for a shutter without
/// readout, else [`SAMPLED_ROWS`](crate::geometry::SAMPLED_ROWS) or fewer to
/// stay within [`MAX_OVERLAY_TRANSFORMS`], at least 3, always odd (one at the middle row).
fn overlay_rows(readout: crate::geometry::RowTimes, buckets: usize) -> usize {
    let rows = shutter_rows(readout);
    if rows == 1 {
        return 1;
    }
    let fit = (MAX_OVERLAY_TRANSFORMS / buckets.max(1)).clamp(3, rows);
    fit - (1 - fit % 2)
}

/// Rebuild the GPU point list when the set of sweeps changed; always refresh the transforms.
/// Extra angle around the camera's field of view kept on the GPU, so edits and optimiser steps
/// of a few degrees re-project without re-uploading points.
const CONE_MARGIN_DEG: f64 = 15.0;
const RECULL_DEG: f64 = 5.0;

/// Cosine of the half-angle of the cone around the optical axis that holds every pixel's ray
/// plus the margin; -1 (keep everything) for fields of view near or beyond 180°.
fn view_cone_cos(intr: &crate::geometry::camera::CameraIntrinsics) -> f64 {
    let (w, h) = (intr.width as f64, intr.height as f64);
    let mut max_angle: f64 = 0.0;
    for (x, y) in [
        (0.0, 0.0),
        (w, 0.0),
        (0.0, h),
        (w, h),
        (w / 2.0, 0.0),
        (0.0, h / 2.0),
    ] {
        match intr.unproject(glam::DVec2::new(x, y)) {
            Some(d) => {
                let z = d.normalize_or_zero().z.clamp(-1.0, 1.0);
                max_angle = max_angle.max(z.acos());
            }
            None => return -1.0,
        }
    }
    let limit = max_angle + (CONE_MARGIN_DEG + RECULL_DEG).to_radians();
    if limit >= std::f64::consts::FRAC_PI_2 * 1.9 {
        -1.0
    } else {
        limit.cos()
    }
}

fn upload_gpu_points(
    cache: &mut OverlayCache,
    transforms: &[Vec<Rigid>],
    stride: usize,
    cone_cos: f64,
) {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for ((li, s), t) in cache.sweeps.iter().zip(transforms) {
        (Arc::as_ptr(s) as usize, *li, s.stamp_nanos, t.len()).hash(&mut h);
    }
    stride.hash(&mut h);
    let key = h.finish();
    // The camera (origin, optical axis) in each sweep's LiDAR frame at its first bucket (the
    // middle row's pose of a rolling shutter).
    let middle = cache.gpu_rows.max(1) as usize / 2;
    let cameras_in_lidar: Vec<(glam::DVec3, glam::DVec3)> = transforms
        .iter()
        .map(|t| {
            let lidar_from_camera = t.get(middle).copied().unwrap_or_default().inverse();
            (
                lidar_from_camera.translation,
                lidar_from_camera.rotation * glam::DVec3::Z,
            )
        })
        .collect();
    let turned = cache.gpu_cone_axes.len() != cameras_in_lidar.len()
        || cache
            .gpu_cone_axes
            .iter()
            .zip(&cameras_in_lidar)
            .any(|(a, (_, b))| a.dot(*b) < RECULL_DEG.to_radians().cos());
    if key != cache.gpu_base_key || cache.gpu_points.is_empty() || turned {
        let mut pts: Vec<(f32, GpuPoint)> = Vec::new();
        let mut base = 0u32;
        for (((li, s), t), (origin, axis)) in
            cache.sweeps.iter().zip(transforms).zip(&cameras_in_lidar)
        {
            let buckets = point_buckets(&LidarSweep::view(s));
            for i in (0..s.points_in_sensor.len()).step_by(stride.max(1)) {
                let p = s.points_in_sensor[i];
                if cone_cos > -1.0 {
                    let d = glam::DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64) - *origin;
                    if d.dot(*axis) < cone_cos * d.length() {
                        continue;
                    }
                }
                let range = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                pts.push((
                    range,
                    GpuPoint {
                        position_intensity: [
                            p[0],
                            p[1],
                            p[2],
                            s.intensity.get(i).copied().unwrap_or(0.0),
                        ],
                        packed: pack_bucket(base + buckets[i], *li as u32),
                    },
                ));
            }
            // Buckets, not transforms: the shader finds a bucket's rows at `bucket * rows`.
            base += (t.len() / cache.gpu_rows.max(1) as usize) as u32;
        }
        // Far to near: nearer splats are drawn over farther ones.
        pts.sort_by(|a, b| b.0.total_cmp(&a.0));
        // Colour scale to the 98th percentile: a few retro-reflectors would wash out the rest.
        let mut sample: Vec<f32> = pts
            .iter()
            .step_by((pts.len() / 4096).max(1))
            .map(|p| p.1.position_intensity[3])
            .collect();
        sample.sort_by(f32::total_cmp);
        cache.intensity_max = sample
            .get(sample.len() * 98 / 100)
            .copied()
            .unwrap_or(1.0)
            .max(1e-3);
        cache.gpu_points = Arc::new(pts.into_iter().map(|p| p.1).collect());
        cache.gpu_cone_axes = cameras_in_lidar.iter().map(|c| c.1).collect();
        // A new key per upload: the GPU keeps buffers by key.
        cache.gpu_base_key = key;
        cache.gpu_points_key = key ^ axis_hash(&cache.gpu_cone_axes);
    }
    let all: Vec<Rigid> = transforms.iter().flatten().copied().collect();
    cache.gpu_transforms = transforms_f32(&all);
}

fn axis_hash(axes: &[glam::DVec3]) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for a in axes {
        a.to_array().map(f64::to_bits).hash(&mut h);
    }
    h.finish()
}

/// For reports: LiDAR points that land inside the shown images, and how many of those
/// survive occlusion (CPU projection of what the GPU draws).
pub(crate) fn points_in_images(studio: &mut Studio) -> (usize, usize) {
    let Some(drive) = studio.drive.clone() else {
        return (0, 0);
    };
    let cameras = camera_names(&studio.current);
    let shown: Vec<usize> = if studio.grid {
        (0..cameras.len()).collect()
    } else {
        vec![studio.camera]
    };
    let (mut inside, mut visible) = (0, 0);
    for i in shown {
        if i < cameras.len() && ensure_cpu(studio, i, &cameras[i], &drive).is_ok() {
            let cpu = &studio.overlays[i].cpu;
            inside += cpu.len();
            visible += cpu.iter().filter(|p| p.visible).count();
        }
    }
    (inside, visible)
}

/// Project the camera's sweeps on the CPU (fallback drawing, hover readout) with occlusion.
fn ensure_cpu(
    studio: &mut Studio,
    index: usize,
    camera: &str,
    drive: &Drive,
) -> Result<(), String> {
    let occlusion = (
        studio.overlay.occlusion,
        studio.overlay.occlusion_px.round() as u32,
    );
    let rig = studio.shown_rig().clone();
    let stride = studio.overlay.stride;
    let readout = studio.readout();
    let Some(cache) = studio.overlays.get_mut(index) else {
        return Ok(());
    };
    if cache.cpu_key == Some(occlusion) {
        return Ok(());
    }
    let Some((frame, _, _, _)) = cache.key else {
        return Ok(());
    };
    let cam = rig.sensor(camera).ok_or("no such camera")?;
    let intr = cam.camera.clone().ok_or("camera has no intrinsics")?;
    let image_stamp = drive
        .stream(camera)
        .and_then(|s| s.frames.get(frame))
        .ok_or("no such frame")?
        .stamp_nanos;
    let lidars: Vec<_> = rig.lidars().collect();
    let mut cpu = Vec::new();
    for (li, s) in &cache.sweeps {
        let lidar = lidars[*li];
        let projected = project_sweep_rolling(
            &LidarSweep::view(s),
            &drive.trajectory,
            lidar.vehicle_from_sensor,
            cam.vehicle_from_sensor,
            &intr,
            (image_stamp, readout),
            stride,
        )
        .map_err(|e| format!("{camera} frame {frame}: {e}"))?;
        let row = lidar.vehicle_from_sensor;
        cpu.extend(projected.into_iter().map(|p| {
            let q = s.points_in_sensor[p.index as usize];
            let z = row
                .transform_point(glam::DVec3::new(q[0] as f64, q[1] as f64, q[2] as f64))
                .z;
            CpuPoint {
                p,
                lidar: *li as u8,
                height_m: z as f32,
                visible: true,
            }
        }));
    }
    cpu.sort_by(|a, b| b.p.depth_m.total_cmp(&a.p.depth_m));
    if occlusion.0 {
        let pts: Vec<ProjectedPoint> = cpu.iter().map(|c| c.p).collect();
        let visible = visible_points(&pts, intr.width, intr.height, occlusion.1, 0.05);
        for (c, v) in cpu.iter_mut().zip(visible) {
            c.visible = v;
        }
    }
    cache.cpu = cpu;
    cache.cpu_key = Some(occlusion);
    Ok(())
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
