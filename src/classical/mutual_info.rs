//! Mutual-information LiDAR–camera calibration (Pandey et al. 2012/2015; the UniCal paper's MI
//! baseline, method.md §15.7).
//!
//! How it works. For one camera and a reference LiDAR, a few frames are prepared once: the image
//! becomes grey, blurred (Gaussian, σ = 5 px at 1920 wide) and histogram-equalised, as in the
//! paper's setting; the sweep's points go through the trajectory at their own firing times into
//! the vehicle frame at the image's stamp (as for edge alignment), each with its reflectivity,
//! binned by its rank among all points (equal-count bins, so sensors of any intensity scale
//! compare alike). For a candidate `vehicle_from_camera` every point is projected, the grey value
//! read bilinearly, and a joint histogram of (reflectivity bin, grey) filled with linear
//! (soft) assignment to the two nearest grey bins; the histogram is smoothed by a Gaussian
//! kernel whose width follows Silverman's rule (h = 1.06 σ̂ n^(−1/5), in bins), and
//! `MI = H(X) + H(Y) − H(X, Y)` in nats. [`MiSearch`] maximises it by Barzilai–Borwein gradient
//! ascent on central finite differences over the six right-perturbation coordinates of the
//! extrinsic, each bounded to the paper's ±2° and ±20 cm around the initial guess (projected
//! steps; a step that lowers MI is halved until it does not).

use glam::DVec3;
use rayon::prelude::*;

use crate::calib::Rig;
use crate::geometry::Rigid;
use crate::geometry::camera::CameraIntrinsics;
use crate::log::Drive;
use crate::optim::edge_align::{
    AlignError, SweepImagePair, points_in_vehicle_at, sweep_image_pairs,
};

/// Settings; the defaults are the paper's (blur, equalisation, bounds).
#[derive(Clone, Debug)]
pub struct MiConfig {
    /// Histogram bins per axis.
    pub bins: usize,
    /// Gaussian blur of the image at 1920 px wide (scaled with the image width).
    pub blur_sigma_px_at_1920: f64,
    /// Search bounds around the initial guess, per rotation axis and per translation axis.
    pub max_rotation_deg: f64,
    pub max_translation_m: f64,
    /// At most this many points per frame (evenly strided).
    pub max_points_per_frame: usize,
    /// Gradient-ascent iterations.
    pub iterations: usize,
}

impl Default for MiConfig {
    fn default() -> Self {
        Self {
            bins: 64,
            blur_sigma_px_at_1920: 5.0,
            max_rotation_deg: 2.0,
            max_translation_m: 0.2,
            max_points_per_frame: 40_000,
            iterations: 60,
        }
    }
}

/// One image and the LiDAR points seen with it.
#[derive(Clone, Debug)]
pub struct MiFrame {
    pub width: usize,
    pub height: usize,
    /// Blurred, histogram-equalised grey in [0, 1].
    pub grey: Vec<f32>,
    pub points_in_vehicle: Vec<DVec3>,
    /// Reflectivity bin of each point.
    pub reflectivity_bin: Vec<u16>,
}

/// The MI problem of one camera against one reference LiDAR.
#[derive(Clone, Debug)]
pub struct MiProblem {
    pub camera: String,
    pub lidar: String,
    pub intrinsics: CameraIntrinsics,
    pub frames: Vec<MiFrame>,
    pub bins: usize,
}

use crate::features::grey::grey_unit as grey;

/// Separable Gaussian blur (clamped borders), rows in parallel.
pub fn gaussian_blur(values: &[f32], width: usize, height: usize, sigma: f64) -> Vec<f32> {
    if sigma <= 0.0 || width == 0 || height == 0 {
        return values.to_vec();
    }
    let radius = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f32> = (-radius..=radius)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let norm: f32 = kernel.iter().sum();
    let kernel: Vec<f32> = kernel.iter().map(|k| k / norm).collect();
    let pass = |src: &[f32], along_rows: bool| -> Vec<f32> {
        let mut out = vec![0.0; src.len()];
        out.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
            for (x, o) in row.iter_mut().enumerate() {
                let mut acc = 0.0;
                for (k, w) in kernel.iter().enumerate() {
                    let d = k as isize - radius;
                    let (sx, sy) = if along_rows {
                        ((x as isize + d).clamp(0, width as isize - 1) as usize, y)
                    } else {
                        (x, (y as isize + d).clamp(0, height as isize - 1) as usize)
                    };
                    acc += w * src[sy * width + sx];
                }
                *o = acc;
            }
        });
        out
    };
    pass(&pass(values, true), false)
}

