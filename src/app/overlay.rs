//! The camera viewport: the image with LiDAR sweeps projected through the current extrinsics.
//!
//! With a wgpu renderer the points are projected on the GPU ([`super::gpu_overlay`]). Otherwise
//! projection runs in the library ([`crate::geometry::projection`]) and is cached until the
//! camera, the frame or the extrinsics change; drawing is egui mesh quads, nearest points drawn
//! last so they cover farther ones.

use std::sync::Arc;

use egui::{Color32, Pos2, Rect, Vec2};

use super::gpu_overlay::{GpuPoint, OverlayCallback, Uniforms, paint_callback, transforms_f32};
use super::state::{ColorBy, ExtrinsicsView, Studio};
use crate::calib::{Rig, SensorKind};
use crate::geometry::Rigid;
use crate::geometry::projection::{
    ProjectedPoint, SweepView, camera_from_lidar_buckets, point_buckets, project_sweep,
};
use crate::log::LidarSweep;

#[derive(Default)]
pub(crate) struct OverlayCache {
    key: Option<(usize, usize, ExtrinsicsView, usize)>,
    rig: Option<Rig>,
    points: Vec<ProjectedPoint>,
    texture: Option<(usize, usize, egui::TextureHandle)>,
    sweeps: Vec<(String, usize, Arc<LidarSweep>)>,
    /// GPU path: points (far to near) with global bucket indices, and the bucket transforms.
    gpu_points: Arc<Vec<GpuPoint>>,
    gpu_points_key: u64,
    gpu_transforms: Vec<[[f32; 4]; 4]>,
    gpu_intensity_max: f32,
}

