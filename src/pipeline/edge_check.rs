//! A camera's target-free check against a LiDAR, for the report: the edge-alignment score
//! (mean truncated distance, px, from the LiDAR's depth discontinuities to the image's edges;
//! [`EdgeAlignment`]) and how well the images pin each axis of the camera's pose down.
//!
//! How the uncertainty is found: the cost is a sum over frames, `S(x) = Σ_k S_k(x)`, of each
//! frame's summed edge distances, with `x` a right perturbation of `vehicle_from_camera` in the
//! camera's own frame (three rotations, three translations). Its Hessian `H` comes from central
//! differences at a step of about the sensor's expected error, and the frames' gradients `g_k`
//! from the same evaluations. The frames are independent samples of the drive, so the
//! covariance of the minimiser is the sandwich (M-estimator) one, `H⁻¹ B H⁻¹` with `B` the
//! centred scatter of the frames' gradients times their count. A direction along which `H`
//! is flat or not convex is one the images do not observe.
//!
//! The scatter sees only how the frames disagree about the edge score's minimum, not how far
//! that minimum lies from the truth (1–6 cm on the simulator). So a floor of [`FLOOR_DEG`] /
//! [`FLOOR_M`] is added in quadrature: without it a tenth of the axes of seven simulated drives
//! ended more than 2σ off, with it 4 %, and 8 % on two fresh drives (docs/experiments/pipeline.md,
//! "Does the report's 1-σ cover the true error?").

use crate::error::RunError;
use glam::DVec3;

use crate::calib::Rig;
use crate::geometry::Rigid;
use crate::log::Drive;
use crate::optim::edge_align::{AlignError, EdgeAlignment, held_out_pairs};

/// The finite-difference steps: rotations (rad) and translations (m).
const STEP_RAD: f64 = 0.3 * std::f64::consts::PI / 180.0;
const STEP_M: f64 = 0.03;
/// Rotations are compared with translations as the displacement they cause at this lever (m).
const LEVER_M: f64 = 10.0;
/// The edge score's own rotation error (°), added in quadrature to every observed rotation
/// axis's σ (module doc).
pub const FLOOR_DEG: f64 = 0.02;
/// The edge score's own translation error (m), added in quadrature to every observed
/// translation axis's σ (module doc).
pub const FLOOR_M: f64 = 0.005;

/// One camera against one LiDAR, over a few frames.
#[derive(Clone, Debug)]
pub struct EdgeCheck {
    pub camera: String,
    pub lidar: String,
    /// One problem per frame (their points are fixed at construction: a point that later
    /// leaves the image costs the truncation instead of dropping out).
    frames: Vec<EdgeAlignment>,
    /// Whether no frame is one the fit used (false only on a log with no other frames).
    held_out: bool,
}

/// Per axis (rotations about the camera's x, y, z, then translations along them): the 1-σ
/// uncertainty (rad, m; infinite where the images do not observe it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisSigmas(pub [f64; 6]);

impl EdgeCheck {
    /// Prepare `frames` frames of `camera` against `lidar` (at their extrinsics in `rig`)
    /// within `segments_nanos`, the points kept where `rig`'s camera pose sees them. The
    /// frames avoid `fitted_images` (the camera's images the fit used) wherever the log has
    /// others ([`EdgeCheck::held_out`] says whether it did).
    pub fn new(
        drive: &Drive,
        rig: &Rig,
        (camera, lidar): (&str, &str),
        frames: usize,
        segments_nanos: &[(i64, i64)],
        fitted_images: &[usize],
    ) -> Result<Self, RunError> {
        let context = |e: AlignError| RunError::from(e).within(format!("{camera} × {lidar}"));
        let (pairs, held_out) = held_out_pairs(
            drive,
            (camera, lidar),
            frames,
            segments_nanos,
            fitted_images,
        )
        .map_err(context)?;
        let mut problem =
            EdgeAlignment::from_pairs(drive, rig, (camera, lidar), pairs, drive.camera_readout)
                .map_err(context)?;
        let all = std::mem::take(&mut problem.frames);
        let frames = all
            .into_iter()
            .filter(|f| !f.points_in_vehicle.is_empty())
            .map(|f| EdgeAlignment {
                frames: vec![f],
                ..problem.clone()
            })
            .collect::<Vec<_>>();
        if frames.is_empty() {
            return Err(RunError::NotEnoughData(format!(
                "{camera} × {lidar}: no LiDAR silhouette inside the image"
            )));
        }
        Ok(Self {
            camera: camera.into(),
            lidar: lidar.into(),
            frames,
            held_out,
        })
    }

    /// Whether every frame is one the fit did not use.
    pub fn held_out(&self) -> bool {
        self.held_out
    }

    pub fn frame_count(&self) -> usize {
        self.frames.len()
    }

