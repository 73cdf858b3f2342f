//! The surface alignment distance (main Eq. 12, method.md §9) for matched pixels of two cameras,
//! with gradients into both cameras' extrinsics and into the geometry; and SC-NeRF's projected
//! ray distance, the ablation's alternative (no geometry gradient).
//!
//! For a match (u_a in camera a, u_b in camera b), each pixel's ray is rendered to its surface
//! point `p = o + D̄ d` (`D̄ = D/A`, the depth normalised by the accumulated opacity), which is
//! projected into the other camera at the time of the partner pixel's row (its frame's, for a
//! global shutter): `e_ab = ‖π_b(p_a) − u_b‖`,
//! `e_ba = ‖π_a(p_b) − u_a‖` (pixels, scaled to a 1920-pixel-wide image as the paper measures
//! them). Matches with either error above the threshold or either accumulation below 0.5 are
//! left out, and `L = (1/|M|) Σ ½ (e_ab + e_ba)`.
//!
//! Backward of `e_ab`: `∂e/∂π = r/‖r‖` through the projection's Jacobian to the point in camera
//! b's frame `q = R_bᵀ (P_b⁻¹ p − t_b)` (→ `∂L/∂t_b = −R_b g`, `∂L/∂R_b = (P_b⁻¹ p − t_b) gᵀ`,
//! then Gram–Schmidt) and to `p`: `∂L/∂o_a += ∂L/∂p`, `∂L/∂d_a += D̄ ∂L/∂p`, and
//! `∂L/∂D̄ = ∂L/∂p · d_a` into the compositing (`∂D̄/∂D = 1/A`, `∂D̄/∂A = −D/A²`) and the field.

use glam::{DVec2, DVec3};

use super::camera_rgb::march;
use super::composite::{Composite, Opacity, Upstream, composite, composite_backward};
use super::field::{FieldSample, SceneField};
use super::hash_grid::GradSink;
use super::mlp::MlpGrad;
use super::observability::PoseInformation;
use super::pose::{PoseGrad, PoseParams, rot6d_backward};
use crate::geometry::camera::CameraIntrinsics;
use crate::geometry::{Rigid, so3};

/// Which correspondence term the optimisation uses (the paper's Table A9 ablation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum AlignmentLoss {
    /// No correspondence loss.
    #[default]
    None,
    /// SC-NeRF's projected ray distance (closest points of the two rays; poses only).
    ProjectedRayDistance,
    /// UniCal's surface alignment distance (rendered surface points; poses and geometry).
    SurfaceAlignment,
}

/// One pixel's ray at its row's time (its frame's, for a global shutter).
#[derive(Clone, Debug)]
pub struct AlignRay {
    pub world_from_vehicle: Rigid,
    /// Unit direction in the camera frame.
    pub dir_in_sensor: DVec3,
    /// The matched pixel (camera's training resolution).
    pub pixel: DVec2,
    /// Sample distances along the ray.
    pub taus_m: Vec<f32>,
}

/// One camera of a pair: pose, intrinsics and the factor to 1920-pixel-wide pixels.
#[derive(Clone, Copy)]
pub struct AlignCamera<'a> {
    pub pose: &'a PoseParams,
    pub intrinsics: &'a CameraIntrinsics,
    pub pixel_scale: f64,
}

/// The term's settings.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AlignSettings {
    /// Matches with a reprojection error above this (1920-wide pixels) are left out.
    pub max_error_px: f64,
    /// Rays with less accumulated opacity are left out.
    pub min_accumulation: f32,
    /// Whether [`AlignStep::info_a`] and [`AlignStep::info_b`] are filled (only the hold of
    /// poorly observed directions reads them).
    pub information: bool,
}

impl AlignmentLoss {
    /// The row names of the paper's Table A9.
    pub fn label(self) -> &'static str {
        match self {
            AlignmentLoss::None => "No",
            AlignmentLoss::ProjectedRayDistance => "Projected Ray Dist",
            AlignmentLoss::SurfaceAlignment => "Surface Alignment Dist",
        }
    }
}

