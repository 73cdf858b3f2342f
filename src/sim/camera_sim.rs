//! Camera simulation: ray-traced shading of the world through the full camera model.
//!
//! Per pixel: the camera model's ray (cached per camera), the nearest surface (from a rasterised
//! visibility buffer confirmed by an exact intersection, the BVH on silhouettes; `raster`), its band-limited
//! albedo, sun light with a shadow ray plus sky ambient, aerial perspective, then the camera's
//! exposure gain and colour tone, vignetting, gamma and sensor noise. Pixels whose neighbours hit
//! a different primitive are re-rendered with 4 sub-samples (edge-adaptive anti-aliasing),
//! each resolved among the triangles of the visibility-buffer samples around it and, on the
//! pixel's own face, lit as the pixel is.
//!
//! Not every pixel is shaded: anchors on a 2-pixel grid are, and the pixels between them take
//! the anchors' mean when they see the same flat face and the anchors' colours agree (textures
//! are band-limited to two pixels). Shadow rays are saved the same way one level up: anchors
//! between coarse anchors (a 4-pixel grid) that agree on the face and the sun take their answer.

use glam::{DVec2, Vec3};
use image::RgbImage;
use rayon::prelude::*;

use super::noise::{fbm2_in, hash64};
use super::raster::{Candidate, OUTSIDE, Pinhole, VisibilityBuffer};
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
    /// The virtual pinhole camera primary visibility is rasterised in (`None`: trace every ray).
    pinhole: Option<Pinhole>,
    /// Each pixel's sample in that camera's image ([`Pinhole::sample_of`]).
    samples: Vec<u32>,
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
        let pinhole = Pinhole::covering(
            &dirs,
            intr.fx as f32,
            intr.fy as f32,
            intr.cx as f32,
            intr.cy as f32,
        );
        let samples = pinhole.map_or_else(Vec::new, |pin| {
            dirs.par_iter()
                .map(|d| {
                    if *d == Vec3::ZERO {
                        OUTSIDE
                    } else {
                        pin.sample_of(*d)
                    }
                })
                .collect()
        });
        Self {
            width: w,
            height: h,
            dirs,
            pixel_angle: (1.0 / intr.fx.max(1.0)) as f32,
            pinhole,
            samples,
        }
    }

    /// The ray through a sub-pixel position: bilinear between the four table rays around it
    /// (the camera model's rays bend smoothly: exact to second order in the quarter-pixel
    /// offsets), the camera model itself at the border or beside an invalid ray.
    fn dir(&self, intr: &CameraIntrinsics, x: f32, y: f32) -> Vec3 {
        let (w, h) = (self.width as usize, self.height as usize);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        if x0 >= 0.0 && y0 >= 0.0 && (x0 as usize) + 1 < w && (y0 as usize) + 1 < h {
            let k = y0 as usize * w + x0 as usize;
            let (a, b, c, d) = (
                self.dirs[k],
                self.dirs[k + 1],
                self.dirs[k + w],
                self.dirs[k + w + 1],
            );
            if a != Vec3::ZERO && b != Vec3::ZERO && c != Vec3::ZERO && d != Vec3::ZERO {
                let top = a + (b - a) * fx;
                let bottom = c + (d - c) * fx;
                return (top + (bottom - top) * fy).normalize_or_zero();
            }
        }
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

super::wide::dispatch_wide! {
    /// The sky's colour along `dir`, compiled for the CPU's widest vectors (`sim::wide`).
    fn sky(dir: Vec3, sun: Vec3, seed: u64) -> Vec3 => sky_in
}

#[inline(always)]
fn sky_in<const WIDE: bool>(dir: Vec3, sun: Vec3, seed: u64) -> Vec3 {
    let up = dir.z.max(0.0);
    let horizon = Vec3::new(0.78, 0.84, 0.92);
    let zenith = Vec3::new(0.32, 0.52, 0.86);
    let mut c = horizon + (zenith - horizon) * up.powf(0.6);
    // Clouds: fBm on the direction projected onto a plane.
    if dir.z > 0.02 {
        let (u, v) = (dir.x / dir.z, dir.y / dir.z);
        let cloud = ((fbm2_in::<WIDE>(u, v, 0.6, 5, 0.001, seed ^ 77) - 0.5) * 3.0).clamp(0.0, 1.0);
        c = c + (Vec3::splat(0.95) - c) * cloud * 0.8;
    }
    let glow = dir.dot(sun).max(0.0).powf(64.0);
    c + Vec3::new(1.0, 0.95, 0.8) * glow * 0.6
}

/// Primitive ids beside the world's triangles: nothing hit within range, and an invalid pixel.
const SKY: u32 = u32::MAX - 1;
const INVALID: u32 = u32::MAX - 2;
/// Rays end here (then only aerial perspective and the sky remain).
const SKY_DISTANCE_M: f32 = 600.0;
/// Anchors may be interpolated between when their colours spread by at most this share of the
/// brightest plus this absolute amount (linear radiance): flat shading and textures band-limited
/// beyond two pixels; every visible texture edge, shadow edge and silhouette is shaded exactly.
const SMOOTH_RELATIVE: f32 = 0.04;
const SMOOTH_ABSOLUTE: f32 = 0.004;

/// Coarse anchors answer the sun question for the anchors between them only when they are at
/// most this far apart on the surface (m): a pole's shadow is wider.
const COARSE_SUN_SPACING_M: f32 = 0.25;

/// Whether the sun reached a shaded sample: its neighbours' answer lets an in-between pixel on
/// the same face skip its shadow ray.
const SHADOW: u8 = 0;
const LIT: u8 = 1;
const NO_SUN: u8 = 2;

/// The pixel's size on the surface it hit (m), for band-limiting textures.
fn footprint(hit: &crate::sim::world::SurfaceHit, dir: Vec3, pixel_angle: f32) -> f32 {
    let cos_view = (-dir.dot(hit.normal)).abs().max(0.15);
    hit.t * pixel_angle / cos_view
}

/// The sun's answer for the anchor at (x, y) from the coarse anchors around it (a 4-pixel grid,
/// `cw` of them a row): whether it is lit, when they all see `face` and agree; `None` otherwise
/// or at the image's edge.
fn coarse_sun(
    coarse: &[(Vec3, u32, u8)],
    cw: usize,
    (w, h): (usize, usize),
    (x, y): (usize, usize),
    face: u32,
) -> Option<bool> {
    let xs: &[usize] = if x % 4 == 0 { &[x] } else { &[x - 2, x + 2] };
    let ys: &[usize] = if y % 4 == 0 { &[y] } else { &[y - 2, y + 2] };
    if xs.iter().any(|&ax| ax >= w) || ys.iter().any(|&ay| ay >= h) {
        return None;
    }
    let at = |ax: usize, ay: usize| coarse[(ay / 4) * cw + ax / 4];
    let first = at(xs[0], ys[0]).2;
    let agree = ys.iter().all(|&ay| {
        xs.iter()
            .all(|&ax| at(ax, ay).1 == face && at(ax, ay).2 == first)
    });
    (agree && first != NO_SUN).then_some(first == LIT)
}

/// Linear radiance of what a ray hit (the sky when nothing), its primitive and whether the sun
/// reaches it. `sun_hint` answers the shadow question without a shadow ray (from neighbours on
/// the same face that agree).
fn shade_hit(
    world: &World,
    dir: Vec3,
    hit: Option<crate::sim::world::SurfaceHit>,
    pixel_angle: f32,
    sun_hint: Option<bool>,
) -> (Vec3, u32, u8) {
    let sun = world.sun_dir;
    let Some(hit) = hit else {
        return (sky(dir, sun, world.seed), SKY, NO_SUN);
    };
    let surf = world.surface(&hit, footprint(&hit, dir, pixel_angle));
    let n = hit.normal;
    let n_dot_l = n.dot(sun).max(0.0);
    let sunlit = n_dot_l > 0.0
        && sun_hint.unwrap_or_else(|| !world.occluded(hit.point + n * 0.02, sun, 500.0));
    let lit = if sunlit { n_dot_l } else { 0.0 };
    let sun_color = Vec3::new(1.0, 0.96, 0.88) * 2.2;
    let ambient = Vec3::new(0.55, 0.62, 0.75) * (0.55 + 0.45 * n.z.max(-0.5));
    let color = surf.albedo * (ambient + sun_color * lit);
    // Aerial perspective.
    let fog = 1.0 - (-hit.t / 700.0).exp();
    let horizon = Vec3::new(0.78, 0.84, 0.92);
    (
        color + (horizon - color) * fog,
        hit.primitive,
        if sunlit { LIT } else { SHADOW },
    )
}

/// Approximately standard-normal noise for the three channels of a pixel: each the sum of four
/// 10-bit uniforms from two hashes (Irwin–Hall, scaled to unit variance), far cheaper than
/// Box–Muller's log and cosine per channel.
#[inline(always)]
fn gaussian3(x: u32, y: u32, seed: u64) -> [f32; 3] {
    let h1 = hash64(seed ^ (x as u64) ^ ((y as u64) << 21));
    let h2 = hash64(h1);
    let bits = [
        h1 & 0xFF_FFFF_FFFF,
        h1 >> 40 | (h2 & 0xFFFF) << 24,
        h2 >> 24,
    ];
    bits.map(|b| {
        let sum: u64 = (0..4).map(|k| (b >> (10 * k)) & 0x3FF).sum();
        // Each uniform is (v + 0.5) / 1024: mean 2 and variance 4/12 for the sum.
        ((sum as f32 + 2.0) / 1024.0 - 2.0) * 3f32.sqrt()
    })
}

/// `v^(1/2.2)` on [0, 1] by a table over `sqrt(v)`, where the curve (`s^(2/2.2)`) is nearly
/// straight and linear interpolation is exact to a hundredth of a grey level.
struct Gamma {
    /// A fixed-size array, so that the lookup's index needs no bounds check and a row of
    /// lookups vectorises (gathers).
    table: Box<[f32; Gamma::N + 2]>,
}

impl Gamma {
    const N: usize = 1024;
    fn new() -> Self {
        let mut table = Box::new([0.0; Self::N + 2]);
        for (i, t) in table.iter_mut().enumerate() {
            *t = (i as f32 / Self::N as f32).powf(2.0 / 2.2);
        }
        Self { table }
    }
    #[cfg(test)]
    fn apply(&self, v: f32) -> f32 {
        self.lookup(Self::argument(v))
    }
    /// The table position of `v`: `sqrt(v)` on [0, 1] in table steps (apart from the lookup,
    /// so a row of them vectorises).
    #[inline]
    fn argument(v: f32) -> f32 {
        v.clamp(0.0, 1.0).sqrt() * Self::N as f32
    }
    #[inline(always)]
    fn lookup(&self, s: f32) -> f32 {
        // `s` is in [0, N] (`argument`): the bound only tells the compiler so.
        let i = (s as usize).min(Self::N);
        let f = s - i as f32;
        self.table[i] + (self.table[i + 1] - self.table[i]) * f
    }
}

/// Per-image working buffers (anchors, radiance and primitive per pixel: ≈ 40 MB at 1920×1080),
/// kept for the next image: fresh allocations of that size cost more in page faults than the
/// tone pass.
#[derive(Default)]
struct Scratch {
    anchors: Vec<(Vec3, u32, u8)>,
    radiance: Vec<Vec3>,
    prim: Vec<u32>,
    /// Whether the sun reached each pixel's sample (`NO_SUN` also when unknown).
    sun: Vec<u8>,
}

/// Buffers of finished images; at most as many as images rendered at once (a rig's cameras
/// render together: buffers beyond the pool's cap would be fresh, page-faulting allocations).
static SCRATCH_POOL: std::sync::Mutex<Vec<Scratch>> = std::sync::Mutex::new(Vec::new());

impl Scratch {
    fn take() -> Self {
        SCRATCH_POOL
            .lock()
            .ok()
            .and_then(|mut pool| pool.pop())
            .unwrap_or_default()
    }

    fn give_back(self) {
        if let Ok(mut pool) = SCRATCH_POOL.lock()
            && pool.len() < 8
        {
            pool.push(self);
        }
    }
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
    let visibility = rays
        .pinhole
        .map(|pin| VisibilityBuffer::render(&world.bvh.triangles, pin, origin, rot.inverse()));
    // The rasterised candidate for pixel k's own ray (its sample looked up once per camera).
    let candidate_at = |k: usize| {
        visibility
            .as_ref()
            .map_or(Candidate::Trace, |v| v.candidate_at(rays.samples[k]))
    };
    let shade = |k: usize| {
        let d = rays.dirs[k];
        if d == Vec3::ZERO {
            return (Vec3::ZERO, INVALID, NO_SUN);
        }
        let hit = world.trace_with(origin, rot * d, SKY_DISTANCE_M, candidate_at(k));
        shade_hit(world, rot * d, hit, rays.pixel_angle, None)
    };
    // Pass 1: shade the anchors, every other pixel of every other row. The coarse anchors
    // (every fourth pixel of every fourth row) first, each with its shadow ray; then the others,
    // which skip theirs when the coarse anchors around them see the same face, agree on the
    // sun and lie close together on it (a shadow thinner than their spacing could hide between).
    let cw = w.div_ceil(4);
    let coarse: Vec<(Vec3, u32, u8)> = (0..cw * h.div_ceil(4))
        .into_par_iter()
        .map(|i| shade((i / cw) * 4 * w + (i % cw) * 4))
        .collect();
    // Anchors are the even pixels of even rows: `aw` of them a row.
    let aw = w.div_ceil(2);
    let mut scratch = Scratch::take();
    let Scratch {
        anchors,
        radiance: radiance_buf,
        prim,
        sun,
    } = &mut scratch;
    // Every slot of the three buffers is written below before it is read.
    anchors.resize(aw * h.div_ceil(2), (Vec3::ZERO, INVALID, NO_SUN));
    radiance_buf.resize(w * h, Vec3::ZERO);
    prim.resize(w * h, INVALID);
    sun.resize(w * h, NO_SUN);
    anchors
        .par_chunks_mut(aw)
        .enumerate()
        .for_each(|(ay, row)| {
            let y = 2 * ay;
            for (ax, slot) in row.iter_mut().enumerate() {
                let x = 2 * ax;
                *slot = if x % 4 == 0 && y % 4 == 0 {
                    coarse[(y / 4) * cw + x / 4]
                } else {
                    let d = rays.dirs[y * w + x];
                    if d == Vec3::ZERO {
                        (Vec3::ZERO, INVALID, NO_SUN)
                    } else {
                        let dir = rot * d;
                        let hit =
                            world.trace_with(origin, dir, SKY_DISTANCE_M, candidate_at(y * w + x));
                        let hint = hit.and_then(|hit| {
                            let spacing = 4.0 * footprint(&hit, dir, rays.pixel_angle);
                            (spacing <= COARSE_SUN_SPACING_M)
                                .then(|| coarse_sun(&coarse, cw, (w, h), (x, y), hit.primitive))
                                .flatten()
                        });
                        shade_hit(world, dir, hit, rays.pixel_angle, hint)
                    }
                };
            }
        });
    let anchor = |x: usize, y: usize| anchors[(y / 2) * aw + x / 2];
    // Pass 2: every other pixel is interpolated from its two or four anchors when they see the
    // same primitive as the pixel's own ray and agree in colour; otherwise it is shaded, without
    // a shadow ray when those anchors agree on the sun.
    radiance_buf
        .par_chunks_mut(w)
        .zip(prim.par_chunks_mut(w))
        .zip(sun.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, ((row, prow), srow))| {
            for x in 0..w {
                let k = y * w + x;
                if x % 2 == 0 && y % 2 == 0 {
                    (row[x], prow[x], srow[x]) = anchor(x, y);
                    continue;
                }
                let d = rays.dirs[k];
                let xs: &[usize] = if x % 2 == 0 { &[x] } else { &[x - 1, x + 1] };
                let ys: &[usize] = if y % 2 == 0 { &[y] } else { &[y - 1, y + 1] };
                if d == Vec3::ZERO || xs.iter().any(|&ax| ax >= w) || ys.iter().any(|&ay| ay >= h) {
                    (row[x], prow[x], srow[x]) = shade(k);
                    continue;
                }
                let (mut lo, mut hi, mut sum) = (Vec3::MAX, Vec3::MIN, Vec3::ZERO);
                let (_, face, first_sun) = anchor(xs[0], ys[0]);
                let (mut anchors_agree, mut same_sun) = (true, true);
                for &ay in ys {
                    for &ax in xs {
                        let (c, a_face, a_sun) = anchor(ax, ay);
                        anchors_agree &= a_face == face;
                        same_sun &= a_sun == first_sun;
                        (lo, hi, sum) = (lo.min(c), hi.max(c), sum + c);
                    }
                }
                let n = (xs.len() * ys.len()) as f32;
                let smooth =
                    (hi - lo).max_element() <= SMOOTH_RELATIVE * hi.max_element() + SMOOTH_ABSOLUTE;
                // The rasterised candidate names the face without an exact intersection: when it
                // is the anchors' face, the pixel sees it too.
                let cand = candidate_at(k);
                if anchors_agree
                    && smooth
                    && let Candidate::Triangle(id) = cand
                    && world.bvh.triangles[id as usize].face == face
                {
                    (row[x], prow[x]) = (sum / n, face);
                    srow[x] = if same_sun { first_sun } else { NO_SUN };
                    continue;
                }
                let dir = rot * d;
                let hit = world.trace_with(origin, dir, SKY_DISTANCE_M, cand);
                let own = hit.map_or(SKY, |h| h.primitive);
                let same_face = anchors_agree && face == own;
                if same_face && smooth {
                    (row[x], prow[x]) = (sum / n, own);
                    srow[x] = if same_sun { first_sun } else { NO_SUN };
                } else {
                    let hint =
                        (same_face && same_sun && first_sun != NO_SUN).then_some(first_sun == LIT);
                    (row[x], prow[x], srow[x]) = shade_hit(world, dir, hit, rays.pixel_angle, hint);
                }
            }
        });
    // Pass 3: 4 sub-samples where a neighbour hit another primitive, each shaded at half the
    // pixel's footprint (reusing the pixel's own colour for sub-samples on its face moves the
    // LiDAR-silhouette-to-edge measure of tests/sim_acceptance.rs from 0.97 to 1.01 px).
    // Then exposure, tone, vignetting, noise and gamma, row by row.
    let edge_sample = |x: usize, y: usize| -> Option<Vec3> {
        let k = y * w + x;
        let p = prim[k];
        let edge = (x + 1 < w && prim[k + 1] != p)
            || (y + 1 < h && prim[k + w] != p)
            || (x > 0 && prim[k - 1] != p)
            || (y > 0 && prim[k - w] != p);
        if !edge || p == INVALID {
            return None;
        }
        let mut sum = Vec3::ZERO;
        for (dx, dy) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)] {
            let d = rays.dir(intr, x as f32 + dx, y as f32 + dy);
            if d == Vec3::ZERO {
                continue;
            }
            let dir = rot * d;
            let hit = match visibility.as_ref().and_then(|v| v.neighbourhood(d)) {
                Some(ids) => world.trace_among(origin, dir, SKY_DISTANCE_M, ids),
                None => world.trace(origin, dir, SKY_DISTANCE_M),
            };
            // On the pixel's own face the sun's answer is the pixel's (a shadow edge moves by
            // at most the sub-sample's quarter-pixel offset).
            let hint = hit
                .filter(|h| h.primitive == p && sun[k] != NO_SUN)
                .map(|_| sun[k] == LIT);
            sum += shade_hit(world, dir, hit, rays.pixel_angle * 0.5, hint).0;
        }
        Some(sum * 0.25)
    };
    let (cx, cy) = (intr.cx as f32, intr.cy as f32);
    // (2 r / diagonal)², so the vignette needs no square root.
    let inv_diag2 = 4.0 / (w * w + h * h) as f32;
    let tint = Vec3::from_array(exposure.tint);
    let gamma = Gamma::new();
    let mut img = RgbImage::new(w as u32, h as u32);
    img.par_chunks_mut(3 * w)
        .enumerate()
        .for_each_init(Vec::new, |tone, (y, row)| {
            // Linear values of the row's channels, then the shoulder and the square root of
            // the gamma table's argument over the whole row at once (vectorised: a division and
            // a square root each), then table, noise and quantisation per channel.
            tone.clear();
            for x in 0..w {
                let r2 =
                    (((x as f32 - cx).powi(2) + (y as f32 - cy).powi(2)) * inv_diag2).min(2.25);
                let vignette = 1.0 - 0.25 * r2;
                let radiance = edge_sample(x, y).unwrap_or(radiance_buf[y * w + x]);
                let c = radiance * exposure.gain * tint * vignette * 0.8;
                tone.extend_from_slice(&c.to_array());
            }
            for v in tone.iter_mut() {
                // Filmic-ish shoulder.
                *v = Gamma::argument(*v / (1.0 + 0.15 * *v));
            }
            finish_row(&gamma, tone, row, y as u32, &exposure);
        });
    scratch.give_back();
    img
}

