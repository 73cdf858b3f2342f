//! Camera intrinsics and projection models: pinhole, plumb_bob, rational_polynomial, equidistant.
//!
//! The camera frame is the OpenCV optical frame (x right, y down, z forward). Distortion
//! coefficients are stored in the order of the ROS distortion model of the same name.
//!
//! Projection divides by depth, applies the model's distortion to the normalised coordinates
//! and maps them through `fx, fy, cx, cy`, exactly as OpenCV does (the equidistant model works
//! on the angle off the optical axis, so it needs `z > 0` and stays accurate up to 90°).
//! Jacobians are analytic. Undistortion inverts the distortion numerically: Newton's method with
//! step halving for the radial-tangential models, a bracketed Newton on the angle for the
//! fisheye. It fails (`None`) rather than return a point past the fold of the distortion.

use super::distortion::{fisheye, fisheye_theta, radial_tangential, undistort_radial_tangential};
use glam::{DVec2, DVec3};
use serde::{Deserialize, Serialize};

/// Intrinsics that cannot be used: the message says which value is wrong and why.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct IntrinsicsError(String);

impl From<String> for IntrinsicsError {
    fn from(what: String) -> Self {
        Self(what)
    }
}

impl From<&str> for IntrinsicsError {
    fn from(what: &str) -> Self {
        Self(what.to_owned())
    }
}

/// Distortion model, named as in ROS `CameraInfo.distortion_model`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum CameraModel {
    /// No distortion.
    #[default]
    Pinhole,
    /// Brown–Conrady: k1, k2, p1, p2, k3.
    PlumbBob,
    /// k1, k2, p1, p2, k3, k4, k5, k6.
    RationalPolynomial,
    /// Kannala–Brandt fisheye as OpenCV `cv::fisheye`: k1, k2, k3, k4.
    Equidistant,
}

impl CameraModel {
    pub fn as_str(self) -> &'static str {
        match self {
            CameraModel::Pinhole => "pinhole",
            CameraModel::PlumbBob => "plumb_bob",
            CameraModel::RationalPolynomial => "rational_polynomial",
            CameraModel::Equidistant => "equidistant",
        }
    }

    /// Number of coefficients ROS's CameraInfo carries for the model (pinhole: plumb_bob's 5).
    pub fn ros_distortion_len(self) -> usize {
        match self {
            CameraModel::Pinhole | CameraModel::PlumbBob => 5,
            CameraModel::RationalPolynomial => 8,
            CameraModel::Equidistant => 4,
        }
    }

    /// The model and coefficients as read from a file or message: an all-zero radial-tangential
    /// distortion is a pinhole whatever the model's name (an all-zero fisheye is still a
    /// fisheye: r = f·θ, not f·tan θ). A pinhole (an empty, `none` or `pinhole` model name)
    /// given non-zero coefficients is an error: dropping them would silently mis-project the
    /// whole image, and guessing a model for them could be wrong.
    pub fn normalized(self, distortion: Vec<f64>) -> Result<(Self, Vec<f64>), IntrinsicsError> {
        let zero = distortion.iter().all(|&v| v == 0.0);
        if self == CameraModel::Pinhole && !zero {
            return Err(format!(
                "the distortion model is empty, none or pinhole, which takes no coefficients, but {} of the {} given are non-zero; name the model (plumb_bob, rational_polynomial or equidistant)",
                distortion.iter().filter(|&&v| v != 0.0).count(),
                distortion.len()
            ).into());
        }
        Ok(
            if self == CameraModel::Pinhole || (self != CameraModel::Equidistant && zero) {
                (CameraModel::Pinhole, Vec::new())
            } else {
                (self, distortion)
            },
        )
    }

    /// Parse a ROS `distortion_model` string (also accepts a few common aliases).
    pub fn parse(name: &str) -> Option<Self> {
        match name.trim().to_ascii_lowercase().as_str() {
            "" | "pinhole" | "none" => Some(Self::Pinhole),
            "plumb_bob" | "radtan" | "brown_conrady" => Some(Self::PlumbBob),
            "rational_polynomial" => Some(Self::RationalPolynomial),
            "equidistant" | "fisheye" | "kannala_brandt" => Some(Self::Equidistant),
            _ => None,
        }
    }
}