/// Histogram equalisation of values in [0, 1] (1024 levels): each value becomes its rank.
pub fn equalize(values: &[f32]) -> Vec<f32> {
    const LEVELS: usize = 1024;
    let level =
        |v: f32| ((v.clamp(0.0, 1.0) * (LEVELS - 1) as f32).round() as usize).min(LEVELS - 1);
    let mut hist = [0usize; LEVELS];
    for &v in values {
        hist[level(v)] += 1;
    }
    let n = values.len().max(1) as f32;
    let mut cdf = [0f32; LEVELS];
    let mut acc = 0usize;
    for (c, h) in cdf.iter_mut().zip(hist) {
        // Mid-rank of the level: equal values map to one value, the result spans (0, 1).
        *c = (acc as f32 + h as f32 * 0.5) / n;
        acc += h;
    }
    values.iter().map(|&v| cdf[level(v)]).collect()
}

/// Equal-count bins of `values`: the bin of each value by its rank (ties share a bin).
pub fn rank_bins(values: &[f32], bins: usize) -> Vec<u16> {
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let mut out = vec![0u16; values.len()];
    let n = values.len().max(1);
    let mut i = 0;
    while i < order.len() {
        let mut j = i;
        while j + 1 < order.len() && values[order[j + 1]] == values[order[i]] {
            j += 1;
        }
        let mid = (i + j) / 2;
        let bin = ((mid * bins) / n).min(bins - 1) as u16;
        for &k in &order[i..=j] {
            out[k] = bin;
        }
        i = j + 1;
    }
    out
}

/// Mutual information (nats) of a joint histogram after Gaussian smoothing of width `h_bins`.
pub fn mutual_information(joint: &[f64], bins: usize, h_bins: f64) -> f64 {
    let smoothed = if h_bins > 0.05 {
        let radius = (3.0 * h_bins).ceil() as isize;
        let kernel: Vec<f64> = (-radius..=radius)
            .map(|i| (-(i * i) as f64 / (2.0 * h_bins * h_bins)).exp())
            .collect();
        let blur = |src: &[f64], rows: bool| {
            let mut out = vec![0.0; src.len()];
            for a in 0..bins {
                for b in 0..bins {
                    let mut acc = 0.0;
                    for (k, w) in kernel.iter().enumerate() {
                        let c = b as isize + k as isize - radius;
                        if c < 0 || c >= bins as isize {
                            continue;
                        }
                        let c = c as usize;
                        acc += w * if rows {
                            src[a * bins + c]
                        } else {
                            src[c * bins + a]
                        };
                    }
                    if rows {
                        out[a * bins + b] = acc;
                    } else {
                        out[b * bins + a] = acc;
                    }
                }
            }
            out
        };
        blur(&blur(joint, true), false)
    } else {
        joint.to_vec()
    };
    let total: f64 = smoothed.iter().sum();
    if total <= 0.0 {
        return 0.0;
    }
    let mut px = vec![0.0; bins];
    let mut py = vec![0.0; bins];
    for a in 0..bins {
        for b in 0..bins {
            let p = smoothed[a * bins + b] / total;
            px[a] += p;
            py[b] += p;
        }
    }
    let mut mi = 0.0;
    for a in 0..bins {
        for b in 0..bins {
            let p = smoothed[a * bins + b] / total;
            if p > 1e-15 {
                mi += p * (p / (px[a] * py[b])).ln();
            }
        }
    }
    mi
}

impl MiProblem {
    /// Prepare `frames` frames of `camera` against `lidar` (extrinsic from `rig`) from a drive.
    pub fn from_drive(
        drive: &Drive,
        rig: &Rig,
        camera: &str,
        lidar: &str,
        frames: usize,
        segments_nanos: &[(i64, i64)],
        config: &MiConfig,
    ) -> Result<Self, AlignError> {
        let pairs = sweep_image_pairs(drive, camera, lidar, frames, segments_nanos)?;
        Self::from_pairs(drive, rig, (camera, lidar), pairs, config)
    }