impl std::str::FromStr for AlignmentLoss {
    type Err = crate::error::ParseError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text {
            "none" => Ok(AlignmentLoss::None),
            "ray-distance" => Ok(AlignmentLoss::ProjectedRayDistance),
            "surface" => Ok(AlignmentLoss::SurfaceAlignment),
            other => Err(format!(
                "unknown --alignment '{other}' (expected none, ray-distance or surface)"
            )
            .into()),
        }
    }
}

impl Default for AlignSettings {
    fn default() -> Self {
        Self {
            max_error_px: 50.0,
            min_accumulation: 0.5,
            information: false,
        }
    }
}

/// Loss and gradients of a batch of matches between cameras a and b.
#[derive(Debug, Default)]
pub struct AlignStep {
    /// Mean of ½(e_ab + e_ba) over the matches kept (1920-wide pixels).
    pub loss: f64,
    pub kept: usize,
    pub geo: MlpGrad,
    pub beta_grad: f64,
    pub pose_a: PoseGrad,
    pub pose_b: PoseGrad,
    /// What the kept reprojections into each camera observe of its pose
    /// ([`super::observability`]); empty unless [`AlignSettings::information`] is set.
    pub info_a: PoseInformation,
    pub info_b: PoseInformation,
}

/// A rendered ray: its samples, composite and surface point.
struct Rendered {
    d: DVec3,
    samples: Vec<FieldSample>,
    alphas: Vec<f32>,
    /// Where each sample's weight sits along the ray.
    at: Vec<f32>,
    composite: Composite,
    depth_m: f64,
    point: DVec3,
}

fn render(field: &SceneField, opacity: Opacity, pose: &PoseParams, ray: &AlignRay) -> Rendered {
    let (o, d) = pose.ray(ray.world_from_vehicle, ray.dir_in_sensor);
    let (mut alphas, mut at, mut transmittance) = (Vec::new(), Vec::new(), 1.0f32);
    let samples = march(
        &|x| field.query_many(x),
        (o, d),
        &ray.taus_m,
        opacity,
        (&mut alphas, &mut at),
        &mut transmittance,
    );
    let composite = composite(&alphas, &at, &[], 0);
    let depth_m = composite.depth_m as f64 / (composite.accumulation as f64).max(1e-6);
    Rendered {
        d,
        samples,
        alphas,
        at,
        composite,
        depth_m,
        point: o + d * depth_m,
    }
}

/// Where world point `p` lands in `camera` at `world_from_vehicle`: the pixel, the Jacobian
/// (2×3) and the point in the vehicle and camera frames.
fn project(
    camera: AlignCamera,
    world_from_vehicle: Rigid,
    p: DVec3,
) -> Option<(DVec2, [[f64; 3]; 2], DVec3, DVec3)> {
    let in_vehicle = world_from_vehicle.inverse().transform_point(p);
    let rotation = camera.pose.rotation();
    let q = rotation.transpose() * (in_vehicle - camera.pose.translation_m);
    let (pixel, jacobian) = camera.intrinsics.project_with_jacobian(q)?;
    Some((pixel, jacobian, in_vehicle, q))
}

/// One direction of a match (`from`'s surface point into `to`): error (scaled pixels) and
/// what its backward pass needs.
struct Reprojection {
    error_px: f64,
    residual: DVec2,
    jacobian: [[f64; 3]; 2],
    in_vehicle: DVec3,
}

fn reproject(from: &Rendered, to: AlignCamera, to_ray: &AlignRay) -> Option<Reprojection> {
    let (pixel, jacobian, in_vehicle, _) = project(to, to_ray.world_from_vehicle, from.point)?;
    let residual = pixel - to_ray.pixel;
    Some(Reprojection {
        error_px: residual.length() * to.pixel_scale,
        residual,
        jacobian,
        in_vehicle,
    })
}

