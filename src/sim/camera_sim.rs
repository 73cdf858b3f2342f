//! Camera simulation: ray-traced shading of the world through the full camera model.
//!
//! Per pixel: the camera model's ray (cached per camera), the nearest surface, its band-limited
//! albedo, sun light with a shadow ray plus sky ambient, aerial perspective, then the camera's
//! exposure gain and colour tone, vignetting, gamma and sensor noise. Pixels whose neighbours hit
//! a different primitive are re-rendered with 4 sub-samples (edge-adaptive anti-aliasing).

use glam::{DVec2, Vec3};
use image::RgbImage;
use rayon::prelude::*;

use super::noise::{fbm2, hash3};
use super::world::World;
use crate::geometry::Rigid;
use crate::geometry::camera::CameraIntrinsics;

/// Unit ray directions in the camera frame for a pixel grid, computed once per camera.
#[derive(Clone, Debug)]
pub struct RayTable {
    pub width: u32,
    pub height: u32,
    dirs: Vec<Vec3>,
    /// Approximate angular size of a pixel (rad).
    pub pixel_angle: f32,
}

impl RayTable {
    pub fn new(intr: &CameraIntrinsics) -> Self {
        let (w, h) = (intr.width, intr.height);
        let dirs: Vec<Vec3> = (0..w as usize * h as usize)
            .into_par_iter()
            .map(|k| {
                let (x, y) = ((k % w as usize) as f64, (k / w as usize) as f64);
                intr.unproject(DVec2::new(x, y))
                    .map_or(Vec3::ZERO, |d| d.as_vec3())
            })
            .collect();
        Self {
            width: w,
            height: h,
            dirs,
            pixel_angle: (1.0 / intr.fx.max(1.0)) as f32,
        }
    }

    fn dir(&self, intr: &CameraIntrinsics, x: f32, y: f32) -> Vec3 {
        intr.unproject(DVec2::new(x as f64, y as f64))
            .map_or(Vec3::ZERO, |d| d.as_vec3())
    }
}

/// How the camera turns light into pixels.
#[derive(Clone, Copy, Debug)]
pub struct Exposure {
    pub gain: f32,
    pub tint: [f32; 3],
    pub noise_sigma: f32,
    pub seed: u64,
}

fn sky(dir: Vec3, sun: Vec3, seed: u64) -> Vec3 {
    let up = dir.z.max(0.0);
    let horizon = Vec3::new(0.78, 0.84, 0.92);
    let zenith = Vec3::new(0.32, 0.52, 0.86);
    let mut c = horizon + (zenith - horizon) * up.powf(0.6);
    // Clouds: fBm on the direction projected onto a plane.
    if dir.z > 0.02 {
        let (u, v) = (dir.x / dir.z, dir.y / dir.z);
        let cloud = ((fbm2(u, v, 0.6, 5, 0.001, seed ^ 77) - 0.5) * 3.0).clamp(0.0, 1.0);
        c = c + (Vec3::splat(0.95) - c) * cloud * 0.8;
    }
    let glow = dir.dot(sun).max(0.0).powf(64.0);
    c + Vec3::new(1.0, 0.95, 0.8) * glow * 0.6
}

/// Linear radiance along one ray and the primitive it hit.
fn radiance(world: &World, origin: Vec3, dir: Vec3, pixel_angle: f32) -> (Vec3, u32) {
    let sun = world.sun_dir;
    let Some(hit) = world.trace(origin, dir, 600.0) else {
        return (sky(dir, sun, world.seed), u32::MAX - 1);
    };
    let cos_view = (-dir.dot(hit.normal)).abs().max(0.15);
    let footprint = hit.t * pixel_angle / cos_view;
    let surf = world.surface(&hit, footprint);
    let n = hit.normal;
    let n_dot_l = n.dot(sun).max(0.0);
    let lit = if n_dot_l > 0.0 && !world.occluded(hit.point + n * 0.02, sun, 500.0) {
        n_dot_l
    } else {
        0.0
    };
    let sun_color = Vec3::new(1.0, 0.96, 0.88) * 2.2;
    let ambient = Vec3::new(0.55, 0.62, 0.75) * (0.55 + 0.45 * n.z.max(-0.5));
    let color = surf.albedo * (ambient + sun_color * lit);
    // Aerial perspective.
    let fog = 1.0 - (-hit.t / 700.0).exp();
    let horizon = Vec3::new(0.78, 0.84, 0.92);
    (color + (horizon - color) * fog, hit.primitive)
}