    /// Each frame's summed edge distance (px) through `vehicle_from_camera`.
    fn frame_sums(&self, vehicle_from_camera: Rigid) -> Vec<f64> {
        self.frames
            .iter()
            .map(|f| {
                f.distances(vehicle_from_camera)
                    .iter()
                    .map(|&d| d as f64)
                    .sum()
            })
            .collect()
    }

    /// The mean truncated edge distance (px) over every frame's points.
    pub fn score(&self, vehicle_from_camera: Rigid) -> f64 {
        let points: usize = self.frames.iter().map(|f| f.point_count()).sum();
        self.frame_sums(vehicle_from_camera).iter().sum::<f64>() / points.max(1) as f64
    }

    /// The edge cost's local quadratic model at `at` (module doc): central differences of the
    /// summed edge distances over every frame, in the camera's own frame.
    pub fn local_model(&self, at: Rigid) -> LocalModel {
        let step = [STEP_RAD, STEP_RAD, STEP_RAD, STEP_M, STEP_M, STEP_M];
        let pose = |dx: [f64; 6]| {
            at.perturbed_right(
                DVec3::new(dx[0], dx[1], dx[2]),
                DVec3::new(dx[3], dx[4], dx[5]),
            )
        };
        let unit = |i: usize, s: f64| -> [f64; 6] {
            std::array::from_fn(|k| if k == i { s * step[i] } else { 0.0 })
        };
        let total = |v: &[f64]| v.iter().sum::<f64>();
        let centre = self.frame_sums(at);
        let s0 = total(&centre);
        let plus: Vec<Vec<f64>> = (0..6)
            .map(|i| self.frame_sums(pose(unit(i, 1.0))))
            .collect();
        let minus: Vec<Vec<f64>> = (0..6)
            .map(|i| self.frame_sums(pose(unit(i, -1.0))))
            .collect();
        let mut hessian = [[0.0; 6]; 6];
        for i in 0..6 {
            hessian[i][i] = (total(&plus[i]) + total(&minus[i]) - 2.0 * s0) / (step[i] * step[i]);
            for j in i + 1..6 {
                let at2 = |a: f64, b: f64| {
                    let mut d = unit(i, a);
                    d[j] = b * step[j];
                    total(&self.frame_sums(pose(d)))
                };
                let v = (at2(1.0, 1.0) - at2(1.0, -1.0) - at2(-1.0, 1.0) + at2(-1.0, -1.0))
                    / (4.0 * step[i] * step[j]);
                hessian[i][j] = v;
                hessian[j][i] = v;
            }
        }
        let frame_gradients: Vec<[f64; 6]> = (0..centre.len())
            .map(|f| std::array::from_fn(|i| (plus[i][f] - minus[i][f]) / (2.0 * step[i])))
            .collect();
        LocalModel {
            hessian,
            frame_gradients,
        }
    }

    /// The 1-σ uncertainty of each axis of the camera's pose at `at` (module doc).
    pub fn sigmas(&self, at: Rigid) -> AxisSigmas {
        let model = self.local_model(at);
        let grads = &model.frame_gradients;
        // Each frame's gradient, centred, and their scatter.
        let k = grads.len();
        let gradient = model.gradient();
        let mean: [f64; 6] = std::array::from_fn(|i| gradient[i] / k.max(1) as f64);
        let mut b = [[0.0; 6]; 6];
        for g in grads {
            for r in 0..6 {
                for c in 0..6 {
                    b[r][c] += (g[r] - mean[r]) * (g[c] - mean[c]);
                }
            }
        }
        let scale_b = if k > 1 {
            k as f64 / (k as f64 - 1.0)
        } else {
            1.0
        };
        b.iter_mut().flatten().for_each(|v| *v *= scale_b.max(1.0));
        AxisSigmas(with_floor(sandwich_sigmas(model.hessian, b, k)))
    }
}

/// The edge cost's local model at a pose (rotations first; px per rad and per m).
#[derive(Clone, Debug)]
pub struct LocalModel {
    /// The Hessian of the summed edge distances.
    pub hessian: [[f64; 6]; 6],
    /// Each frame's own gradient.
    pub frame_gradients: Vec<[f64; 6]>,
}

impl LocalModel {
    /// The gradient of the summed edge distances: the sum of the frames' gradients.
    pub fn gradient(&self) -> [f64; 6] {
        std::array::from_fn(|i| self.frame_gradients.iter().map(|g| g[i]).sum())
    }

    /// The Newton step to the model's minimum, `−H⁻¹ g`, where `H` is positive definite.
    pub fn newton_step(&self) -> Option<[f64; 6]> {
        let h: [f64; 36] = std::array::from_fn(|k| self.hessian[k / 6][k % 6]);
        crate::geometry::spd::solve6(h, self.gradient()).map(|x| x.map(|v| -v))
    }
}

