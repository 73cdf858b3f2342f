//! Image correspondences for the surface alignment term (method.md §9, §15.6), computed once
//! before the optimisation starts.
//!
//! Candidate pairs are two training frames of different cameras taken within 0.3 s of each
//! other, or of one camera within 2 s, whose views overlap under the starting calibration: of a
//! grid of pixels of the first, pushed out to 8 and 20 m and projected into the second, at least
//! 10 % land inside its image. Each pair's keypoints (oriented FAST + steered BRIEF, detected at
//! up to 960 px wide and scaled to the training resolution) are matched by mutual nearest
//! neighbours with a 0.8 ratio test and verified by RANSAC on the essential matrix (1.5 training
//! pixels); pairs with fewer than 12 inliers are dropped. Pairs are processed in parallel.
//!
//! [`build_cached`] keeps the result on disk, named by a hash of everything it depends on
//! (every frame's stamp, keypoints and intrinsics, the starting extrinsics, the vehicle poses
//! at the frames' stamps, and a version of this code's settings), so a second run on the same
//! data and start matches nothing again. The cache is best effort: a missing, unreadable or
//! inconsistent file is rebuilt, and a failed write only costs the next run the matching.

use std::hash::Hasher;
use std::path::Path;

use glam::{DVec2, DVec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::depth_calib::CameraData;
use crate::features::epipolar::verify;
use crate::features::matching::match_mutual;
use crate::features::orb::Keypoint;
use crate::geometry::camera::rescale_pixel;
use crate::geometry::{Rigid, Trajectory};

/// Frames of different cameras at most this far apart in time form pairs.
const CROSS_CAMERA_SECS: f64 = 0.3;
/// Frames of one camera at most this far apart form pairs.
const SAME_CAMERA_SECS: f64 = 2.0;
const MIN_OVERLAP: f64 = 0.1;
const MIN_INLIERS: usize = 12;

/// Keypoints of a camera image for correspondences and heat maps: detected at up to 960 px
/// wide (the training images are too small for 2048 of them), positions scaled to an image
/// `training_width` pixels wide.
pub fn training_keypoints(img: &image::RgbImage, training_width: u32) -> Vec<Keypoint> {
    let (w, h) = img.dimensions();
    let scale = (960.0 / w.max(1) as f64).min(1.0);
    let (dw, dh) = (
        ((w as f64 * scale).round() as u32).max(1),
        ((h as f64 * scale).round() as u32).max(1),
    );
    let detect_on = if scale < 1.0 {
        image::imageops::resize(img, dw, dh, image::imageops::FilterType::Triangle)
    } else {
        img.clone()
    };
    let gray = crate::features::grey::grey_u8(&detect_on);
    let to_training = training_width as f64 / dw as f64;
    crate::features::orb::detect(&gray, dw as usize, dh as usize, 2048)
        .into_iter()
        .map(|k| Keypoint {
            x: rescale_pixel(k.x as f64, to_training) as f32,
            y: rescale_pixel(k.y as f64, to_training) as f32,
            ..k
        })
        .collect()
}

/// Matched pixels (training resolution) of frame `a` and frame `b`, each `(camera, frame)`.
#[derive(Clone, Debug, PartialEq)]
pub struct MatchedPair {
    pub a: (usize, usize),
    pub b: (usize, usize),
    pub pixels: Vec<(DVec2, DVec2)>,
}

/// All verified pairs, and for each camera the pairs it takes part in.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Correspondences {
    pub pairs: Vec<MatchedPair>,
    pub by_camera: Vec<Vec<usize>>,
    /// Candidate pairs examined (overlapping views).
    pub candidates: usize,
}

impl Correspondences {
    /// `pairs` of `cameras` cameras, indexed by camera.
    fn new(pairs: Vec<MatchedPair>, cameras: usize, candidates: usize) -> Self {
        let mut by_camera = vec![Vec::new(); cameras];
        for (k, p) in pairs.iter().enumerate() {
            by_camera[p.a.0].push(k);
            if p.b.0 != p.a.0 {
                by_camera[p.b.0].push(k);
            }
        }
        Self {
            pairs,
            by_camera,
            candidates,
        }
    }

    pub fn matches(&self) -> usize {
        self.pairs.iter().map(|p| p.pixels.len()).sum()
    }
}

