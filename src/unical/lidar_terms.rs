//! The LiDAR terms of the objective (method.md §6 and §8) for a batch of one LiDAR's rays:
//! depth (`L_depth`, main Eq. 5), intensity (`L_int`) and the SDF regulariser (`L_reg`, see
//! [`super::regulariser`]), with gradients for the scene, the intensity decoder, the sensor's
//! intensity mapping and its pose.
//!
//! A ray is a return `p` of sensor s fired at time t: `o = P(t)·t_s`, `d = R_P R_s p/|p|` (rolling
//! shutter: P is the trajectory at each return's own time, §5), target range `|p|` and
//! normalised intensity. The field is sampled at `x_i = o + τ_i d` (τ from the occupancy grid)
//! and composited to a range D and a feature F; the intensity decoder reads (F, SH(d)). The
//! step returns the gradient of `λ_d·L_depth + λ_i·L_int + λ_r·L_reg` (means over the batch)
//! and each term's value.
//!
//! Backward: losses → decoder (∂L/∂F, ∂L/∂SH) and per-sample ∂L/∂w_i (weight suppression) →
//! compositing → SDF → field (sparse grid + MLP gradients, and ∂L/∂x_i from the encoding's
//! spatial gradient) → ∂L/∂o = Σ∂L/∂x_i, ∂L/∂d = Σ τ_i ∂L/∂x_i + SH Jacobian → pose. The
//! Eikonal samples add scene gradients only.

use glam::DVec3;

use super::camera_rgb::{sh_backward, sh_encoding};
use super::composite::{Composite, Opacity, Upstream, composite, composite_backward};
use super::field::SceneField;
use super::hash_grid::GradSink;
use super::intensity::{IntensityDecoder, IntensityMap};
use super::mlp::MlpGrad;
use super::pose::{PoseGrad, PoseParams};
use super::pose_newton::{NewtonConfig, PoseRow, plane_row};
use super::regulariser::{
    NEAR_HIT_M, eikonal_many, free_space_suppression, smoothed_gradient, weight_suppression,
};
use crate::geometry::Rigid;

/// One LiDAR ray ready to render.
#[derive(Clone, Debug)]
pub struct DepthRay {
    /// `world_from_vehicle` at the return's firing time.
    pub world_from_vehicle: Rigid,
    /// Unit direction in the sensor frame.
    pub dir_in_sensor: DVec3,
    pub range_m: f32,
    /// Intensity normalised to [0, 1]; `None` when the sensor reports none.
    pub intensity: Option<f32>,
    /// Sample distances along the ray.
    pub taus_m: Vec<f32>,
}

/// The objective's weights for the LiDAR terms (method.md §8: 0.1, 0.1, 0.01).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LidarWeights {
    pub depth: f32,
    pub intensity: f32,
    pub regulariser: f32,
    /// Whether to also gather each ray's point-to-plane row against the rendered surface for
    /// the preconditioned pose steps ([`super::pose_newton`]), with their settings (`None`: not
    /// gathered).
    pub pose_rows: Option<NewtonConfig>,
    /// Registration phase for a LiDAR that does not shape the scene yet: only free space well
    /// in front of its returns is trained (weight suppression at the depth weight,
    /// [`super::regulariser::free_space_suppression`]); no depth, intensity or Eikonal term.
    pub free_space_only: bool,
}

impl LidarWeights {
    pub const PAPER: Self = Self {
        depth: 0.1,
        intensity: 0.1,
        regulariser: 0.01,
        pose_rows: None,
        free_space_only: false,
    };
}

/// Term values (unweighted means over the batch) and gradients of their weighted sum.
#[derive(Debug)]
pub struct LidarStep {
    pub depth_loss: f64,
    pub mean_abs_error_m: f64,
    pub intensity_loss: f64,
    pub regulariser_loss: f64,
    pub mlp: MlpGrad,
    pub decoder: MlpGrad,
    /// ∂L/∂scale, ∂L/∂offset of the sensor's intensity mapping.
    pub intensity_map: [f64; 2],
    pub beta_grad: f64,
    pub pose: PoseGrad,
    /// Point-to-plane rows of the rays that reach a surface (when asked).
    pub pose_rows: Vec<PoseRow>,
}

