//! The pose of a planar target from its image (planar PnP): `camera_from_target` from points on
//! the target's plane (z = 0 in the target frame) and their pixels.
//!
//! How it works: pixels are undistorted through the camera model to normalised coordinates;
//! the homography from the plane to them is the null vector of the DLT system (Hartley's
//! normalisation, the smallest eigenvector of `AᵀA` by Jacobi rotations); `H ∝ [r1 r2 t]`
//! gives a first rotation (made orthonormal through a quaternion) and translation in front of
//! the camera; Levenberg–Marquardt then minimises the pixel reprojection error through the full
//! camera model (distortion included), six parameters perturbing the pose on the right.

use glam::{DMat3, DQuat, DVec2, DVec3};

use super::Rigid;
use super::camera::CameraIntrinsics;
use super::spd::{solve6, symmetric_eigen};

/// A planar target's pose and how well it explains the pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarPose {
    pub camera_from_target: Rigid,
    /// Root-mean-square pixel reprojection error.
    pub rms_px: f64,
}

/// `camera_from_target` for target-plane points `plane_m` (x, y on z = 0) seen at `pixels`;
/// `None` with fewer than four points, a degenerate layout or points the camera model cannot
/// unproject.
pub fn planar_pose(
    intrinsics: &CameraIntrinsics,
    plane_m: &[DVec2],
    pixels: &[DVec2],
) -> Option<PlanarPose> {
    if plane_m.len() != pixels.len() || plane_m.len() < 4 {
        return None;
    }
    let normalised: Vec<DVec2> = pixels
        .iter()
        .map(|p| {
            let ray = intrinsics.unproject(*p)?;
            (ray.z > 1e-9).then(|| DVec2::new(ray.x / ray.z, ray.y / ray.z))
        })
        .collect::<Option<_>>()?;
    let h = homography(plane_m, &normalised)?;
    let initial = decompose(&h)?;
    Some(refine(intrinsics, plane_m, pixels, initial))
}

/// A similarity that moves points to their centroid with mean distance √2 (Hartley).
fn normaliser(points: &[DVec2]) -> (DVec2, f64) {
    let c = points.iter().copied().sum::<DVec2>() / points.len() as f64;
    let d = points.iter().map(|p| (*p - c).length()).sum::<f64>() / points.len() as f64;
    (c, std::f64::consts::SQRT_2 / d.max(1e-12))
}

/// The homography (row-major) taking `from` to `to` by the normalised DLT.
fn homography(from: &[DVec2], to: &[DVec2]) -> Option<DMat3> {
    let (cf, sf) = normaliser(from);
    let (ct, st) = normaliser(to);
    let mut ata = [[0.0f64; 9]; 9];
    for (a, b) in from.iter().zip(to) {
        let (x, y) = ((*a - cf) * sf).into();
        let (u, v) = ((*b - ct) * st).into();
        let rows = [
            [-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u],
            [0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v],
        ];
        for r in rows {
            for i in 0..9 {
                for j in 0..9 {
                    ata[i][j] += r[i] * r[j];
                }
            }
        }
    }
    let (values, vectors) = symmetric_eigen(ata);
    let k = (0..9).min_by(|&i, &j| values[i].total_cmp(&values[j]))?;
    let hn: Vec<f64> = (0..9).map(|i| vectors[i][k]).collect();
    // glam matrices are column-major: build from rows.
    let hn = DMat3::from_cols_array(&[
        hn[0], hn[3], hn[6], hn[1], hn[4], hn[7], hn[2], hn[5], hn[8],
    ]);
    // Undo the normalisations: H = Tt⁻¹ Hn Tf.
    let tf = DMat3::from_cols_array(&[sf, 0.0, 0.0, 0.0, sf, 0.0, -sf * cf.x, -sf * cf.y, 1.0]);
    let tt_inv = DMat3::from_cols_array(&[1.0 / st, 0.0, 0.0, 0.0, 1.0 / st, 0.0, ct.x, ct.y, 1.0]);
    let h = tt_inv * hn * tf;
    h.is_finite().then_some(h)
}

/// `[r1 r2 t] ∝ H`, with the target in front of the camera.
fn decompose(h: &DMat3) -> Option<Rigid> {
    let (h1, h2, h3) = (h.x_axis, h.y_axis, h.z_axis);
    let scale = 2.0 / (h1.length() + h2.length());
    if !scale.is_finite() {
        return None;
    }
    let sign = if h3.z < 0.0 { -1.0 } else { 1.0 };
    let (r1, r2, t) = (h1 * scale * sign, h2 * scale * sign, h3 * scale * sign);
    let r3 = r1.cross(r2);
    let rotation = DQuat::from_mat3(&DMat3::from_cols(r1, r2, r3)).normalize();
    rotation.is_finite().then(|| Rigid::new(rotation, t))
}

fn residuals(
    intrinsics: &CameraIntrinsics,
    pose: Rigid,
    plane_m: &[DVec2],
    pixels: &[DVec2],
) -> Option<Vec<f64>> {
    let mut out = Vec::with_capacity(2 * pixels.len());
    for (p, u) in plane_m.iter().zip(pixels) {
        let pc = pose.transform_point(DVec3::new(p.x, p.y, 0.0));
        if pc.z <= 1e-6 {
            return None;
        }
        let q = intrinsics.project(pc)?;
        out.extend([q.x - u.x, q.y - u.y]);
    }
    Some(out)
}