impl OverlayCache {
    pub(crate) fn state(&self) -> (&[[[f32; 4]; 4]], Vec<[f32; 2]>) {
        (
            &self.gpu_transforms,
            self.points.iter().map(|p| p.pixel).collect(),
        )
    }
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

fn camera_names(studio: &Studio) -> Vec<String> {
    studio
        .current
        .sensors
        .iter()
        .filter(|s| s.kind == SensorKind::Camera && s.camera.is_some())
        .map(|s| s.name.clone())
        .collect()
}

pub(crate) fn viewport_ui(studio: &mut Studio, ui: &mut egui::Ui) {
    if let Some(job) = &studio.demo {
        super::demo::progress_ui(job, ui);
        return;
    }
    let Some(drive) = studio.drive.as_ref() else {
        ui.centered_and_justified(|ui| {
            ui.heading("Open a drive (File ▸ Open log…, or drop an .mcap here)")
        });
        return;
    };
    let cameras = camera_names(studio);
    if cameras.is_empty() {
        ui.label("This drive has no camera with intrinsics.");
        return;
    }
    studio.camera = studio.camera.min(cameras.len() - 1);
    let camera = cameras[studio.camera].clone();
    let n_frames = drive.stream(&camera).map_or(0, |s| s.frames.len());
    ui.horizontal(|ui| {
        egui::ComboBox::from_label("camera")
            .selected_text(&camera)
            .show_ui(ui, |ui| {
                for (i, c) in cameras.iter().enumerate() {
                    ui.selectable_value(&mut studio.camera, i, c);
                }
            });
        if n_frames > 0 {
            ui.add(egui::Slider::new(&mut studio.frame, 0..=n_frames - 1).text("frame"));
        }
        ui.separator();
        ui.selectable_value(&mut studio.view, ExtrinsicsView::Initial, "initial");
        ui.selectable_value(&mut studio.view, ExtrinsicsView::Current, "current");
        if studio.ground_truth.is_some() {
            ui.selectable_value(
                &mut studio.view,
                ExtrinsicsView::GroundTruth,
                "ground truth",
            );
        }
        ui.separator();
        ui.selectable_value(&mut studio.color_by, ColorBy::Range, "range");
        ui.selectable_value(&mut studio.color_by, ColorBy::Intensity, "intensity");
        ui.add(egui::Slider::new(&mut studio.point_size, 0.5..=6.0).text("size"));
        ui.add(egui::Slider::new(&mut studio.max_range_m, 5.0..=200.0).text("max range m"));
    });
    studio.frame = studio.frame.min(n_frames.saturating_sub(1));
    if n_frames == 0 {
        return;
    }
    if let Err(e) = refresh(studio, &camera, ui.ctx()) {
        studio.status.push(format!("error: {e}"));
    }
    let cache = &studio.overlay_cache;
    let Some((_, _, texture)) = &cache.texture else {
        return;
    };
    let Some(intr) = studio
        .current
        .sensor(&camera)
        .and_then(|s| s.camera.clone())
    else {
        return;
    };
    let available = ui.available_size();
    let aspect = intr.width as f32 / intr.height as f32;
    let size = if available.x / available.y > aspect {
        Vec2::new(available.y * aspect, available.y)
    } else {
        Vec2::new(available.x, available.x / aspect)
    };
    let (rect, _response) = ui.allocate_exact_size(size, egui::Sense::hover());
    let painter = ui.painter_at(rect);
    painter.image(
        texture.id(),
        rect,
        Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)),
        Color32::WHITE,
    );
    if studio.gpu {
        let ppp = ui.ctx().pixels_per_point();
        let mut uniforms = Uniforms::camera(&intr);
        uniforms.viewport_size_px = [rect.width() * ppp, rect.height() * ppp];
        uniforms.color_mode = match studio.color_by {
            ColorBy::Range => 0,
            ColorBy::Intensity => 1,
        };
        // Splat radius in physical pixels (the CPU path draws squares of side `point_size`).
        uniforms.point_size_px = (studio.point_size * 0.6).max(0.75) * ppp;
        uniforms.opacity = 1.0;
        uniforms.range_min_m = 0.0;
        uniforms.range_max_m = studio.max_range_m;
        uniforms.intensity_max = cache.gpu_intensity_max;
        painter.add(paint_callback(
            rect,
            OverlayCallback {
                points_key: cache.gpu_points_key,
                points: cache.gpu_points.clone(),
                transforms: cache.gpu_transforms.clone(),
                uniforms,
            },
        ));
        return;
    }
    let scale = rect.width() / intr.width as f32;
    let half = studio.point_size * 0.5;
    let mut mesh = egui::Mesh::default();
    let (lo, hi) = match studio.color_by {
        ColorBy::Range => (0.0, studio.max_range_m),
        ColorBy::Intensity => (
            0.0,
            cache.points.iter().map(|p| p.intensity).fold(1.0, f32::max),
        ),
    };
    // Far points first so near ones cover them.
    let mut order: Vec<&ProjectedPoint> = cache
        .points
        .iter()
        .filter(|p| p.depth_m <= studio.max_range_m)
        .collect();
    order.sort_by(|a, b| b.depth_m.total_cmp(&a.depth_m));
    for p in order {
        let v = match studio.color_by {
            ColorBy::Range => p.depth_m,
            ColorBy::Intensity => p.intensity,
        };
        let c = colormap((v - lo) / (hi - lo).max(1e-6));
        let center = rect.min + Vec2::new((p.pixel[0] + 0.5) * scale, (p.pixel[1] + 0.5) * scale);
        mesh.add_colored_rect(Rect::from_center_size(center, Vec2::splat(2.0 * half)), c);
    }
    painter.add(egui::Shape::mesh(mesh));
}