/// Changes whenever the matching's settings or the file layout change (old files are then
/// simply not found).
const CACHE_VERSION: &str = "rigcal-matches-2: 0.3 s, 2 s, 10 %, 12 inliers, 1.5 px, ratio 0.8";

/// The on-disk form of [`Correspondences`].
#[derive(Serialize, Deserialize)]
struct CachedMatches {
    version: String,
    candidates: usize,
    /// `[camera a, frame a, camera b, frame b]` and `[ua.x, ua.y, ub.x, ub.y]` per match.
    pairs: Vec<([usize; 4], Vec<[f64; 4]>)>,
}

/// A transform's exact bits into a hash.
fn write_rigid(h: &mut impl Hasher, t: &Rigid) {
    let (q, v) = (t.rotation.to_array(), t.translation.to_array());
    q.iter().chain(&v).for_each(|x| h.write_u64(x.to_bits()));
}

/// The cache file's name for this input: 128 bits of two hashes of everything [`build`] reads.
pub fn cache_key(
    cameras: &[CameraData],
    vehicle_from_camera: &[Rigid],
    trajectory: &Trajectory,
) -> String {
    let hash = |seed: u64| {
        let mut h = crate::util::FastHasher::default();
        h.write_u64(seed);
        h.write(CACHE_VERSION.as_bytes());
        for (c, extrinsic) in cameras.iter().zip(vehicle_from_camera) {
            let k = &c.intrinsics;
            h.write_u64(u64::from(k.width) << 32 | u64::from(k.height));
            for v in [k.fx, k.fy, k.cx, k.cy].iter().chain(&k.distortion) {
                h.write_u64(v.to_bits());
            }
            write_rigid(&mut h, extrinsic);
            h.write_u64(c.readout.first_row_nanos as u64);
            h.write_u64(c.readout.last_row_nanos as u64);
            for f in &c.frames {
                h.write_u64(f.stamp_nanos as u64);
                // The pose the overlap check places the frame at.
                if let Ok(wv) = trajectory.world_from_vehicle(c.middle_stamp_nanos(f.stamp_nanos)) {
                    write_rigid(&mut h, &wv);
                }
                h.write_u64(f.keypoints.len() as u64);
                for kp in &f.keypoints {
                    h.write_u64(u64::from(kp.x.to_bits()) << 32 | u64::from(kp.y.to_bits()));
                    kp.descriptor.iter().for_each(|d| h.write_u64(*d));
                }
            }
            h.write_u64(c.frames.len() as u64);
        }
        h.finish()
    };
    format!(
        "{:016x}{:016x}",
        hash(0x9e37_79b9_7f4a_7c15),
        hash(0xc2b2_ae3d_27d4_eb4f)
    )
}

/// Called as candidate pairs are matched: `(pairs done, pairs to match)`, from any thread.
pub type MatchProgress<'a> = &'a (dyn Fn(usize, usize) + Sync);

/// [`build`], kept in `dir` (created if missing) under [`cache_key`]: read back when there, else
/// built and written atomically. `None`: always built. A cached result reports one
/// `(total, total)`.
pub fn build_cached(
    cameras: &[CameraData],
    vehicle_from_camera: &[Rigid],
    trajectory: &Trajectory,
    dir: Option<&Path>,
    progress: MatchProgress,
) -> Correspondences {
    let Some(dir) = dir else {
        return build(cameras, vehicle_from_camera, trajectory, progress);
    };
    let path = dir.join(format!(
        "{}.json",
        cache_key(cameras, vehicle_from_camera, trajectory)
    ));
    if let Some(c) = std::fs::read(&path)
        .ok()
        .and_then(|bytes| serde_json::from_slice::<CachedMatches>(&bytes).ok())
        .and_then(|cached| from_cache(cached, cameras))
    {
        progress(c.candidates, c.candidates);
        return c;
    }
    let built = build(cameras, vehicle_from_camera, trajectory, progress);
    let cached = CachedMatches {
        version: CACHE_VERSION.into(),
        candidates: built.candidates,
        pairs: built
            .pairs
            .iter()
            .map(|p| {
                (
                    [p.a.0, p.a.1, p.b.0, p.b.1],
                    p.pixels
                        .iter()
                        .map(|(ua, ub)| [ua.x, ua.y, ub.x, ub.y])
                        .collect(),
                )
            })
            .collect(),
    };
    if let Ok(bytes) = serde_json::to_vec(&cached) {
        let _ = std::fs::create_dir_all(dir);
        let _ = crate::util::write_atomic(&path, &bytes);
    }
    built
}