/// The surface alignment distance of `matches` (pairs of rays of cameras a and b); the hash
/// table's gradients go to `grid`.
pub fn surface_alignment_step(
    field: &SceneField,
    opacity: Opacity,
    (cam_a, cam_b): (AlignCamera, AlignCamera),
    matches: &[(AlignRay, AlignRay)],
    settings: &AlignSettings,
    grid: &mut impl GradSink,
) -> AlignStep {
    let mut out = AlignStep {
        geo: field.geo.zero_grad(),
        ..AlignStep::default()
    };
    // Forward every match, then keep those that pass the filters.
    let mut kept = Vec::new();
    for (ray_a, ray_b) in matches {
        let ra = render(field, opacity, cam_a.pose, ray_a);
        let rb = render(field, opacity, cam_b.pose, ray_b);
        if ra.composite.accumulation < settings.min_accumulation
            || rb.composite.accumulation < settings.min_accumulation
        {
            continue;
        }
        let (Some(ab), Some(ba)) = (reproject(&ra, cam_b, ray_b), reproject(&rb, cam_a, ray_a))
        else {
            continue;
        };
        if ab.error_px > settings.max_error_px || ba.error_px > settings.max_error_px {
            continue;
        }
        kept.push((ray_a, ray_b, ra, rb, ab, ba));
    }
    if kept.is_empty() {
        return out;
    }
    let w = 0.5 / kept.len() as f64;
    for (ray_a, ray_b, ra, rb, ab, ba) in &kept {
        out.loss += w * (ab.error_px + ba.error_px);
        if settings.information {
            add_information(&mut out.info_b, cam_b, ab);
            add_information(&mut out.info_a, cam_a, ba);
        }
        // e_ab: a's surface into b; e_ba: b's surface into a.
        let (ga, gb) = backward_direction(
            field,
            opacity,
            (cam_a, ray_a, ra),
            (cam_b, ray_b),
            ab,
            w,
            grid,
            &mut out.geo,
        );
        out.pose_a.add(&ga.0);
        out.pose_b.add(&gb);
        out.beta_grad += ga.1;
        let (gb2, ga2) = backward_direction(
            field,
            opacity,
            (cam_b, ray_b, rb),
            (cam_a, ray_a),
            ba,
            w,
            grid,
            &mut out.geo,
        );
        out.pose_b.add(&gb2.0);
        out.pose_a.add(&ga2);
        out.beta_grad += gb2.1;
    }
    out.kept = kept.len();
    out
}

/// One reprojection's information about the pose of the camera it lands in.
fn add_information(info: &mut PoseInformation, to: AlignCamera, reprojection: &Reprojection) {
    let scale = to.pixel_scale;
    let jacobian = reprojection.jacobian.map(|row| row.map(|x| x * scale));
    info.add_reprojection(
        jacobian,
        to.pose.rotation(),
        reprojection.in_vehicle - to.pose.translation_m,
    );
}