/// The largest image side [`CameraIntrinsics::validate`] accepts (px): larger than any camera
/// made, so a larger one is a mistake (a unit slip, an unset field) that would only fail later
/// as an allocation of tens of gigabytes.
pub const MAX_IMAGE_SIDE_PX: u32 = 32768;

/// Intrinsics of one camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraIntrinsics {
    pub width: u32,
    pub height: u32,
    pub model: CameraModel,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// Coefficients in the order of the ROS distortion model; missing trailing ones are zero.
    #[serde(default)]
    pub distortion: Vec<f64>,
}

/// A pixel coordinate of an image resized by `factor`, with pixel centres at integers (so a
/// point keeps its place under [`CameraIntrinsics::scaled`]): `(x + 0.5) · factor − 0.5`.
/// Plain `x · factor` puts every point a quarter of a pixel off at half size.
pub fn rescale_pixel(x: f64, factor: f64) -> f64 {
    (x + 0.5) * factor - 0.5
}

impl CameraIntrinsics {
    pub fn pinhole(width: u32, height: u32, fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Self {
            width,
            height,
            model: CameraModel::Pinhole,
            fx,
            fy,
            cx,
            cy,
            distortion: Vec::new(),
        }
    }

    /// Intrinsics from a CameraInfo message's fields (ROS 2 or Foxglove): the distortion model's
    /// name, its coefficients and the row-major `K`; validated ([`Self::validate`]).
    pub fn from_camera_info(
        width: u32,
        height: u32,
        model_name: &str,
        distortion: Vec<f64>,
        k: &[f64],
    ) -> Result<Self, IntrinsicsError> {
        if k.len() < 9 {
            return Err(format!("camera calibration K has {} values, expected 9", k.len()).into());
        }
        let model = CameraModel::parse(model_name)
            .ok_or_else(|| format!("unknown distortion_model '{model_name}'"))?;
        let (model, distortion) = model.normalized(distortion)?;
        let intrinsics = Self {
            width,
            height,
            model,
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
            distortion,
        };
        intrinsics.validate()?;
        Ok(intrinsics)
    }

    /// Whether the camera projects other than a pinhole: a fisheye model (even with every
    /// coefficient zero) or any non-zero distortion coefficient. Formats that carry K only
    /// (KITTI, nuScenes) cannot describe such a camera.
    pub fn has_lens_distortion(&self) -> bool {
        self.model == CameraModel::Equidistant || self.distortion.iter().any(|&v| v != 0.0)
    }

