//! The overlay's points for each camera: the sweeps around its image's stamp moved into the
//! camera's frame (a firing-time bucket per row band under a rolling shutter), culled to its
//! view cone, and either uploaded as GPU transforms or projected on the CPU with occlusion;
//! recomputed only when the frame, the extrinsics or the settings change.

use super::*;

/// Recompute a camera's texture, sweeps and GPU transforms when its frame or the extrinsics
/// changed.
pub(super) fn refresh(
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
pub(super) const MAX_OVERLAY_TRANSFORMS: usize = 1 << 16;

/// Camera poses per firing-time bucket for `buckets` buckets: one for a shutter without
/// readout, else [`SAMPLED_ROWS`](crate::geometry::SAMPLED_ROWS) or fewer to
/// stay within [`MAX_OVERLAY_TRANSFORMS`], at least 3, always odd (one at the middle row).
pub(super) fn overlay_rows(readout: crate::geometry::RowTimes, buckets: usize) -> usize {
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
pub(super) const CONE_MARGIN_DEG: f64 = 15.0;
pub(super) const RECULL_DEG: f64 = 5.0;

/// Cosine of the half-angle of the cone around the optical axis that holds every pixel's ray
/// plus the margin; -1 (keep everything) for fields of view near or beyond 180°.
pub(super) fn view_cone_cos(intr: &crate::geometry::camera::CameraIntrinsics) -> f64 {
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

pub(super) fn upload_gpu_points(
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

pub(super) fn axis_hash(axes: &[glam::DVec3]) -> u64 {
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
pub(super) fn ensure_cpu(
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