/// Backward of `weight · e` for the reprojection of `from`'s surface point into `to`:
/// `((pose gradient of from, ∂L/∂β), pose gradient of to)`.
fn backward_direction(
    field: &SceneField,
    opacity: Opacity,
    (from_cam, from_ray, rendered): (AlignCamera, &AlignRay, &Rendered),
    (to_cam, to_ray): (AlignCamera, &AlignRay),
    reprojection: &Reprojection,
    weight: f64,
    grid: &mut impl GradSink,
    geo: &mut MlpGrad,
) -> ((PoseGrad, f64), PoseGrad) {
    let r = reprojection.residual;
    let norm = r.length();
    if norm <= 0.0 {
        return ((PoseGrad::default(), 0.0), PoseGrad::default());
    }
    let g_pixel = r * (weight * to_cam.pixel_scale / norm);
    let j = reprojection.jacobian;
    let g_q = DVec3::new(
        j[0][0] * g_pixel.x + j[1][0] * g_pixel.y,
        j[0][1] * g_pixel.x + j[1][1] * g_pixel.y,
        j[0][2] * g_pixel.x + j[1][2] * g_pixel.y,
    );
    // Camera `to`: q = R_toᵀ (x − t_to), x the point in the vehicle frame.
    let rotation_to = to_cam.pose.rotation();
    let x = reprojection.in_vehicle - to_cam.pose.translation_m;
    let d_rotation = so3::outer(x, g_q);
    let to_grad = PoseGrad {
        r6: rot6d_backward(to_cam.pose.r6, d_rotation),
        translation_m: -(rotation_to * g_q),
    };
    // The point p = o + D̄ d in the world.
    let g_p = to_ray.world_from_vehicle.rotation_matrix() * (rotation_to * g_q);
    let d_depth_bar = g_p.dot(rendered.d);
    let a = (rendered.composite.accumulation as f64).max(1e-6);
    let up = Upstream {
        depth: (d_depth_bar / a) as f32,
        accumulation: (-rendered.composite.depth_m as f64 / (a * a) * d_depth_bar) as f32,
        ..Upstream::default()
    };
    let taus = &from_ray.taus_m[..rendered.samples.len()];
    let (d_alpha, _) = composite_backward(
        &rendered.alphas,
        &rendered.at,
        &[],
        0,
        &rendered.composite,
        &up,
    );
    let (d_o, d_d, d_beta) = field.ray_backward(
        &rendered.samples,
        taus,
        opacity,
        (&d_alpha, &[]),
        grid,
        geo,
        None,
    );
    let from_grad = from_cam.pose.ray_backward(
        from_ray.world_from_vehicle,
        from_ray.dir_in_sensor,
        g_p + d_o,
        g_p * rendered.depth_m + d_d,
    );
    ((from_grad, d_beta), to_grad)
}

/// SC-NeRF's projected ray distance of one match: the closest points of the two rays, each
/// projected into the other camera, `½ (‖π_b(x_a) − u_b‖² + ‖π_a(x_b) − u_a‖²)` in 1920-wide
/// pixels; `None` for parallel rays, points behind a camera or errors above `max_error_px`.
pub fn projected_ray_distance(
    (cam_a, cam_b): (AlignCamera, AlignCamera),
    (ray_a, ray_b): (&AlignRay, &AlignRay),
    max_error_px: f64,
) -> Option<f64> {
    let (oa, da) = cam_a
        .pose
        .ray(ray_a.world_from_vehicle, ray_a.dir_in_sensor);
    let (ob, db) = cam_b
        .pose
        .ray(ray_b.world_from_vehicle, ray_b.dir_in_sensor);
    // Closest points of o_a + s d_a and o_b + t d_b (unit directions).
    let w0 = oa - ob;
    let b = da.dot(db);
    let (d, e) = (da.dot(w0), db.dot(w0));
    let denom = 1.0 - b * b;
    if denom < 1e-9 {
        return None;
    }
    let s = (b * e - d) / denom;
    let t = (e - b * d) / denom;
    let (xa, xb) = (oa + da * s, ob + db * t);
    let (pb, ..) = project(cam_b, ray_b.world_from_vehicle, xa)?;
    let (pa, ..) = project(cam_a, ray_a.world_from_vehicle, xb)?;
    let eb = (pb - ray_b.pixel).length() * cam_b.pixel_scale;
    let ea = (pa - ray_a.pixel).length() * cam_a.pixel_scale;
    (eb <= max_error_px && ea <= max_error_px).then_some(0.5 * (eb * eb + ea * ea))
}