/// A cached file as correspondences, if it fits these cameras (indices in range, finite pixels).
fn from_cache(cached: CachedMatches, cameras: &[CameraData]) -> Option<Correspondences> {
    if cached.version != CACHE_VERSION {
        return None;
    }
    let frame_ok = |c: usize, f: usize| cameras.get(c).is_some_and(|cam| f < cam.frames.len());
    let mut pairs = Vec::with_capacity(cached.pairs.len());
    for ([ca, fa, cb, fb], pixels) in cached.pairs {
        if !frame_ok(ca, fa) || !frame_ok(cb, fb) || pixels.iter().flatten().any(|v| !v.is_finite())
        {
            return None;
        }
        pairs.push(MatchedPair {
            a: (ca, fa),
            b: (cb, fb),
            pixels: pixels
                .into_iter()
                .map(|[ax, ay, bx, by]| (DVec2::new(ax, ay), DVec2::new(bx, by)))
                .collect(),
        });
    }
    Some(Correspondences::new(
        pairs,
        cameras.len(),
        cached.candidates,
    ))
}

/// Match every overlapping pair of `cameras`' frames (their keypoints, in training pixels),
/// given each camera's current `vehicle_from_camera`.
pub fn build(
    cameras: &[CameraData],
    vehicle_from_camera: &[Rigid],
    trajectory: &Trajectory,
    progress: MatchProgress,
) -> Correspondences {
    let mut candidates = Vec::new();
    for (i, ci) in cameras.iter().enumerate() {
        for (j, cj) in cameras.iter().enumerate().skip(i) {
            for (fi, a) in ci.frames.iter().enumerate() {
                for (fj, b) in cj.frames.iter().enumerate() {
                    let dt = (a.stamp_nanos - b.stamp_nanos).abs() as f64 * 1e-9;
                    let near = if i == j {
                        fj > fi && dt <= SAME_CAMERA_SECS
                    } else {
                        dt <= CROSS_CAMERA_SECS
                    };
                    if near {
                        candidates.push(((i, fi), (j, fj)));
                    }
                }
            }
        }
    }
    let overlapping: Vec<_> = candidates
        .into_iter()
        .filter(|&(a, b)| {
            overlap(cameras, vehicle_from_camera, trajectory, a, b)
                .is_some_and(|o| o >= MIN_OVERLAP)
        })
        .collect();
    let total = overlapping.len();
    progress(0, total);
    let done = std::sync::atomic::AtomicUsize::new(0);
    let pairs: Vec<MatchedPair> = overlapping
        .par_iter()
        .filter_map(|&(a, b)| {
            let matched = (|| {
                let ka = &cameras.get(a.0)?.frames.get(a.1)?.keypoints;
                let kb = &cameras.get(b.0)?.frames.get(b.1)?.keypoints;
                match_pair(cameras, (a, ka), (b, kb))
            })();
            progress(
                done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1,
                total,
            );
            matched
        })
        .collect();
    Correspondences::new(pairs, cameras.len(), overlapping.len())
}