/// The per-axis σ of `H⁻¹ B H⁻¹` (rotations first, rad and m), infinite along the axes a flat
/// or concave direction of `H` touches.
fn sandwich_sigmas(h: [[f64; 6]; 6], b: [[f64; 6]; 6], frames: usize) -> [f64; 6] {
    // Rotations counted at a lever so the two halves share a scale.
    let s = [LEVER_M, LEVER_M, LEVER_M, 1.0, 1.0, 1.0];
    let hs: [[f64; 6]; 6] =
        std::array::from_fn(|r| std::array::from_fn(|c| h[r][c] / (s[r] * s[c])));
    let bs: [[f64; 6]; 6] =
        std::array::from_fn(|r| std::array::from_fn(|c| b[r][c] / (s[r] * s[c])));
    let (inv, unobserved, largest) = crate::geometry::spd::observed_inverse(hs, 1e-4);
    // With one frame the scatter is unknown: the Hessian's own scale stands in.
    let cov = if frames > 1 {
        mul(mul(inv, bs), inv)
    } else {
        inv
    };
    std::array::from_fn(|axis| {
        if unobserved[axis] || largest <= 0.0 {
            f64::INFINITY
        } else {
            cov[axis][axis].max(0.0).sqrt() / s[axis]
        }
    })
}

/// `sigmas` (rotations first, rad and m) with the edge score's own error added in quadrature;
/// an unobserved axis stays unobserved.
fn with_floor(sigmas: [f64; 6]) -> [f64; 6] {
    std::array::from_fn(|k| {
        let floor = if k < 3 {
            FLOOR_DEG.to_radians()
        } else {
            FLOOR_M
        };
        sigmas[k].hypot(floor)
    })
}

fn mul(a: [[f64; 6]; 6], b: [[f64; 6]; 6]) -> [[f64; 6]; 6] {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..6).map(|k| a[r][k] * b[k][c]).sum()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flat_direction_is_not_observed_and_the_scatter_sets_the_others() {
        // H = diag(4, 4, 4, 1, 1, 0): the last translation is flat.
        let mut h = [[0.0; 6]; 6];
        for (i, v) in [4.0, 4.0, 4.0, 1.0, 1.0, 0.0].iter().enumerate() {
            h[i][i] = *v;
        }
        let mut b = [[0.0; 6]; 6];
        for i in 0..6 {
            b[i][i] = 1.0;
        }
        let s = sandwich_sigmas(h, b, 8);
        assert!(s[5].is_infinite());
        // Rotations: H/λ² = 4/100 → H⁻¹ = 25, scaled B = 1/100 → variance 25·0.01·25, σ in
        // rad = sqrt(6.25)/10.
        assert!((s[0] - 0.25).abs() < 1e-9, "{s:?}");
        assert!((s[3] - 1.0).abs() < 1e-9, "{s:?}");
    }

    /// The floor adds in quadrature: it dominates a tiny σ, barely moves a large one and leaves
    /// an unobserved axis unobserved.
    #[test]
    fn the_floor_adds_in_quadrature() {
        let s = with_floor([0.0, 1e-3, f64::INFINITY, 0.0, 0.012, f64::INFINITY]);
        assert!((s[0] - FLOOR_DEG.to_radians()).abs() < 1e-12);
        assert!((s[1] - 1e-3f64.hypot(FLOOR_DEG.to_radians())).abs() < 1e-12);
        assert!((s[3] - FLOOR_M).abs() < 1e-12);
        assert!((s[4] - 0.013).abs() < 1e-12, "{s:?}");
        assert!(s[2].is_infinite() && s[5].is_infinite());
    }

    /// The Newton step of a quadratic `½ xᵀHx + gᵀx` lands on its minimum; an indefinite
    /// model has none.
    #[test]
    fn the_newton_step_reaches_a_quadratic_minimum() {
        let minimum = [0.01, -0.02, 0.003, 0.05, -0.01, 0.02];
        let mut hessian = [[0.0; 6]; 6];
        for (i, row) in hessian.iter_mut().enumerate() {
            row[i] = 2.0 + i as f64;
            if i + 1 < 6 {
                row[i + 1] = 0.5;
            }
            if i > 0 {
                row[i - 1] = 0.5;
            }
        }
        // At x = 0 the gradient of ½ (x − m)ᵀ H (x − m) is −H m.
        let gradient =
            std::array::from_fn(|r| -(0..6).map(|c| hessian[r][c] * minimum[c]).sum::<f64>());
        let model = LocalModel {
            hessian,
            frame_gradients: vec![gradient],
        };
        let step = model.newton_step().unwrap();
        for (s, m) in step.iter().zip(minimum) {
            assert!((s - m).abs() < 1e-12, "{step:?}");
        }
        hessian[2][2] = -1.0;
        let indefinite = LocalModel { hessian, ..model };
        assert!(indefinite.newton_step().is_none());
    }
}