fn gaussian(x: u32, y: u32, c: u32, seed: u64) -> f32 {
    let u1 = hash3(x as i32, y as i32, c as i32, seed).max(1e-7);
    let u2 = hash3(x as i32, y as i32, c as i32 + 3, seed ^ 0xA5A5);
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

/// Render one image of `world` seen by a camera at `world_from_camera`.
pub fn render(
    world: &World,
    rays: &RayTable,
    intr: &CameraIntrinsics,
    world_from_camera: Rigid,
    exposure: Exposure,
) -> RgbImage {
    let (w, h) = (rays.width as usize, rays.height as usize);
    let rot = world_from_camera.rotation.as_quat();
    let origin = world_from_camera.translation.as_vec3();
    // Pass 1: one sample per pixel.
    let mut radiance_buf = vec![Vec3::ZERO; w * h];
    let mut prim = vec![0u32; w * h];
    radiance_buf
        .par_chunks_mut(w)
        .zip(prim.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (row, prow))| {
            for x in 0..w {
                let d = rays.dirs[y * w + x];
                if d == Vec3::ZERO {
                    continue;
                }
                let (c, p) = radiance(world, origin, rot * d, rays.pixel_angle);
                row[x] = c;
                prow[x] = p;
            }
        });
    // Pass 2: 4 sub-samples where a neighbour hit another primitive.
    let refined: Vec<(usize, Vec3)> = (0..w * h)
        .into_par_iter()
        .with_min_len(4096)
        .filter_map(|k| {
            let (x, y) = (k % w, k / w);
            let p = prim[k];
            let edge = (x + 1 < w && prim[k + 1] != p)
                || (y + 1 < h && prim[k + w] != p)
                || (x > 0 && prim[k - 1] != p)
                || (y > 0 && prim[k - w] != p);
            if !edge {
                return None;
            }
            let mut sum = Vec3::ZERO;
            for (dx, dy) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)] {
                let d = rays.dir(intr, x as f32 + dx, y as f32 + dy);
                if d != Vec3::ZERO {
                    sum += radiance(world, origin, rot * d, rays.pixel_angle * 0.5).0;
                }
            }
            Some((k, sum * 0.25))
        })
        .collect();
    for (k, c) in refined {
        radiance_buf[k] = c;
    }
    // Exposure, tone, vignetting, noise, gamma.
    let (cx, cy) = (intr.cx as f32, intr.cy as f32);
    let diag = ((w * w + h * h) as f32).sqrt() * 0.5;
    let tint = Vec3::from_array(exposure.tint);
    let mut img = RgbImage::new(w as u32, h as u32);
    img.par_chunks_mut(3 * w).enumerate().for_each(|(y, row)| {
        for x in 0..w {
            let r = (((x as f32 - cx).powi(2) + (y as f32 - cy).powi(2)).sqrt() / diag).min(1.5);
            let vignette = 1.0 - 0.25 * r * r;
            let c = radiance_buf[y * w + x] * exposure.gain * tint * vignette * 0.8;
            for ch in 0..3 {
                // Filmic-ish shoulder, then gamma.
                let v = c[ch] / (1.0 + 0.15 * c[ch]);
                let v = v.max(0.0).powf(1.0 / 2.2) * 255.0
                    + exposure.noise_sigma * gaussian(x as u32, y as u32, ch as u32, exposure.seed);
                row[3 * x + ch] = v.clamp(0.0, 255.0) as u8;
            }
        }
    });
    img
}