/// Recompute the texture and projected points when the camera, frame or extrinsics changed.
fn refresh(studio: &mut Studio, camera: &str, ctx: &egui::Context) -> Result<(), String> {
    let Some(drive) = studio.drive.as_ref() else {
        return Ok(());
    };
    let key = (studio.camera, studio.frame, studio.view, studio.stride);
    let rig = studio.shown_rig().clone();
    let gpu = studio.gpu;
    let cache = &mut studio.overlay_cache;
    if cache.key == Some(key) && cache.rig.as_ref() == Some(&rig) {
        return Ok(());
    }
    let stream = drive.stream(camera).ok_or("no such camera")?;
    let image_stamp = stream.frames[studio.frame].stamp_nanos;
    if cache.texture.as_ref().map(|(c, f, _)| (*c, *f)) != Some((studio.camera, studio.frame)) {
        let img = drive
            .load_image(camera, studio.frame)
            .map_err(|e| e.to_string())?;
        let color =
            egui::ColorImage::from_rgb([img.width() as usize, img.height() as usize], img.as_raw());
        let tex = ctx.load_texture(
            format!("{camera}-{}", studio.frame),
            color,
            egui::TextureOptions::LINEAR,
        );
        cache.texture = Some((studio.camera, studio.frame, tex));
    }
    let cam = rig.sensor(camera).ok_or("no such camera")?;
    let intr = cam.camera.clone().ok_or("camera has no intrinsics")?;
    let mut points = Vec::new();
    // GPU path: which sweeps are drawn (their points are uploaded once), and bucket transforms.
    let mut gpu_sweeps: Vec<(Arc<LidarSweep>, Vec<Rigid>)> = Vec::new();
    for lidar in rig.lidars() {
        let Some(ls) = drive.stream(&lidar.name) else {
            continue;
        };
        // The sweep nearest in time to the image.
        let Some((idx, _)) = ls
            .frames
            .iter()
            .enumerate()
            .min_by_key(|(_, f)| (f.stamp_nanos - image_stamp).abs())
        else {
            continue;
        };
        let sweep = match cache
            .sweeps
            .iter()
            .find(|(n, i, _)| *n == lidar.name && *i == idx)
        {
            Some((_, _, s)) => s.clone(),
            None => {
                let s = Arc::new(
                    drive
                        .load_sweep(&lidar.name, idx)
                        .map_err(|e| e.to_string())?,
                );
                cache.sweeps.push((lidar.name.clone(), idx, s.clone()));
                if cache.sweeps.len() > 8 {
                    cache.sweeps.remove(0);
                }
                s
            }
        };
        let view = SweepView {
            points_in_lidar: &sweep.points_in_sensor,
            intensity: &sweep.intensity,
            time_offset_secs: sweep.time_offset_secs.as_deref(),
            stamp_nanos: sweep.stamp_nanos,
        };
        if gpu {
            let t = camera_from_lidar_buckets(
                &view,
                &drive.trajectory,
                lidar.vehicle_from_sensor,
                cam.vehicle_from_sensor,
                image_stamp,
            )
            .map_err(|e| format!("{camera} frame {}: {e}", studio.frame))?;
            gpu_sweeps.push((sweep.clone(), t));
            continue;
        }
        match project_sweep(
            &view,
            &drive.trajectory,
            lidar.vehicle_from_sensor,
            cam.vehicle_from_sensor,
            &intr,
            image_stamp,
            studio.stride,
        ) {
            Ok(p) => points.extend(p),
            Err(e) => return Err(format!("{camera} frame {}: {e}", studio.frame)),
        }
    }
    if gpu {
        upload_gpu_points(cache, &gpu_sweeps, studio.stride);
    }
    cache.points = points;
    cache.key = Some(key);
    cache.rig = Some(rig);
    Ok(())
}

/// Rebuild the GPU point list when the set of sweeps changed; always refresh the transforms.
fn upload_gpu_points(
    cache: &mut OverlayCache,
    sweeps: &[(Arc<LidarSweep>, Vec<Rigid>)],
    stride: usize,
) {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for (s, t) in sweeps {
        (Arc::as_ptr(s) as usize, s.stamp_nanos, t.len()).hash(&mut h);
    }
    stride.hash(&mut h);
    let key = h.finish();
    if key != cache.gpu_points_key || cache.gpu_points.is_empty() {
        let mut pts: Vec<(f32, GpuPoint)> = Vec::new();
        let mut base = 0u32;
        for (s, t) in sweeps {
            let view = SweepView {
                points_in_lidar: &s.points_in_sensor,
                intensity: &s.intensity,
                time_offset_secs: s.time_offset_secs.as_deref(),
                stamp_nanos: s.stamp_nanos,
            };
            let buckets = point_buckets(&view);
            for i in (0..s.points_in_sensor.len()).step_by(stride.max(1)) {
                let p = s.points_in_sensor[i];
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
                        bucket: base + buckets[i],
                    },
                ));
            }
            base += t.len() as u32;
        }
        // Far to near: nearer splats are drawn over farther ones.
        pts.sort_by(|a, b| b.0.total_cmp(&a.0));
        cache.gpu_intensity_max = pts
            .iter()
            .map(|p| p.1.position_intensity[3])
            .fold(1.0, f32::max);
        cache.gpu_points = Arc::new(pts.into_iter().map(|p| p.1).collect());
        cache.gpu_points_key = key;
    }
    let all: Vec<Rigid> = sweeps.iter().flat_map(|(_, t)| t.iter().copied()).collect();
    cache.gpu_transforms = transforms_f32(&all);
}