    /// The same from chosen sweep–image pairs (e.g. [`held_out_pairs`](crate::optim::edge_align::held_out_pairs)'s).
    pub fn from_pairs(
        drive: &Drive,
        rig: &Rig,
        (camera, lidar): (&str, &str),
        pairs: Vec<SweepImagePair>,
        config: &MiConfig,
    ) -> Result<Self, AlignError> {
        let setup = |what: String| AlignError::Setup(what);
        let intrinsics = rig
            .sensor(camera)
            .and_then(|c| c.camera.clone())
            .ok_or_else(|| setup(format!("'{camera}' is not a camera with intrinsics")))?;
        let vehicle_from_lidar = rig
            .sensor(lidar)
            .ok_or_else(|| setup(format!("no sensor '{lidar}' in the rig")))?
            .vehicle_from_sensor;
        let mut prepared = Vec::new();
        let mut all_reflectivity = Vec::new();
        for pair in pairs {
            let Some(image) = drive.image_or_skip(camera, pair.image_index) else {
                continue;
            };
            let (w, h) = (image.width() as usize, image.height() as usize);
            let sigma = config.blur_sigma_px_at_1920 * w as f64 / 1920.0;
            let grey = equalize(&gaussian_blur(&grey(&image), w, h, sigma));
            let n = pair.sweep.len();
            let stride = n.div_ceil(config.max_points_per_frame.max(1)).max(1);
            let indices: Vec<usize> = (0..n).step_by(stride).collect();
            let points = points_in_vehicle_at(
                &pair.sweep,
                &indices,
                &drive.trajectory,
                vehicle_from_lidar,
                pair.image_stamp_nanos,
            )?;
            let reflectivity: Vec<f32> = indices
                .iter()
                .map(|&i| pair.sweep.intensity.get(i).copied().unwrap_or(0.0))
                .collect();
            all_reflectivity.extend_from_slice(&reflectivity);
            prepared.push((w, h, grey, points, reflectivity.len()));
        }
        if all_reflectivity.iter().all(|&v| v == all_reflectivity[0]) {
            return Err(setup(format!(
                "'{lidar}' has no intensity (all returns equal): mutual information needs reflectivity"
            )));
        }
        let bins_of_all = rank_bins(&all_reflectivity, config.bins);
        let mut offset = 0;
        let frames = prepared
            .into_iter()
            .map(|(width, height, grey, points_in_vehicle, n)| {
                let reflectivity_bin = bins_of_all[offset..offset + n].to_vec();
                offset += n;
                MiFrame {
                    width,
                    height,
                    grey,
                    points_in_vehicle,
                    reflectivity_bin,
                }
            })
            .collect();
        let mut problem = Self {
            camera: camera.into(),
            lidar: lidar.into(),
            intrinsics,
            frames,
            bins: config.bins,
        };
        if let Some(c) = rig.sensor(camera) {
            problem.keep_visible(c.vehicle_from_sensor);
        }
        Ok(problem)
    }

    /// Keep the points `vehicle_from_camera` puts inside the image with a 5 % margin, so MI is
    /// measured on one set of points wherever the search goes (points entering and leaving the
    /// image at its border would otherwise bias it).
    pub fn keep_visible(&mut self, vehicle_from_camera: Rigid) {
        let camera_from_vehicle = vehicle_from_camera.inverse();
        let intr = &self.intrinsics;
        for f in &mut self.frames {
            let keep: Vec<bool> = f
                .points_in_vehicle
                .iter()
                .map(|q| {
                    let p = camera_from_vehicle.transform_point(*q);
                    p.z > 0.5
                        && intr
                            .project(p)
                            .is_some_and(|px| crate::optim::edge_align::inside_margin(intr, px))
                })
                .collect();
            let mut k = keep.iter();
            f.points_in_vehicle.retain(|_| *k.next().unwrap_or(&false));
            let mut k = keep.iter();
            f.reflectivity_bin.retain(|_| *k.next().unwrap_or(&false));
        }
    }

    /// Points over all frames.
    pub fn point_count(&self) -> usize {
        self.frames.iter().map(|f| f.points_in_vehicle.len()).sum()
    }

