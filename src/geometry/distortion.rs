//! Lens distortion formulas of the camera models, with their Jacobians and inverses.
//!
//! The formulas are OpenCV's: `cv::projectPoints` (calib3d "Camera Calibration and 3D
//! Reconstruction" model, 8 coefficients, no tilt or thin prism) and `cv::fisheye::projectPoints`
//! (θd = θ·(1 + k1·θ² + k2·θ⁴ + k3·θ⁶ + k4·θ⁸), zero skew). Inverses are numerical: Newton with
//! step halving for radial-tangential, a bracketed Newton on the angle for the fisheye; both
//! return `None` rather than a point past the fold of the distortion.

use glam::{DVec2, DVec3};
use std::f64::consts::FRAC_PI_2;

/// Convergence threshold of the undistortion iterations, in normalised units.
const UNDISTORT_TOL: f64 = 1e-12;
const UNDISTORT_MAX_ITERS: usize = 60;

pub(crate) type Mat2 = [[f64; 2]; 2];

/// Radial-tangential distortion of normalised `xy` and its 2×2 Jacobian.
pub(crate) fn radial_tangential(c: &[f64; 8], xy: DVec2) -> (DVec2, Mat2) {
    let [k1, k2, p1, p2, k3, k4, k5, k6] = *c;
    let (x, y) = (xy.x, xy.y);
    let r2 = x * x + y * y;
    let num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    let den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6));
    let radial = num / den;
    let d_num = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
    let d_den = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2);
    let d_radial = (d_num * den - num * d_den) / (den * den); // d radial / d r²
    let distorted = DVec2::new(
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    );
    let cross = 2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y;
    let jacobian = [
        [
            radial + 2.0 * x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x,
            cross,
        ],
        [
            cross,
            radial + 2.0 * y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x,
        ],
    ];
    (distorted, jacobian)
}

/// Newton's method with step halving on [`radial_tangential`], started at the distorted point.
pub(crate) fn undistort_radial_tangential(c: &[f64; 8], target: DVec2) -> Option<DVec2> {
    let tol = UNDISTORT_TOL * target.length().max(1.0);
    let mut xy = target;
    let (mut f, mut j) = radial_tangential(c, xy);
    for _ in 0..UNDISTORT_MAX_ITERS {
        let residual = (f - target).length();
        if residual < tol {
            return (det2(&j) > 0.0).then_some(xy);
        }
        let step = solve2(&j, f - target)?;
        let mut t = 1.0;
        loop {
            let candidate = xy - step * t;
            let (fc, jc) = radial_tangential(c, candidate);
            if (fc - target).length() < residual {
                (xy, f, j) = (candidate, fc, jc);
                break;
            }
            t *= 0.5;
            if t < 1e-6 {
                return None;
            }
        }
    }
    None
}

/// `theta_d(theta)` of the equidistant model and its derivative.
pub(crate) fn fisheye_theta_d(k: [f64; 4], theta: f64) -> (f64, f64) {
    let [k1, k2, k3, k4] = k;
    let t2 = theta * theta;
    let theta_d = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))));
    let d_theta_d = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)));
    (theta_d, d_theta_d)
}

/// Equidistant projection of `p` (z > 0) to distorted normalised coordinates, and its 2×3
/// Jacobian. Works on the angle `atan2(ρ, z)` so it stays accurate close to 90° off-axis.
pub(crate) fn fisheye(k: [f64; 4], p: DVec3) -> (DVec2, [[f64; 3]; 2]) {
    let rho = p.x.hypot(p.y);
    if rho < 1e-14 * p.z {
        let iz = 1.0 / p.z;
        return (
            p.truncate() * iz,
            [[iz, 0.0, -p.x * iz * iz], [0.0, iz, -p.y * iz * iz]],
        );
    }
    let (theta_d, d_theta_d) = fisheye_theta_d(k, rho.atan2(p.z));
    let n2 = rho * rho + p.z * p.z;
    let (ux, uy) = (p.x / rho, p.y / rho);
    // Across the radial direction the image scales by c = θd/ρ, along it by a = dθd/dρ.
    let c = theta_d / rho;
    let a = d_theta_d * p.z / n2;
    let b = -d_theta_d * rho / n2; // dθd/dz
    let jacobian = [
        [c * uy * uy + a * ux * ux, ux * uy * (a - c), ux * b],
        [ux * uy * (a - c), c * ux * ux + a * uy * uy, uy * b],
    ];
    (DVec2::new(ux, uy) * theta_d, jacobian)
}

/// Angle off the optical axis whose distorted angle is `theta_d`: Newton on `[0, π/2)`, falling
/// back to bisection when a step leaves the bracket. `None` past the fold or at/after 90°.
pub(crate) fn fisheye_theta(k: [f64; 4], theta_d: f64) -> Option<f64> {
    let (mut lo, mut hi) = (0.0, FRAC_PI_2);
    let mut theta = if theta_d < hi { theta_d } else { 0.5 * hi };
    for _ in 0..UNDISTORT_MAX_ITERS {
        let (f, df) = fisheye_theta_d(k, theta);
        let residual = f - theta_d;
        if residual.abs() < UNDISTORT_TOL {
            return (df > 0.0 && theta < FRAC_PI_2).then_some(theta);
        }
        if residual > 0.0 {
            hi = theta;
        } else {
            lo = theta;
        }
        let next = theta - residual / df;
        theta = if df > 0.0 && next > lo && next < hi {
            next
        } else {
            0.5 * (lo + hi)
        };
    }
    None
}

pub(crate) fn det2(m: &Mat2) -> f64 {
    m[0][0] * m[1][1] - m[0][1] * m[1][0]
}

/// Solve `m · s = r`; `None` if `m` is singular.
pub(crate) fn solve2(m: &Mat2, r: DVec2) -> Option<DVec2> {
    let det = det2(m);
    if det.abs() < 1e-300 || !det.is_finite() {
        return None;
    }
    let s = DVec2::new(m[1][1] * r.x - m[0][1] * r.y, m[0][0] * r.y - m[1][0] * r.x) / det;
    s.is_finite().then_some(s)
}