/// Fraction of a grid of frame a's pixels, at 8 and 20 m, that frame b sees (each frame at
/// its middle row's pose).
fn overlap(
    cameras: &[CameraData],
    vehicle_from_camera: &[Rigid],
    trajectory: &Trajectory,
    (ca, fa): (usize, usize),
    (cb, fb): (usize, usize),
) -> Option<f64> {
    let (cam_a, cam_b) = (&cameras[ca], &cameras[cb]);
    let world_from_a = trajectory
        .world_from_vehicle(cam_a.middle_stamp_nanos(cam_a.frames[fa].stamp_nanos))
        .ok()?
        * vehicle_from_camera[ca];
    let b_from_world = (trajectory
        .world_from_vehicle(cam_b.middle_stamp_nanos(cam_b.frames[fb].stamp_nanos))
        .ok()?
        * vehicle_from_camera[cb])
        .inverse();
    let (w, h) = (
        cam_a.intrinsics.width as f64,
        cam_a.intrinsics.height as f64,
    );
    let (mut seen, mut total) = (0usize, 0usize);
    for gy in 0..6 {
        for gx in 0..8 {
            let pixel = DVec2::new((gx as f64 + 0.5) * w / 8.0, (gy as f64 + 0.5) * h / 6.0);
            let Some(ray) = cam_a.intrinsics.unproject(pixel) else {
                continue;
            };
            for depth in [8.0, 20.0] {
                total += 1;
                let p: DVec3 = world_from_a.transform_point(ray * depth);
                let q = b_from_world.transform_point(p);
                if cam_b
                    .intrinsics
                    .project(q)
                    .is_some_and(|u| cam_b.intrinsics.in_image(u))
                {
                    seen += 1;
                }
            }
        }
    }
    (total > 0).then(|| seen as f64 / total as f64)
}

fn match_pair(
    cameras: &[CameraData],
    (a, ka): ((usize, usize), &[Keypoint]),
    (b, kb): ((usize, usize), &[Keypoint]),
) -> Option<MatchedPair> {
    let matches = match_mutual(ka, kb, 0.8, 64);
    if matches.len() < MIN_INLIERS {
        return None;
    }
    let (ia, ib) = (&cameras[a.0].intrinsics, &cameras[b.0].intrinsics);
    let pixel = |k: &Keypoint| DVec2::new(k.x as f64, k.y as f64);
    let mut rays_a = Vec::with_capacity(matches.len());
    let mut rays_b = Vec::with_capacity(matches.len());
    let mut pixels = Vec::with_capacity(matches.len());
    for (i, j) in matches {
        let (pa, pb) = (pixel(&ka[i]), pixel(&kb[j]));
        if let (Some(ra), Some(rb)) = (ia.unproject(pa), ib.unproject(pb)) {
            rays_a.push(ra);
            rays_b.push(rb);
            pixels.push((pa, pb));
        }
    }
    let threshold = 1.5 / ia.fx.max(1e-9).min(ib.fx.max(1e-9));
    let seed = (a.0 * 1000 + a.1 * 31 + b.0 * 7 + b.1) as u64 + 1;
    let verified = verify(&rays_a, &rays_b, threshold, 200, MIN_INLIERS, seed)?;
    let pixels: Vec<(DVec2, DVec2)> = pixels
        .into_iter()
        .zip(&verified.inliers)
        .filter(|(_, keep)| **keep)
        .map(|(p, _)| p)
        .collect();
    (pixels.len() >= MIN_INLIERS).then_some(MatchedPair { a, b, pixels })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::camera::CameraIntrinsics;

    /// A point projected at full size and at the training size lands where `rescale_pixel`
    /// puts the full-size pixel, for the sizes the pipeline uses (1920 → 960 → 480, and back up
    /// for the hand-eye's full-size keypoints).
    #[test]
    fn rescaled_pixels_stay_on_the_scaled_cameras_projection() {
        let full = CameraIntrinsics::pinhole(1920, 1080, 1970.0, 1970.0, 970.3, 541.7);
        for point in [
            DVec3::new(0.0, 0.0, 10.0),
            DVec3::new(-3.1, 1.7, 8.0),
            DVec3::new(4.4, -2.2, 12.5),
        ] {
            let p = full.project(point).unwrap();
            for (from, to) in [(1.0, 0.5), (0.5, 0.25), (0.5, 1.0), (1.0, 0.25)] {
                let (a, b) = (full.scaled(from), full.scaled(to));
                let pa = a.project(point).unwrap();
                let pb = b.project(point).unwrap();
                let factor = to / from;
                let (x, y) = (rescale_pixel(pa.x, factor), rescale_pixel(pa.y, factor));
                assert!(
                    (x - pb.x).abs() < 1e-3 && (y - pb.y).abs() < 1e-3,
                    "{p}: {x} {y} vs {pb}"
                );
                // The old `x · factor` is a quarter pixel off at half size.
                if (from, to) == (0.5, 0.25) {
                    assert!((pa.x * 0.5 - pb.x - 0.25).abs() < 1e-3);
                }
            }
        }
    }
}