    /// The joint histogram (reflectivity × grey, soft in grey) and the number of points in view.
    pub fn joint_histogram(&self, vehicle_from_camera: Rigid) -> (Vec<f64>, usize) {
        let bins = self.bins;
        let camera_from_vehicle = vehicle_from_camera.inverse();
        let mut joint = vec![0.0; bins * bins];
        let mut used = 0;
        for f in &self.frames {
            let (wm, hm) = ((f.width - 1) as f64, (f.height - 1) as f64);
            for (q, &rb) in f.points_in_vehicle.iter().zip(&f.reflectivity_bin) {
                let p = camera_from_vehicle.transform_point(*q);
                if p.z <= 0.5 {
                    continue;
                }
                let Some(px) = self.intrinsics.project(p) else {
                    continue;
                };
                if !(px.x >= 0.0 && px.y >= 0.0 && px.x <= wm && px.y <= hm) {
                    continue;
                }
                let (x0, y0) = (px.x.floor() as usize, px.y.floor() as usize);
                let (x1, y1) = ((x0 + 1).min(f.width - 1), (y0 + 1).min(f.height - 1));
                let (fx, fy) = (px.x - x0 as f64, px.y - y0 as f64);
                let g = |x: usize, y: usize| f.grey[y * f.width + x] as f64;
                let v = (g(x0, y0) * (1.0 - fx) + g(x1, y0) * fx) * (1.0 - fy)
                    + (g(x0, y1) * (1.0 - fx) + g(x1, y1) * fx) * fy;
                let gb = (v * bins as f64 - 0.5).clamp(0.0, (bins - 1) as f64);
                let (b0, t) = (gb.floor() as usize, gb - gb.floor());
                let row = rb as usize * bins;
                joint[row + b0] += 1.0 - t;
                if b0 + 1 < bins {
                    joint[row + b0 + 1] += t;
                }
                used += 1;
            }
        }
        (joint, used)
    }

    /// Mutual information (nats) of reflectivity and grey level through `vehicle_from_camera`.
    pub fn mi(&self, vehicle_from_camera: Rigid) -> f64 {
        let (joint, n) = self.joint_histogram(vehicle_from_camera);
        if n < 100 {
            return 0.0;
        }
        // Silverman's rule on the grey axis (in bins; a uniform marginal has σ = bins/√12).
        let sigma = self.bins as f64 / 12f64.sqrt();
        let h = 1.06 * sigma * (n as f64).powf(-0.2);
        mutual_information(&joint, self.bins, h)
    }
}

/// Barzilai–Borwein gradient ascent on MI within the paper's bounds.
#[derive(Clone, Debug)]
pub struct MiSearch {
    pub start: Rigid,
    /// Coordinates scaled so the bounds are ±1: rotation (3, in units of the rotation bound),
    /// translation (3, in units of the translation bound), right perturbation of `start`.
    x: [f64; 6],
    previous: Option<([f64; 6], [f64; 6])>,
    gamma: f64,
    pub best_mi: f64,
    pub best: Rigid,
    pub iterations: usize,
    converged: bool,
    bounds: (f64, f64),
}

impl MiSearch {
    pub fn new(problem: &MiProblem, start: Rigid, config: &MiConfig) -> Self {
        Self {
            start,
            x: [0.0; 6],
            previous: None,
            gamma: 0.05,
            best_mi: problem.mi(start),
            best: start,
            iterations: 0,
            converged: false,
            bounds: (
                config.max_rotation_deg.to_radians(),
                config.max_translation_m,
            ),
        }
    }

    fn pose(&self, x: &[f64; 6]) -> Rigid {
        let (r, t) = self.bounds;
        self.start.perturbed_right(
            DVec3::new(x[0], x[1], x[2]) * r,
            DVec3::new(x[3], x[4], x[5]) * t,
        )
    }

    pub fn converged(&self) -> bool {
        self.converged
    }