    /// Why these intrinsics cannot be used, if they cannot: focal lengths must be finite and
    /// positive (an uncalibrated ROS driver publishes K = 0), the principal point and every
    /// distortion coefficient finite, the image non-empty, and no more coefficients than the
    /// model has.
    pub fn validate(&self) -> Result<(), IntrinsicsError> {
        if !(self.fx.is_finite() && self.fy.is_finite() && self.fx > 0.0 && self.fy > 0.0) {
            return Err(format!(
                "focal lengths must be finite and positive (fx = {}, fy = {}); an uncalibrated camera publishes zeros",
                self.fx, self.fy
            ).into());
        }
        if !(self.cx.is_finite() && self.cy.is_finite()) {
            return Err(format!(
                "principal point must be finite (cx = {}, cy = {})",
                self.cx, self.cy
            )
            .into());
        }
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "image size must be positive ({} × {})",
                self.width, self.height
            )
            .into());
        }
        if self.width.max(self.height) > MAX_IMAGE_SIDE_PX {
            return Err(format!(
                "image size {} × {} is more than {MAX_IMAGE_SIDE_PX} px a side",
                self.width, self.height
            )
            .into());
        }
        if self.model == CameraModel::Pinhole && self.distortion.iter().any(|&v| v != 0.0) {
            return Err(
                "pinhole takes no distortion coefficients; name the model plumb_bob to use them"
                    .into(),
            );
        }
        if let Some(v) = self.distortion.iter().find(|v| !v.is_finite()) {
            return Err(format!("distortion coefficient {v} is not finite").into());
        }
        let most = self.model.ros_distortion_len();
        if self.distortion.len() > most && self.distortion[most..].iter().any(|&v| v != 0.0) {
            return Err(format!(
                "{} takes {most} distortion coefficients, got {} non-zero beyond them",
                self.model.as_str(),
                self.distortion.len() - most
            )
            .into());
        }
        Ok(())
    }

    /// The ROS `distortion_model` name and coefficients padded to its length: a pinhole is
    /// written as `plumb_bob` with five zeros, as ROS drivers do.
    pub fn ros_distortion(&self) -> (&'static str, Vec<f64>) {
        let (name, mut d) = match self.model {
            CameraModel::Pinhole => (CameraModel::PlumbBob.as_str(), Vec::new()),
            m => (m.as_str(), self.distortion.clone()),
        };
        d.resize(self.model.ros_distortion_len().max(d.len()), 0.0);
        (name, d)
    }

    /// Pixel of a point in the camera frame; `None` if it is not in front of the camera
    /// (`z <= MIN_DEPTH`). Points far outside the field of view still get a pixel (possibly a
    /// folded-over one for the polynomial models), as in OpenCV; check [`Self::in_image`].
    pub fn project(&self, point_in_camera: DVec3) -> Option<DVec2> {
        self.project_with_jacobian(point_in_camera)
            .map(|(pixel, _)| pixel)
    }

    /// [`Self::project`] and its Jacobian d(pixel)/d(point), 2×3 row-major.
    pub fn project_with_jacobian(&self, p: DVec3) -> Option<(DVec2, [[f64; 3]; 2])> {
        if p.z <= MIN_DEPTH || !p.is_finite() {
            return None;
        }
        let (distorted, d_dp) = match self.model {
            CameraModel::Equidistant => fisheye(self.fisheye_coeffs(), p),
            _ => {
                let iz = 1.0 / p.z;
                let xy = DVec2::new(p.x * iz, p.y * iz);
                let (d, j) = radial_tangential(&self.radtan_coeffs(), xy);
                // Chain through d(x, y)/dp = [[1, 0, -x], [0, 1, -y]] / z.
                let row = |r: [f64; 2]| [r[0] * iz, r[1] * iz, -(r[0] * xy.x + r[1] * xy.y) * iz];
                (d, [row(j[0]), row(j[1])])
            }
        };
        let pixel = self.pixel_from_normalized(distorted);
        let scale = |r: [f64; 3], f: f64| [r[0] * f, r[1] * f, r[2] * f];
        pixel
            .is_finite()
            .then_some((pixel, [scale(d_dp[0], self.fx), scale(d_dp[1], self.fy)]))
    }

    /// Apply the lens distortion to normalised coordinates `(x/z, y/z)`.
    pub fn distort_normalized(&self, xy: DVec2) -> DVec2 {
        match self.model {
            CameraModel::Equidistant => fisheye(self.fisheye_coeffs(), xy.extend(1.0)).0,
            _ => radial_tangential(&self.radtan_coeffs(), xy).0,
        }
    }

    /// Inverse of [`Self::distort_normalized`]; `None` if the iteration does not converge or
    /// lands beyond the point where the distortion folds over.
    pub fn undistort_normalized(&self, distorted: DVec2) -> Option<DVec2> {
        match self.model {
            CameraModel::Pinhole => Some(distorted),
            CameraModel::Equidistant => {
                let theta_d = distorted.length();
                if theta_d < AXIS_EPS {
                    return Some(distorted);
                }
                let theta = fisheye_theta(self.fisheye_coeffs(), theta_d)?;
                Some(distorted * (theta.tan() / theta_d))
            }
            _ => undistort_radial_tangential(&self.radtan_coeffs(), distorted),
        }
    }

    /// Unit ray (z > 0) in the camera frame through the centre of `pixel`.
    pub fn unproject(&self, pixel: DVec2) -> Option<DVec3> {
        let distorted = DVec2::new((pixel.x - self.cx) / self.fx, (pixel.y - self.cy) / self.fy);
        let theta_d = distorted.length();
        let ray = if self.model == CameraModel::Equidistant && theta_d >= AXIS_EPS {
            // Built from the angle directly so rays near 90° off-axis stay accurate.
            let theta = fisheye_theta(self.fisheye_coeffs(), theta_d)?;
            (distorted * (theta.sin() / theta_d)).extend(theta.cos())
        } else {
            self.undistort_normalized(distorted)?
                .extend(1.0)
                .try_normalize()?
        };
        (ray.is_finite() && ray.z > 0.0).then_some(ray)
    }

    /// Whether `pixel` is on the sensor. Pixel centres sit at integer coordinates, so the image
    /// covers `[-0.5, width - 0.5) × [-0.5, height - 0.5)`.
    pub fn in_image(&self, pixel: DVec2) -> bool {
        pixel.x >= -0.5
            && pixel.y >= -0.5
            && pixel.x < self.width as f64 - 0.5
            && pixel.y < self.height as f64 - 0.5
    }

    /// Intrinsics of the same camera with the image resized by `factor` (OpenCV pixel-centre
    /// convention: `c' = (c + 0.5) · factor - 0.5`). Distortion is unit-free and unchanged.
    pub fn scaled(&self, factor: f64) -> Self {
        let centre = |c: f64| rescale_pixel(c, factor);
        Self {
            width: (self.width as f64 * factor).round() as u32,
            height: (self.height as f64 * factor).round() as u32,
            model: self.model,
            fx: self.fx * factor,
            fy: self.fy * factor,
            cx: centre(self.cx),
            cy: centre(self.cy),
            distortion: self.distortion.clone(),
        }
    }

    fn pixel_from_normalized(&self, d: DVec2) -> DVec2 {
        DVec2::new(self.fx * d.x + self.cx, self.fy * d.y + self.cy)
    }

    /// k1, k2, p1, p2, k3, k4, k5, k6, with the ones the model does not use set to zero.
    fn radtan_coeffs(&self) -> [f64; 8] {
        let used = match self.model {
            CameraModel::PlumbBob => 5,
            CameraModel::RationalPolynomial => 8,
            CameraModel::Pinhole | CameraModel::Equidistant => 0,
        };
        let mut c = [0.0; 8];
        for (c, &d) in c.iter_mut().zip(self.distortion.iter().take(used)) {
            *c = d;
        }
        c
    }

    fn fisheye_coeffs(&self) -> [f64; 4] {
        let mut k = [0.0; 4];
        for (k, &d) in k.iter_mut().zip(&self.distortion) {
            *k = d;
        }
        k
    }
}