/// Mean projected ray distance of `matches` and its pose gradients by central differences (a
/// closed form of a few dozen operations per match: differences cost little and are exact
/// enough for the ablation baseline).
pub fn projected_ray_step(
    (cam_a, cam_b): (AlignCamera, AlignCamera),
    matches: &[(AlignRay, AlignRay)],
    max_error_px: f64,
) -> AlignStep {
    let mean = |pa: &PoseParams, pb: &PoseParams, keep: &[bool]| -> f64 {
        let (ca, cb) = (
            AlignCamera { pose: pa, ..cam_a },
            AlignCamera { pose: pb, ..cam_b },
        );
        let n = keep.iter().filter(|k| **k).count().max(1) as f64;
        matches
            .iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .filter_map(|(m, _)| projected_ray_distance((ca, cb), (&m.0, &m.1), f64::INFINITY))
            .sum::<f64>()
            / n
    };
    let keep: Vec<bool> = matches
        .iter()
        .map(|m| projected_ray_distance((cam_a, cam_b), (&m.0, &m.1), max_error_px).is_some())
        .collect();
    let kept = keep.iter().filter(|k| **k).count();
    let mut out = AlignStep {
        loss: if kept > 0 {
            mean(cam_a.pose, cam_b.pose, &keep)
        } else {
            0.0
        },
        kept,
        ..AlignStep::default()
    };
    if kept == 0 {
        return out;
    }
    let eps = 1e-6;
    for which in 0..2 {
        for k in 0..9 {
            let nudge = |sign: f64| {
                let (mut pa, mut pb) = (*cam_a.pose, *cam_b.pose);
                let p = if which == 0 { &mut pa } else { &mut pb };
                if k < 6 {
                    p.r6[k] += sign * eps;
                } else {
                    p.translation_m[k - 6] += sign * eps;
                }
                mean(&pa, &pb, &keep)
            };
            let g = (nudge(1.0) - nudge(-1.0)) / (2.0 * eps);
            let target = if which == 0 {
                &mut out.pose_a
            } else {
                &mut out.pose_b
            };
            if k < 6 {
                target.r6[k] = g;
            } else {
                target.translation_m[k - 6] = g;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::field::tiny_field;
    use super::super::pose::assert_pose_gradient;
    use super::*;
    use crate::unical::composite::OpacityModel;
    use crate::unical::hash_grid::SparseGrad;
    use glam::{DMat3, DQuat};

    /// Two forward-looking cameras 1 m apart watching a field; matches are the true
    /// projections of points at 6–9 m (so the errors are small but not zero).
    fn setup_with(
        offset: DVec2,
    ) -> (
        SceneField,
        PoseParams,
        PoseParams,
        CameraIntrinsics,
        Vec<(AlignRay, AlignRay)>,
    ) {
        let field = tiny_field(3, 4.0, 20.0);
        // Optical frame looking along the vehicle's +x: z_cam = x_vehicle.
        let look_forward = DQuat::from_mat3(&DMat3::from_cols(
            DVec3::new(0.0, -1.0, 0.0),
            DVec3::new(0.0, 0.0, -1.0),
            DVec3::new(1.0, 0.0, 0.0),
        ));
        let pose_a = PoseParams::from_rigid(Rigid::new(look_forward, DVec3::new(1.0, 0.5, 1.5)));
        let pose_b = PoseParams::from_rigid(Rigid::new(
            DQuat::from_rotation_z(-0.2) * look_forward,
            DVec3::new(1.0, -0.5, 1.5),
        ));
        let intrinsics = CameraIntrinsics::pinhole(320, 240, 300.0, 300.0, 160.0, 120.0);
        let wv_a = Rigid::new(DQuat::from_rotation_z(0.05), DVec3::new(0.0, 0.0, 0.0));
        let wv_b = Rigid::new(DQuat::from_rotation_z(0.02), DVec3::new(0.4, 0.1, 0.0));
        // The tiny field is solid everywhere: samples start at 5.5 m so the rendered surface
        // lies a few soft samples in, in front of both cameras.
        let taus: Vec<f32> = (55..100).map(|k| k as f32 * 0.1).collect();
        let matches = (0..6)
            .filter_map(|i| {
                let p = DVec3::new(
                    6.0 + i as f64 * 0.5,
                    -1.0 + 0.4 * i as f64,
                    1.0 + 0.1 * i as f64,
                );
                let ray = |pose: &PoseParams, wv: Rigid| -> Option<AlignRay> {
                    let q = pose.rotation().transpose()
                        * (wv.inverse().transform_point(p) - pose.translation_m);
                    let pixel = intrinsics.project(q)? + offset;
                    Some(AlignRay {
                        world_from_vehicle: wv,
                        dir_in_sensor: intrinsics.unproject(pixel)?,
                        pixel,
                        taus_m: taus.clone(),
                    })
                };
                Some((ray(&pose_a, wv_a)?, ray(&pose_b, wv_b)?))
            })
            .collect();
        (field, pose_a, pose_b, intrinsics, matches)
    }

    fn setup() -> (
        SceneField,
        PoseParams,
        PoseParams,
        CameraIntrinsics,
        Vec<(AlignRay, AlignRay)>,
    ) {
        setup_with(DVec2::new(1.5, -0.7))
    }

    fn settings() -> AlignSettings {
        AlignSettings {
            max_error_px: f64::INFINITY,
            min_accumulation: 0.0,
            information: false,
        }
    }

    /// The information is gathered only when asked, one reprojection per kept match into
    /// each camera, and asking changes nothing else of the step.
    #[test]
    fn information_is_gathered_only_when_asked() {
        let (field, pose_a, pose_b, k, matches) = setup();
        let cam = |pose| AlignCamera {
            pose,
            intrinsics: &k,
            pixel_scale: 6.0,
        };
        let opacity = Opacity {
            model: OpacityModel::PerSample,
            beta: 0.5,
        };
        let run = |information: bool| {
            surface_alignment_step(
                &field,
                opacity,
                (cam(&pose_a), cam(&pose_b)),
                &matches,
                &AlignSettings {
                    information,
                    ..settings()
                },
                &mut SparseGrad::default(),
            )
        };
        let (off, on) = (run(false), run(true));
        assert_eq!(off.info_a, PoseInformation::default());
        assert_eq!(off.info_b, PoseInformation::default());
        assert_eq!(on.kept, matches.len());
        assert_eq!(on.info_a.count, on.kept as f64);
        assert_eq!(on.info_b.count, on.kept as f64);
        let strongest = |info: &PoseInformation| info.directions()[5].0;
        assert!(strongest(&on.info_a) > 0.0 && strongest(&on.info_b) > 0.0);
        assert_eq!((on.loss, on.kept), (off.loss, off.kept));
        assert_eq!((on.pose_a.r6, on.pose_b.r6), (off.pose_a.r6, off.pose_b.r6));
    }

    #[test]
    fn surface_alignment_pose_gradients_match_finite_differences() {
        for model in [OpacityModel::PerSample, OpacityModel::Interval] {
            surface_alignment_pose_gradients_of(Opacity { model, beta: 0.5 });
        }
    }

    fn surface_alignment_pose_gradients_of(opacity: Opacity) {
        let (field, pose_a, pose_b, k, matches) = setup();
        fn cam<'a>(pose: &'a PoseParams, k: &'a CameraIntrinsics) -> AlignCamera<'a> {
            AlignCamera {
                pose,
                intrinsics: k,
                pixel_scale: 6.0,
            }
        }
        let step = surface_alignment_step(
            &field,
            opacity,
            (cam(&pose_a, &k), cam(&pose_b, &k)),
            &matches,
            &settings(),
            &mut SparseGrad::default(),
        );
        assert_eq!(step.kept, matches.len());
        assert!(step.loss > 1.0, "{}", step.loss);
        let loss = |pa: &PoseParams, pb: &PoseParams| {
            surface_alignment_step(
                &field,
                opacity,
                (cam(pa, &k), cam(pb, &k)),
                &matches,
                &settings(),
                &mut SparseGrad::default(),
            )
            .loss
        };
        // 1 % of the largest component: the field is f32, the pose moves its samples.
        let tol = |g: &PoseGrad| {
            let m = g.r6.iter().map(|v| v.abs()).fold(0.0, f64::max);
            0.01 * m.max(g.translation_m.abs().max_element())
        };
        assert_pose_gradient(pose_a, &step.pose_a, 1e-4, tol(&step.pose_a), |p| {
            loss(p, &pose_b)
        });
        assert_pose_gradient(pose_b, &step.pose_b, 1e-4, tol(&step.pose_b), |p| {
            loss(&pose_a, p)
        });
    }

    #[test]
    fn surface_alignment_geometry_gradients_match_finite_differences() {
        for model in [OpacityModel::PerSample, OpacityModel::Interval] {
            surface_alignment_geometry_gradients_of(Opacity { model, beta: 0.5 });
        }
    }

    fn surface_alignment_geometry_gradients_of(opacity: Opacity) {
        let (field, pose_a, pose_b, k, matches) = setup();
        let cam = |pose| AlignCamera {
            pose,
            intrinsics: &k,
            pixel_scale: 1.0,
        };
        let mut grid = SparseGrad::default();
        let step = surface_alignment_step(
            &field,
            opacity,
            (cam(&pose_a), cam(&pose_b)),
            &matches,
            &settings(),
            &mut grid,
        );
        grid.merge();
        let mut touched: Vec<(usize, [f32; 2])> = grid
            .entries
            .iter()
            .map(|(i, g)| (*i as usize, *g))
            .collect();
        touched.sort_by(|a, b| {
            (b.1[0].abs() + b.1[1].abs()).total_cmp(&(a.1[0].abs() + a.1[1].abs()))
        });
        assert!(!touched.is_empty() && touched[0].1[0].abs() + touched[0].1[1].abs() > 0.0);
        for (entry, g) in touched.iter().take(4) {
            for f in 0..2 {
                let eps = 1e-2f32;
                let at = |delta: f32| {
                    let mut moved = field.clone();
                    moved.grid.params[entry * 2 + f] += delta;
                    surface_alignment_step(
                        &moved,
                        opacity,
                        (cam(&pose_a), cam(&pose_b)),
                        &matches,
                        &settings(),
                        &mut SparseGrad::default(),
                    )
                    .loss
                };
                let fd = (at(eps) - at(-eps)) / (2.0 * eps as f64);
                let an = g[f] as f64;
                assert!(
                    (fd - an).abs() < 2e-2 * an.abs().max(0.05),
                    "entry {entry}[{f}]: {fd} vs {an}"
                );
            }
        }
        assert!(step.geo.weights.iter().any(|l| l.iter().any(|w| *w != 0.0)));
    }

    #[test]
    fn filters_drop_large_errors_and_thin_rays() {
        let (field, pose_a, pose_b, k, matches) = setup();
        let cam = |pose| AlignCamera {
            pose,
            intrinsics: &k,
            pixel_scale: 1.0,
        };
        let strict = AlignSettings {
            max_error_px: 1e-3,
            min_accumulation: 0.0,
            information: false,
        };
        let none = surface_alignment_step(
            &field,
            Opacity {
                model: OpacityModel::PerSample,
                beta: 0.5,
            },
            (cam(&pose_a), cam(&pose_b)),
            &matches,
            &strict,
            &mut SparseGrad::default(),
        );
        assert_eq!((none.kept, none.loss), (0, 0.0));
        let opaque_only = AlignSettings {
            max_error_px: f64::INFINITY,
            min_accumulation: 1.01,
            information: false,
        };
        let none = surface_alignment_step(
            &field,
            Opacity {
                model: OpacityModel::PerSample,
                beta: 0.5,
            },
            (cam(&pose_a), cam(&pose_b)),
            &matches,
            &opaque_only,
            &mut SparseGrad::default(),
        );
        assert_eq!(none.kept, 0);
    }

    #[test]
    fn projected_ray_distance_is_zero_for_exact_matches_and_its_gradient_matches() {
        // Exact matches: both rays pass through the same point.
        let (_, pose_a, pose_b, k, matches) = setup_with(DVec2::ZERO);
        let cam = |pose| AlignCamera {
            pose,
            intrinsics: &k,
            pixel_scale: 1.0,
        };
        let step = projected_ray_step((cam(&pose_a), cam(&pose_b)), &matches, 50.0);
        assert_eq!(step.kept, matches.len());
        assert!(step.loss < 1e-12, "{}", step.loss);
        // Moving camera b breaks it.
        let mut moved = pose_b;
        moved.translation_m.z += 0.05;
        let worse = projected_ray_step((cam(&pose_a), cam(&moved)), &matches, 50.0);
        assert!(worse.loss > step.loss, "{} vs {}", worse.loss, step.loss);
        let g = worse.pose_b.translation_m.length();
        assert!(g > 0.0);
    }
}