    /// The axes of the best pose that sit on the search's bounds, as text (`rot y at +2°,
    /// z at −20 cm`); empty when the best pose is inside them. A maximum on a bound is where
    /// the search was stopped, not a maximum of mutual information.
    pub fn at_bounds(&self) -> String {
        let (r, t) = self.bounds;
        let names = ["rot x", "rot y", "rot z", "x", "y", "z"];
        self.x
            .iter()
            .enumerate()
            .filter(|(_, v)| v.abs() >= 1.0 - 1e-9)
            .map(|(i, v)| {
                let sign = if *v > 0.0 { '+' } else { '−' };
                if i < 3 {
                    format!("{} at {sign}{:.1}°", names[i], r.to_degrees())
                } else {
                    format!("{} at {sign}{:.0} cm", names[i], t * 100.0)
                }
            })
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// One iteration: a central-difference gradient (12 evaluations, in parallel), the
    /// Barzilai–Borwein step, projection onto the bounds, halving until MI does not drop.
    pub fn step(&mut self, problem: &MiProblem) {
        if self.converged {
            return;
        }
        self.iterations += 1;
        // 0.02 of the bound: 0.04° and 4 mm.
        const H: f64 = 0.02;
        let grad_parts: Vec<f64> = (0..12)
            .into_par_iter()
            .map(|k| {
                let mut x = self.x;
                x[k / 2] += if k % 2 == 0 { H } else { -H };
                problem.mi(self.pose(&x))
            })
            .collect();
        let grad: [f64; 6] =
            std::array::from_fn(|i| (grad_parts[2 * i] - grad_parts[2 * i + 1]) / (2.0 * H));
        if let Some((px, pg)) = self.previous {
            // γ = sᵀs / |sᵀy| (ascent: y = g_k − g_{k−1} is negative along s near a maximum).
            let s: [f64; 6] = std::array::from_fn(|i| self.x[i] - px[i]);
            let y: [f64; 6] = std::array::from_fn(|i| grad[i] - pg[i]);
            let ss: f64 = s.iter().map(|v| v * v).sum();
            let sy: f64 = s.iter().zip(&y).map(|(a, b)| a * b).sum();
            if sy.abs() > 1e-15 && ss > 0.0 {
                self.gamma = ss / sy.abs();
            }
        }
        if self.previous.is_none() {
            // First step: at most 0.05 of the bound along the steepest coordinate (0.1°, 1 cm).
            let g_max = grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
            if g_max > 0.0 {
                self.gamma = 0.05 / g_max;
            }
        }
        let mut gamma = self.gamma;
        for _ in 0..8 {
            let candidate: [f64; 6] =
                std::array::from_fn(|i| (self.x[i] + gamma * grad[i]).clamp(-1.0, 1.0));
            let mi = problem.mi(self.pose(&candidate));
            if mi >= self.best_mi {
                self.previous = Some((self.x, grad));
                let moved: f64 = candidate
                    .iter()
                    .zip(&self.x)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                self.x = candidate;
                self.best_mi = mi;
                self.best = self.pose(&candidate);
                self.gamma = gamma;
                // Moves below 0.001 of the bound (0.002°, 0.2 mm): done.
                self.converged = moved < 1e-3;
                return;
            }
            gamma *= 0.5;
        }
        self.converged = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_search_on_its_bounds_names_them() {
        let mut search = MiSearch {
            start: Rigid::IDENTITY,
            x: [0.3, 0.0, 0.0, 0.0, 0.5, 0.0],
            previous: None,
            gamma: 0.05,
            best_mi: 0.0,
            best: Rigid::IDENTITY,
            iterations: 0,
            converged: true,
            bounds: (2f64.to_radians(), 0.2),
        };
        assert_eq!(search.at_bounds(), "");
        search.x[1] = 1.0;
        search.x[5] = -1.0;
        assert_eq!(search.at_bounds(), "rot y at +2.0°, z at −20 cm");
    }

    #[test]
    fn mi_of_independent_and_dependent_variables() {
        let bins = 16;
        // Independent: a uniform joint histogram has no information.
        let uniform = vec![1.0; bins * bins];
        assert!(mutual_information(&uniform, bins, 0.0).abs() < 1e-12);
        // Identical variables: MI = H(X) = ln(bins).
        let mut diag = vec![0.0; bins * bins];
        for i in 0..bins {
            diag[i * bins + i] = 1.0;
        }
        assert!((mutual_information(&diag, bins, 0.0) - (bins as f64).ln()).abs() < 1e-9);
        // Smoothing lowers it but keeps it clearly above zero.
        let smoothed = mutual_information(&diag, bins, 1.0);
        assert!(smoothed > 0.5 && smoothed < (bins as f64).ln());
    }

    #[test]
    fn equalisation_and_rank_bins_spread_values_evenly() {
        let values: Vec<f32> = (0..1000).map(|i| ((i as f32) / 1000.0).powi(3)).collect();
        let eq = equalize(&values);
        let below_half = eq.iter().filter(|&&v| v < 0.5).count();
        assert!((450..=550).contains(&below_half), "{below_half}");
        let bins = rank_bins(&values, 10);
        for b in 0..10u16 {
            let n = bins.iter().filter(|&&x| x == b).count();
            assert_eq!(n, 100, "bin {b}");
        }
        // Ties share a bin.
        let tied = rank_bins(&[1.0, 1.0, 1.0, 2.0], 4);
        assert!(tied[0] == tied[1] && tied[1] == tied[2] && tied[3] > tied[0]);
    }

    #[test]
    fn blur_keeps_the_mean_and_spreads_a_spike() {
        let (w, h) = (31, 21);
        let mut v = vec![0.0f32; w * h];
        v[10 * w + 15] = 1.0;
        let b = gaussian_blur(&v, w, h, 2.0);
        let sum: f32 = b.iter().sum();
        assert!((sum - 1.0).abs() < 1e-4, "{sum}");
        assert!(b[10 * w + 15] < 0.1 && b[10 * w + 17] > 0.01);
        assert!((b[10 * w + 13] - b[10 * w + 17]).abs() < 1e-6);
    }
}