/// Points with `z` at or below this (camera frame, metres) are behind the camera.
const MIN_DEPTH: f64 = 1e-9;
/// Below this distorted radius (normalised units) a fisheye ray is taken as the optical axis.
const AXIS_EPS: f64 = 1e-15;
#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::distortion::{det2, fisheye_theta_d};
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn validation_names_what_is_wrong() {
        assert!(plumb_bob_wide().validate().is_ok());
        let with = |f: &dyn Fn(&mut CameraIntrinsics)| {
            let mut c = plumb_bob_wide();
            f(&mut c);
            c.validate().unwrap_err()
        };
        assert!(with(&|c| c.fx = 0.0).to_string().contains("focal"));
        assert!(
            with(&|c| c.fy = f64::INFINITY)
                .to_string()
                .contains("focal")
        );
        assert!(
            with(&|c| c.cx = f64::NAN)
                .to_string()
                .contains("principal point")
        );
        assert!(with(&|c| c.height = 0).to_string().contains("image size"));
        assert!(
            with(&|c| c.distortion[2] = f64::NAN)
                .to_string()
                .contains("not finite")
        );
        assert!(
            with(&|c| c.distortion.extend([0.0, 0.3]))
                .to_string()
                .contains("plumb_bob takes 5")
        );
        assert!(
            with(&|c| c.width = 200_000)
                .to_string()
                .contains("32768 px a side")
        );
        assert!(
            with(&|c| c.height = u32::MAX)
                .to_string()
                .contains("32768 px a side")
        );
        // A pinhole has no coefficients to use: non-zero ones are refused, zeros are fine.
        assert!(
            with(&|c| c.model = CameraModel::Pinhole)
                .to_string()
                .contains("pinhole takes no")
        );
        let mut zeros = plumb_bob_wide();
        zeros.model = CameraModel::Pinhole;
        zeros.distortion = vec![0.0; 5];
        assert!(zeros.validate().is_ok());
    }

    fn plumb_bob_wide() -> CameraIntrinsics {
        CameraIntrinsics {
            model: CameraModel::PlumbBob,
            distortion: vec![-0.27, 0.075, 6e-4, -4e-4, -0.009],
            ..CameraIntrinsics::pinhole(1920, 1080, 1050.0, 1048.5, 962.3, 538.7)
        }
    }

    fn rational() -> CameraIntrinsics {
        CameraIntrinsics {
            model: CameraModel::RationalPolynomial,
            distortion: vec![0.52, -2.6, 2e-4, -3e-4, 1.5, 0.4, -2.4, 1.45],
            ..CameraIntrinsics::pinhole(2048, 1536, 976.0, 975.2, 1022.1, 771.9)
        }
    }

    /// A ~190° lens; OpenCV's model only reaches 90° off-axis, so the image corners are invalid.
    fn fisheye_wide() -> CameraIntrinsics {
        CameraIntrinsics {
            model: CameraModel::Equidistant,
            distortion: vec![0.03, -0.005, 0.001, -2e-4],
            ..CameraIntrinsics::pinhole(1600, 1300, 395.0, 394.6, 801.2, 648.9)
        }
    }

    fn cameras() -> Vec<CameraIntrinsics> {
        let pinhole = CameraIntrinsics::pinhole(640, 480, 525.0, 523.5, 319.5, 239.5);
        vec![pinhole, plumb_bob_wide(), rational(), fisheye_wide()]
    }

    /// Directions from on-axis out to `max_deg` off-axis, all around, at assorted depths.
    fn points(max_deg: f64) -> Vec<DVec3> {
        let mut out = vec![DVec3::new(0.0, 0.0, 2.0), DVec3::new(1e-9, -2e-9, 1.0)];
        for i in 1..=24 {
            let theta = (max_deg * i as f64 / 24.0).to_radians();
            for j in 0..12 {
                let phi = (30.0 * j as f64 + 7.0 * i as f64).to_radians();
                let depth = 0.5 + 0.37 * ((i * 12 + j) % 11) as f64;
                let dir = DVec3::new(
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                );
                out.push(dir * depth);
            }
        }
        out
    }

    fn max_off_axis_deg(cam: &CameraIntrinsics) -> f64 {
        if cam.model == CameraModel::Equidistant {
            89.5
        } else {
            75.0
        }
    }

    /// Whether the radial-tangential distortion is still one-to-one between the centre and `xy`
    /// (the polynomial folds back on itself far enough out; OpenCV projects such points anyway).
    fn before_fold(cam: &CameraIntrinsics, xy: DVec2) -> bool {
        let c = cam.radtan_coeffs();
        let det_at = |s: f64| det2(&radial_tangential(&c, xy * s).1);
        cam.model == CameraModel::Equidistant || (0..=64).all(|i| det_at(i as f64 / 64.0) > 0.0)
    }

    #[test]
    fn unproject_then_project_round_trips_over_the_whole_image() {
        for cam in cameras() {
            let (w, h) = (cam.width as f64, cam.height as f64);
            for i in 0..=32 {
                for j in 0..=24 {
                    let px = DVec2::new(-0.5 + w * i as f64 / 32.0, -0.5 + h * j as f64 / 24.0);
                    let Some(ray) = cam.unproject(px) else {
                        // Only the fisheye corners, beyond 90° off-axis, have no ray.
                        let limit = fisheye_theta_d(cam.fisheye_coeffs(), FRAC_PI_2).0;
                        let d = DVec2::new((px.x - cam.cx) / cam.fx, (px.y - cam.cy) / cam.fy);
                        assert!(cam.model == CameraModel::Equidistant && d.length() > limit);
                        continue;
                    };
                    assert!((ray.length() - 1.0).abs() < 1e-12 && ray.z > 0.0);
                    let back = cam.project(ray * 7.3).unwrap_or_else(|| panic!("{px}"));
                    assert!(
                        (back - px).length() < 1e-6,
                        "{:?} {px} -> {back}",
                        cam.model
                    );
                }
            }
        }
    }

    #[test]
    fn project_then_unproject_recovers_the_direction_out_to_the_edge_of_the_fov() {
        for cam in cameras() {
            let mut checked = 0;
            for p in points(max_off_axis_deg(&cam)) {
                let px = cam.project(p).unwrap_or_else(|| panic!("{p}"));
                if !before_fold(&cam, p.truncate() / p.z) {
                    continue;
                }
                let ray = cam
                    .unproject(px)
                    .unwrap_or_else(|| panic!("{:?} {p}", cam.model));
                assert!(
                    (ray - p.normalize_or_zero()).length() < 1e-9,
                    "{:?} {p}: {ray}",
                    cam.model
                );
                checked += 1;
            }
            assert!(checked > 100, "{:?}: {checked}", cam.model);
        }
    }

    #[test]
    fn distort_and_undistort_are_inverse() {
        for cam in cameras() {
            for p in points(max_off_axis_deg(&cam)) {
                let xy = p.truncate() / p.z;
                if !before_fold(&cam, xy) {
                    continue;
                }
                let back = cam.undistort_normalized(cam.distort_normalized(xy));
                let back = back.unwrap_or_else(|| panic!("{:?} {xy}", cam.model));
                assert!(
                    (back - xy).length() < 1e-9 * xy.length().max(1.0),
                    "{:?} {xy}",
                    cam.model
                );
            }
        }
    }

    #[test]
    fn undistort_fails_beyond_the_fold() {
        // r·(1 - 0.3 r²) peaks at r_d ≈ 0.703, so r_d = 0.8 has no preimage.
        let cam = CameraIntrinsics {
            model: CameraModel::PlumbBob,
            distortion: vec![-0.3],
            ..CameraIntrinsics::pinhole(100, 100, 50.0, 50.0, 49.5, 49.5)
        };
        assert!(cam.undistort_normalized(DVec2::new(0.6, 0.2)).is_some());
        assert!(cam.undistort_normalized(DVec2::new(0.8, 0.0)).is_none());
        let fisheye = CameraIntrinsics {
            model: CameraModel::Equidistant,
            ..cam
        };
        assert!(fisheye.undistort_normalized(DVec2::new(1.6, 0.0)).is_none());
    }

    #[test]
    fn jacobian_matches_central_differences() {
        for cam in cameras() {
            for p in points(max_off_axis_deg(&cam)) {
                let (_, jac) = cam
                    .project_with_jacobian(p)
                    .unwrap_or_else(|| panic!("{p}"));
                let h = 1e-6 * p.length();
                let scale = jac.iter().flatten().fold(1.0_f64, |m, v| m.max(v.abs()));
                for k in 0..3 {
                    let mut dp = DVec3::ZERO;
                    dp[k] = h;
                    let plus = cam.project(p + dp).unwrap_or_else(|| panic!("{p}"));
                    let minus = cam.project(p - dp).unwrap_or_else(|| panic!("{p}"));
                    let fd = (plus - minus) / (2.0 * h);
                    for (row, numeric) in [fd.x, fd.y].into_iter().enumerate() {
                        let err = (jac[row][k] - numeric).abs();
                        let analytic = jac[row][k];
                        let what = format!("{:?} {p} [{row}][{k}]", cam.model);
                        assert!(err < 1e-6 * scale, "{what}: {analytic} vs {numeric}");
                    }
                }
            }
        }
    }

    #[test]
    fn zero_distortion_reads_as_pinhole_but_a_zero_fisheye_stays_a_fisheye() {
        use CameraModel::*;
        assert_eq!(PlumbBob.normalized(vec![0.0; 5]), Ok((Pinhole, vec![])));
        assert_eq!(
            RationalPolynomial.normalized(vec![0.0; 8]),
            Ok((Pinhole, vec![]))
        );
        assert_eq!(
            Equidistant.normalized(vec![0.0; 4]),
            Ok((Equidistant, vec![0.0; 4]))
        );
        assert_eq!(PlumbBob.normalized(vec![0.1]), Ok((PlumbBob, vec![0.1])));
        assert_eq!(Pinhole.normalized(vec![0.0; 5]), Ok((Pinhole, vec![])));
        // A pinhole given coefficients is refused, not silently stripped of them.
        let e = Pinhole
            .normalized(vec![0.1, 0.0, 0.0, 0.0, 0.0])
            .unwrap_err();
        assert!(
            e.to_string().contains("1 of the 5 given are non-zero"),
            "{e}"
        );
        assert!(
            CameraIntrinsics::from_camera_info(
                10,
                10,
                "",
                vec![-0.2],
                &[1., 0., 5., 0., 1., 5., 0., 0., 1.]
            )
            .is_err()
        );
        let mut c = CameraIntrinsics::pinhole(10, 10, 1.0, 1.0, 5.0, 5.0);
        assert_eq!(c.ros_distortion(), ("plumb_bob", vec![0.0; 5]));
        c.model = Equidistant;
        c.distortion = vec![0.1];
        assert_eq!(
            c.ros_distortion(),
            ("equidistant", vec![0.1, 0.0, 0.0, 0.0])
        );
    }

    #[test]
    fn points_behind_the_camera_do_not_project() {
        for cam in cameras() {
            let behind = [DVec3::NEG_Z, DVec3::X, DVec3::new(1.0, 2.0, 1e-12)];
            for p in behind {
                assert!(cam.project(p).is_none() && cam.project_with_jacobian(p).is_none());
            }
            assert!(cam.project(DVec3::new(f64::NAN, 0.0, 1.0)).is_none());
        }
    }

    #[test]
    fn scaling_follows_the_pixel_centre_convention() {
        for cam in cameras() {
            let half = cam.scaled(0.5);
            assert_eq!((half.width, half.height), (cam.width / 2, cam.height / 2));
            for p in points(30.0) {
                let (Some(a), Some(b)) = (cam.project(p), half.project(p)) else {
                    panic!("{p}")
                };
                assert!(((a + 0.5) * 0.5 - 0.5 - b).length() < 1e-9);
            }
        }
    }

    #[test]
    fn in_image_covers_pixel_areas() {
        let cam = CameraIntrinsics::pinhole(640, 480, 500.0, 500.0, 319.5, 239.5);
        assert!(cam.in_image(DVec2::new(-0.5, -0.5)) && cam.in_image(DVec2::new(639.49, 479.49)));
        assert!(!cam.in_image(DVec2::new(639.5, 10.0)) && !cam.in_image(DVec2::new(10.0, -0.51)));
        assert!(!cam.in_image(DVec2::new(f64::NAN, 10.0)));
    }
}