/// What a LiDAR batch renders with: the scene, β and the shared intensity decoder (`None`:
/// no intensity term).
#[derive(Clone, Copy)]
pub struct LidarModel<'a> {
    pub field: &'a SceneField,
    /// The opacity model and β.
    pub opacity: Opacity,
    pub decoder: Option<&'a IntensityDecoder>,
    /// How many of the hash grid's coarsest levels the pose gradient sees (`None`: all;
    /// `Some(0.0)`: none, for a held sensor, which saves the spatial gradient's table reads).
    pub pose_levels: Option<f32>,
}

/// The composite (depth, accumulation, weights) of one LiDAR ray, forward only (diagnostics).
pub fn render_composite(
    field: &SceneField,
    opacity: Opacity,
    pose: &PoseParams,
    ray: &DepthRay,
) -> Composite {
    let (o, d) = pose.ray(ray.world_from_vehicle, ray.dir_in_sensor);
    let sdfs: Vec<f32> = field
        .query_ray(o, d, &ray.taus_m)
        .iter()
        .map(|s| s.sdf())
        .collect();
    let (alphas, at) = opacity.alphas(&sdfs, &ray.taus_m);
    composite(&alphas, &at, &[], 0)
}

/// The LiDAR terms of `rays`, all from one sensor at `pose` with intensity mapping `map`; the
/// hash table's gradients go to `grid`.
pub fn lidar_step(
    model: LidarModel,
    pose: &PoseParams,
    map: &IntensityMap,
    weights: &LidarWeights,
    rays: &[DepthRay],
    grid: &mut impl GradSink,
) -> LidarStep {
    let field = model.field;
    let mut out = LidarStep {
        depth_loss: 0.0,
        mean_abs_error_m: 0.0,
        intensity_loss: 0.0,
        regulariser_loss: 0.0,
        mlp: field.geo.zero_grad(),
        decoder: model
            .decoder
            .map_or_else(MlpGrad::default, |d| d.mlp.zero_grad()),
        intensity_map: [0.0; 2],
        beta_grad: 0.0,
        pose: PoseGrad::default(),
        pose_rows: Vec::new(),
    };
    let n = rays.len().max(1) as f64;
    let with_intensity = rays.iter().filter(|r| r.intensity.is_some()).count();
    let n_int = with_intensity.max(1) as f64;
    let dim = field.geo.output_dim().saturating_sub(1);
    let reg_weight = (weights.regulariser as f64 / n) as f32;
    for ray in rays {
        if ray.taus_m.is_empty() {
            continue;
        }
        let (o, d) = pose.ray(ray.world_from_vehicle, ray.dir_in_sensor);
        let samples = field.query_ray(o, d, &ray.taus_m);
        let sdfs: Vec<f32> = samples.iter().map(|s| s.sdf()).collect();
        // Where each weight sits: `at` (the samples, or the sections' midpoints).
        let (alphas, at) = model.opacity.alphas(&sdfs, &ray.taus_m);
        let decode = model
            .decoder
            .zip(ray.intensity)
            .filter(|_| !weights.free_space_only);
        let (features, fdim) = if decode.is_some() {
            let f: Vec<f32> = samples
                .iter()
                .flat_map(|s| s.feature().iter().copied())
                .collect();
            (f, dim)
        } else {
            (Vec::new(), 0)
        };
        let c = composite(&alphas, &at, &features, fdim);
        // Depth (Eq. 5).
        let r = (c.depth_m - ray.range_m) as f64;
        out.depth_loss += r * r / n;
        out.mean_abs_error_m += r.abs() / n;
        let d_depth = if weights.free_space_only {
            0.0
        } else {
            (weights.depth as f64 * 2.0 * r / n) as f32
        };
        // Intensity.
        let mut d_feature = Vec::new();
        let mut d_d_sh = DVec3::ZERO;
        if let Some((decoder, target)) = decode {
            let sh: Vec<f32> = sh_encoding(d).iter().map(|v| *v as f32).collect();
            let (value, trace) = decoder.forward(&c.feature, &sh);
            let ri = (map.scale * value + map.offset - target) as f64;
            out.intensity_loss += ri * ri / n_int;
            let d_pred = weights.intensity as f64 * 2.0 * ri / n_int;
            out.intensity_map[0] += d_pred * value as f64;
            out.intensity_map[1] += d_pred;
            let (d_f, d_sh) = decoder.backward(
                &trace,
                value,
                (d_pred * map.scale as f64) as f32,
                &mut out.decoder,
            );
            d_feature = d_f;
            d_d_sh = sh_backward(d, &d_sh);
        }
        // Regulariser: weight suppression away from the hit, Eikonal near it.
        let mut d_weights = Vec::new();
        if weights.free_space_only {
            let carve = (weights.depth as f64 / n) as f32;
            let (penalty, d_w) = free_space_suppression(&c.weights, &at, ray.range_m, carve);
            out.regulariser_loss += penalty / n;
            d_weights = d_w;
        } else if weights.regulariser != 0.0 {
            let (suppression, d_w) = weight_suppression(&c.weights, &at, ray.range_m, reg_weight);
            out.regulariser_loss += suppression / n;
            d_weights = d_w;
            let near: Vec<DVec3> = ray
                .taus_m
                .iter()
                .filter(|tau| (*tau - ray.range_m).abs() < NEAR_HIT_M)
                .map(|tau| o + d * *tau as f64)
                .collect();
            out.regulariser_loss += eikonal_many(field, &near, reg_weight, grid, &mut out.mlp) / n;
        }
        let up = Upstream {
            depth: d_depth,
            accumulation: 0.0,
            feature: &d_feature,
            weights: &d_weights,
        };
        let upstream = composite_backward(&alphas, &at, &features, fdim, &c, &up);
        let (d_o, d_d, d_beta) = field.ray_backward(
            &samples,
            &ray.taus_m,
            model.opacity,
            (&upstream.0, &upstream.1),
            grid,
            &mut out.mlp,
            model.pose_levels,
        );
        out.beta_grad += d_beta;
        out.pose.add(&pose.ray_backward(
            ray.world_from_vehicle,
            ray.dir_in_sensor,
            d_o,
            d_d + d_d_sh,
        ));
        if let Some(rows) = weights.pose_rows {
            // The rendered surface point (D/A) and the SDF's normal there.
            if c.accumulation > 0.5 {
                let depth = (c.depth_m / c.accumulation) as f64;
                let normal = smoothed_gradient(field, o + d * depth, rows.normal_stencil_m);
                let (wv, u) = (ray.world_from_vehicle, ray.dir_in_sensor);
                out.pose_rows.extend(plane_row(
                    wv,
                    pose,
                    u,
                    d,
                    normal,
                    depth,
                    ray.range_m as f64,
                    rows.min_incidence_cos,
                ));
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
    use glam::DQuat;

    fn setup() -> (SceneField, IntensityDecoder, PoseParams, Vec<DepthRay>) {
        let field = tiny_field(2, 4.0, 20.0);
        let pose = PoseParams::from_rigid(Rigid::new(
            DQuat::from_euler(glam::EulerRot::ZYX, 0.2, 0.05, -0.03),
            DVec3::new(0.9, 0.1, 1.8),
        ));
        let rays: Vec<DepthRay> = (0..6)
            .map(|i| DepthRay {
                world_from_vehicle: Rigid::new(
                    DQuat::from_rotation_z(0.1 * i as f64),
                    DVec3::new(2.0 + i as f64 * 0.3, 1.0, 0.0),
                ),
                dir_in_sensor: DVec3::new(1.0, 0.2 * i as f64 - 0.5, -0.3).normalize_or_zero(),
                range_m: 6.0,
                // One ray without intensity: it must contribute depth only.
                intensity: (i != 3).then_some(0.1 + 0.12 * i as f32),
                taus_m: (1..40).map(|k| k as f32 * 0.2).collect(),
            })
            .collect();
        (field, IntensityDecoder::new(2, 8), pose, rays)
    }

    fn total(s: &LidarStep, w: &LidarWeights) -> f64 {
        w.depth as f64 * s.depth_loss
            + w.intensity as f64 * s.intensity_loss
            + w.regulariser as f64 * s.regulariser_loss
    }

    /// End-to-end check of the whole chain (field, compositing, intensity decoder on SH of the
    /// rolling-shutter ray's direction, 6D pose) against finite differences of the loss in the
    /// pose parameters, β and the intensity mapping.
    #[test]
    fn pose_beta_and_mapping_gradients_match_finite_differences() {
        let (field, decoder, pose, rays) = setup();
        let map = IntensityMap {
            scale: 0.9,
            offset: 0.05,
        };
        // No regulariser: it does not move poses by design.
        let w = LidarWeights {
            depth: 1.0,
            intensity: 2.0,
            regulariser: 0.0,
            pose_rows: None,
            free_space_only: false,
        };
        for opacity in [OpacityModel::PerSample, OpacityModel::Interval] {
            pose_beta_and_mapping_gradients_of(opacity, &field, &decoder, &pose, &rays, &w, map);
        }
    }

    fn pose_beta_and_mapping_gradients_of(
        opacity: OpacityModel,
        field: &SceneField,
        decoder: &IntensityDecoder,
        pose: &PoseParams,
        rays: &[DepthRay],
        w: &LidarWeights,
        map: IntensityMap,
    ) {
        let (pose, w) = (*pose, *w);
        let beta = 3.0;
        let model = |beta| LidarModel {
            field,
            opacity: Opacity {
                model: opacity,
                beta,
            },
            decoder: Some(decoder),
            pose_levels: None,
        };
        let step = lidar_step(
            model(beta),
            &pose,
            &map,
            &w,
            rays,
            &mut SparseGrad::default(),
        );
        assert!(step.depth_loss > 0.0 && step.intensity_loss > 0.0);
        let loss = |p: &PoseParams| {
            total(
                &lidar_step(model(beta), p, &map, &w, rays, &mut SparseGrad::default()),
                &w,
            )
        };
        // f32 fields make the finite differences noisy at the 1e-3 level of the loss: compare
        // each component against 1 % of the whole gradient's size.
        let eps = 1e-3;
        let norm = step.pose.r6.iter().map(|g| g * g).sum::<f64>().sqrt()
            + step.pose.translation_m.length();
        assert!(norm > 1e-2, "gradient too small to test: {norm}");
        let tol = 0.01 * norm;
        assert_pose_gradient(pose, &step.pose, eps, tol, loss);
        let at_beta = |b| {
            total(
                &lidar_step(model(b), &pose, &map, &w, rays, &mut SparseGrad::default()),
                &w,
            )
        };
        let fd = (at_beta(beta + 1e-3) - at_beta(beta - 1e-3)) / 2e-3;
        assert!((fd - step.beta_grad).abs() < 2e-2 * (fd.abs() + step.beta_grad.abs()) + 1e-3);
        for k in 0..2 {
            let (mut up, mut down) = (map, map);
            if k == 0 {
                up.scale += 1e-3;
                down.scale -= 1e-3;
            } else {
                up.offset += 1e-3;
                down.offset -= 1e-3;
            }
            let l = |m: &IntensityMap| {
                total(
                    &lidar_step(model(beta), &pose, m, &w, rays, &mut SparseGrad::default()),
                    &w,
                )
            };
            let fd = (l(&up) - l(&down)) / 2e-3;
            let an = step.intensity_map[k];
            assert!(
                (fd - an).abs() < 1e-3 + 0.01 * an.abs(),
                "map[{k}]: {fd} vs {an}"
            );
        }
    }

    /// All three terms on: the geometry MLP's and the decoder's gradients against finite
    /// differences (the regulariser's weight suppression goes through the compositing, its
    /// Eikonal part through the stencil).
    #[test]
    fn scene_and_decoder_gradients_of_all_terms_match_finite_differences() {
        for opacity in [OpacityModel::PerSample, OpacityModel::Interval] {
            scene_and_decoder_gradients_of(opacity);
        }
    }

    fn scene_and_decoder_gradients_of(opacity: OpacityModel) {
        let (field, decoder, pose, mut rays) = setup();
        // Put the hits inside the sampled range so both regulariser parts are active.
        for r in &mut rays {
            r.range_m = 3.05;
        }
        let w = LidarWeights {
            depth: 0.5,
            intensity: 1.0,
            regulariser: 2.0,
            pose_rows: None,
            free_space_only: false,
        };
        let map = IntensityMap::default();
        let run = |f: &SceneField, dec: &IntensityDecoder| {
            let model = LidarModel {
                field: f,
                opacity: Opacity {
                    model: opacity,
                    beta: 3.0,
                },
                decoder: Some(dec),
                pose_levels: None,
            };
            lidar_step(model, &pose, &map, &w, &rays, &mut SparseGrad::default())
        };
        let step = run(&field, &decoder);
        assert!(step.regulariser_loss > 0.0);
        let eps = 1e-3;
        let mut checked = 0;
        for layer in 0..field.geo.layers.len() {
            for k in [1, 4, 9] {
                let (mut up, mut down) = (field.clone(), field.clone());
                up.geo.layers[layer].weights_mut()[k] += eps;
                down.geo.layers[layer].weights_mut()[k] -= eps;
                let fd = (total(&run(&up, &decoder), &w) - total(&run(&down, &decoder), &w))
                    / (2.0 * eps as f64);
                let an = step.mlp.weights[layer][k] as f64;
                assert!(
                    (fd - an).abs() < 0.03 * (fd.abs() + an.abs()) + 2e-3,
                    "{opacity:?} geometry layer {layer} weight {k}: {fd} vs {an}"
                );
                checked += usize::from(an.abs() > 2e-3);
            }
        }
        for layer in 0..decoder.mlp.layers.len() {
            for k in [0, 2, 6] {
                let (mut up, mut down) = (decoder.clone(), decoder.clone());
                up.mlp.layers[layer].weights_mut()[k] += eps;
                down.mlp.layers[layer].weights_mut()[k] -= eps;
                let fd = (total(&run(&field, &up), &w) - total(&run(&field, &down), &w))
                    / (2.0 * eps as f64);
                let an = step.decoder.weights[layer][k] as f64;
                assert!(
                    (fd - an).abs() < 0.03 * (fd.abs() + an.abs()) + 2e-3,
                    "decoder layer {layer} weight {k}: {fd} vs {an}"
                );
                checked += usize::from(an.abs() > 2e-3);
            }
        }
        assert!(
            checked >= 4,
            "too few non-zero gradients to test ({checked})"
        );
    }

    #[test]
    fn render_composite_is_the_depth_term_forward() {
        let (field, _, pose, rays) = setup();
        let w = LidarWeights {
            depth: 1.0,
            intensity: 0.0,
            regulariser: 0.0,
            pose_rows: None,
            free_space_only: false,
        };
        let model = LidarModel {
            field: &field,
            opacity: Opacity {
                model: OpacityModel::PerSample,
                beta: 3.0,
            },
            decoder: None,
            pose_levels: None,
        };
        for ray in &rays {
            let step = lidar_step(
                model,
                &pose,
                &IntensityMap::default(),
                &w,
                std::slice::from_ref(ray),
                &mut SparseGrad::default(),
            );
            let rendered = render_composite(&field, model.opacity, &pose, ray).depth_m;
            let error = (rendered - ray.range_m).abs() as f64;
            assert!((error - step.mean_abs_error_m).abs() < 1e-5, "{error}");
        }
    }

    /// Rows are gathered only when asked, at most one per ray, with the sign of the rendered
    /// surface's distance from the return; nothing else of the step changes.
    #[test]
    fn pose_rows_are_gathered_on_request_and_change_nothing_else() {
        let (field, decoder, pose, rays) = setup();
        let model = LidarModel {
            field: &field,
            opacity: Opacity {
                model: OpacityModel::PerSample,
                beta: 3.0,
            },
            decoder: Some(&decoder),
            pose_levels: None,
        };
        let w = LidarWeights {
            depth: 1.0,
            intensity: 2.0,
            regulariser: 0.1,
            pose_rows: Some(NewtonConfig {
                min_incidence_cos: 0.0,
                ..NewtonConfig::default()
            }),
            free_space_only: false,
        };
        let map = IntensityMap::default();
        let step = lidar_step(model, &pose, &map, &w, &rays, &mut SparseGrad::default());
        assert!(!step.pose_rows.is_empty() && step.pose_rows.len() <= rays.len());
        for ray in &rays {
            let c = render_composite(&field, model.opacity, &pose, ray);
            if c.accumulation > 0.5 {
                let r = (c.depth_m / c.accumulation - ray.range_m) as f64;
                assert!(step.pose_rows.iter().any(|row| row.residual_m * r >= 0.0));
            }
        }
        let plain = lidar_step(
            model,
            &pose,
            &map,
            &LidarWeights {
                pose_rows: None,
                free_space_only: false,
                ..w
            },
            &rays,
            &mut SparseGrad::default(),
        );
        assert!(plain.pose_rows.is_empty());
        assert_eq!(plain.pose, step.pose);
        assert_eq!(plain.mlp.weights, step.mlp.weights);
        assert_eq!(plain.depth_loss, step.depth_loss);
    }
}