fn refine(
    intrinsics: &CameraIntrinsics,
    plane_m: &[DVec2],
    pixels: &[DVec2],
    initial: Rigid,
) -> PlanarPose {
    let cost = |pose: Rigid| {
        residuals(intrinsics, pose, plane_m, pixels)
            .map_or(f64::INFINITY, |r| r.iter().map(|v| v * v).sum::<f64>())
    };
    let moved = |pose: Rigid, x: &[f64; 6]| {
        pose.perturbed_right(DVec3::new(x[0], x[1], x[2]), DVec3::new(x[3], x[4], x[5]))
    };
    let mut pose = initial;
    let mut current = cost(pose);
    let mut lambda = 1e-3;
    for _ in 0..50 {
        let Some(r0) = residuals(intrinsics, pose, plane_m, pixels) else {
            break;
        };
        // Jacobian by central differences (6 columns).
        let mut jac = vec![[0.0f64; 6]; r0.len()];
        let eps = 1e-6;
        for k in 0..6 {
            let mut d = [0.0; 6];
            d[k] = eps;
            let up = residuals(intrinsics, moved(pose, &d), plane_m, pixels);
            d[k] = -eps;
            let down = residuals(intrinsics, moved(pose, &d), plane_m, pixels);
            let (Some(up), Some(down)) = (up, down) else {
                return PlanarPose {
                    camera_from_target: pose,
                    rms_px: (current / pixels.len() as f64).sqrt(),
                };
            };
            for (row, (a, b)) in jac.iter_mut().zip(up.iter().zip(&down)) {
                row[k] = (a - b) / (2.0 * eps);
            }
        }
        let mut h = [0.0f64; 36];
        let mut g = [0.0f64; 6];
        for (row, r) in jac.iter().zip(&r0) {
            for i in 0..6 {
                g[i] -= row[i] * r;
                for j in 0..6 {
                    h[i * 6 + j] += row[i] * row[j];
                }
            }
        }
        let mut improved = false;
        for _ in 0..10 {
            let mut damped = h;
            for i in 0..6 {
                damped[i * 6 + i] *= 1.0 + lambda;
            }
            let Some(step) = solve6(damped, g) else {
                lambda *= 10.0;
                continue;
            };
            let candidate = moved(pose, &step);
            let c = cost(candidate);
            if c < current {
                let gain = current - c;
                pose = candidate;
                current = c;
                lambda = (lambda * 0.3).max(1e-9);
                improved = gain > 1e-14 * current.max(1e-30);
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    PlanarPose {
        camera_from_target: pose,
        rms_px: (current / pixels.len() as f64).sqrt(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::camera::CameraModel;

    fn camera(distorted: bool) -> CameraIntrinsics {
        let mut c = CameraIntrinsics::pinhole(1920, 1080, 1400.0, 1400.0, 960.0, 540.0);
        if distorted {
            c.model = CameraModel::PlumbBob;
            c.distortion = vec![-0.12, 0.03, 0.001, -0.0005, 0.0];
        }
        c
    }

    fn board() -> Vec<DVec2> {
        (1..6)
            .flat_map(|j| {
                (1..8).map(move |i| DVec2::new((i as f64 - 4.0) * 0.1, (j as f64 - 3.0) * 0.1))
            })
            .collect()
    }

    #[test]
    fn recovers_a_known_pose_with_and_without_distortion() {
        for distorted in [false, true] {
            let cam = camera(distorted);
            for truth in [
                Rigid::new(
                    DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.4, 0.2),
                    DVec3::new(0.4, -0.2, 4.0),
                ),
                Rigid::new(DQuat::from_rotation_y(2.6), DVec3::new(-1.0, 0.5, 7.0)),
            ] {
                let plane = board();
                let pixels: Vec<DVec2> = plane
                    .iter()
                    .map(|p| cam.project(truth.transform_point(DVec3::new(p.x, p.y, 0.0))))
                    .collect::<Option<_>>()
                    .unwrap_or_default();
                assert_eq!(pixels.len(), plane.len());
                let found = planar_pose(&cam, &plane, &pixels);
                let found = found.map_or(Rigid::IDENTITY, |f| f.camera_from_target);
                let (r, t) = truth.difference(found);
                assert!(
                    r < 1e-7 && t < 1e-7,
                    "distorted {distorted}: {r} rad, {t} m"
                );
            }
        }
    }

    #[test]
    fn noisy_corners_give_a_close_pose_and_their_rms() {
        let cam = camera(true);
        let truth = Rigid::new(DQuat::from_rotation_x(0.5), DVec3::new(0.2, 0.1, 5.0));
        let plane = board();
        let pixels: Vec<DVec2> = plane
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let noise =
                    DVec2::new(((k * 37) % 7) as f64 - 3.0, ((k * 11) % 5) as f64 - 2.0) * 0.1;
                cam.project(truth.transform_point(DVec3::new(p.x, p.y, 0.0)))
                    .map(|q| q + noise)
            })
            .collect::<Option<_>>()
            .unwrap_or_default();
        let found = planar_pose(&cam, &plane, &pixels);
        let Some(found) = found else {
            panic!("no pose");
        };
        let (r, t) = truth.difference(found.camera_from_target);
        assert!(r < 0.01 && t < 0.01, "{r} rad, {t} m");
        assert!(
            found.rms_px > 0.05 && found.rms_px < 0.3,
            "{}",
            found.rms_px
        );
        assert!(planar_pose(&cam, &plane[..3], &pixels[..3]).is_none());
    }
}