super::wide::dispatch_wide! {
    /// Gamma table, sensor noise and quantisation of one row: `tone` holds the table arguments,
    /// three per pixel. Compiled for the CPU's widest vectors (`sim::wide`), where a row's noise
    /// hashes and table lookups run several pixels at once; the bytes are the same.
    fn finish_row(gamma: &Gamma, tone: &[f32], row: &mut [u8], y: u32, exposure: &Exposure) -> () => finish_row_in
}

/// The row's body; the same code at every level (`WIDE` is only the dispatch's parameter).
#[inline(always)]
fn finish_row_in<const WIDE: bool>(
    gamma: &Gamma,
    tone: &[f32],
    row: &mut [u8],
    y: u32,
    exposure: &Exposure,
) {
    for (x, (px, s)) in row
        .chunks_exact_mut(3)
        .zip(tone.chunks_exact(3))
        .enumerate()
    {
        let noise = gaussian3(x as u32, y, exposure.seed);
        for ch in 0..3 {
            let v = gamma.lookup(s[ch]) * 255.0 + exposure.noise_sigma * noise[ch];
            px[ch] = v.clamp(0.0, 255.0) as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_table_matches_powf() {
        let g = Gamma::new();
        for i in 0..=10_000 {
            let v = i as f32 / 10_000.0;
            let exact = v.powf(1.0 / 2.2) * 255.0;
            assert!((g.apply(v) * 255.0 - exact).abs() < 0.05, "{v}");
        }
        assert_eq!(g.apply(3.0), g.apply(1.0));
        assert_eq!(g.apply(-1.0), 0.0);
    }

    #[test]
    fn pixel_noise_has_unit_variance_and_no_bias() {
        let n = 200_000;
        let samples: Vec<f32> = (0..n / 3)
            .flat_map(|k| gaussian3(k % 640, k / 640, 9))
            .collect();
        let n = samples.len();
        let mean = samples.iter().sum::<f32>() / n as f32;
        let var = samples.iter().map(|s| (s - mean).powi(2)).sum::<f32>() / n as f32;
        assert!(mean.abs() < 0.01, "{mean}");
        assert!((var - 1.0).abs() < 0.02, "{var}");
    }
}
