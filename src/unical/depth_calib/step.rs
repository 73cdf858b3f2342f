//! One optimisation step of [`DepthCalibration`] once the geometry is initialised: the LiDARs'
//! depth and intensity rays, then the cameras' colour rays with the correspondence term's pose
//! gradients, then the scene's shared parameters. Each sensor's rays are split into chunks
//! that run in parallel, each with its own hash-grid accumulator; a sensor's pose steps after
//! its own rays (each ray sees only its own sensor's pose), the scene after every sensor's.

use super::*;
use crate::unical::mlp::MlpGrad;

/// What one step gathers over every sensor before the scene's shared update.
#[derive(Default)]
struct StepSums {
    geo: MlpGrad,
    beta_grad: f64,
    loss: f64,
    mae: f64,
    colour_loss: f64,
    intensity_loss: f64,
    regulariser_loss: f64,
}

impl DepthCalibration {
    /// One optimisation step over every sensor: the same number of rays from each LiDAR (depth)
    /// and each camera (colour), gradients weighted by the objective's λs (§8).
    pub fn step(&mut self) -> DepthReport {
        if let Some(c2f) = self.config.coarse_to_fine {
            let levels = self.field.grid.config.levels as f32;
            let end = (c2f.end_fraction * self.config.iterations as f32).max(1.0);
            let progress = (self.iteration as f32 / end).min(1.0);
            let active = c2f.start_levels + (levels - c2f.start_levels) * progress;
            self.field.grid.set_active_levels(active);
        }
        if self.initialising_geometry() {
            return self.geometry_init_step();
        }
        if self.point_index.is_some() || !self.aggregated.is_empty() {
            self.point_index = None;
            self.aggregated = Vec::new();
        }
        let total = self.config.iterations;
        let lr_field = decayed_lr(self.config.lr_field, 0.1, self.iteration, total);
        let lr_pose = self
            .config
            .pose_rate(self.config.lr_pose, 0.01, self.iteration);
        let lr_camera_pose = self.camera_rate_now();
        // Before the warm-up's end only the correspondence term moves cameras; at its end their
        // schedule starts again (DepthCalibConfig::alignment_release).
        if self.iteration == self.config.pose_warmup
            && self.config.camera_release() < self.config.pose_warmup
            && let Some(stage) = self.camera.as_mut()
        {
            stage.restart_pose_optimisers();
        }
        let mut sums = StepSums {
            geo: self.field.geo.zero_grad(),
            ..StepSums::default()
        };
        self.lidar_terms(&mut sums, lr_pose, lr_field);
        let frozen = self.frozen_cameras();
        let align = self.alignment_gradients();
        add_scaled(&mut sums.geo, &align.geo, 1.0);
        sums.beta_grad += align.beta_grad;
        self.camera_terms(&mut sums, &align, frozen, (lr_camera_pose, lr_field));
        self.step_scene(&sums, lr_field);
        self.iteration += 1;
        let lidars = self.lidars.len().max(1) as f64;
        DepthReport {
            loss: sums.loss,
            mean_abs_error_m: sums.mae / lidars,
            beta: self.beta(),
            colour_loss: sums.colour_loss,
            intensity_loss: sums.intensity_loss,
            regulariser_loss: sums.regulariser_loss,
            geometry_init_loss: None,
            alignment_loss: align.loss,
            alignment_matches: align.kept,
        }
    }

    /// Every LiDAR's depth and intensity rays (§8.1): their gradients into `sums`, and each
    /// LiDAR's pose and intensity map stepped.
    fn lidar_terms(&mut self, sums: &mut StepSums, lr_pose: f32, lr_field: f32) {
        let lidars = self.lidars.len().max(1) as f64;
        let base_weights = self.config.lidar_weights();
        let mut decoder_grad = self.decoder.mlp.zero_grad();
        let with_intensity = self.intensity_norm.iter().flatten().count().max(1) as f64;
        for s in 0..self.lidars.len() {
            let rays = self.draw_rays(s, self.config.rays_per_sensor);
            if rays.is_empty() {
                continue;
            }
            let chunk = rays.len().div_ceil(self.grid_accs.len()).max(1);
            let model = LidarModel {
                field: &self.field,
                opacity: self.opacity(),
                decoder: self.intensity_norm[s].map(|_| &self.decoder),
                // A held LiDAR's pose gradient would be thrown away: skip it.
                pose_levels: self.is_frozen(&self.lidars[s].name).then_some(0.0),
            };
            let (pose, map) = (&self.poses[s], &self.intensity_maps[s]);
            // Registration phase: a LiDAR other than the anchor clears free space in front of
            // its returns and tracks the anchor's surfaces, but places none of its own.
            let weights = LidarWeights {
                free_space_only: !self.shapes_scene(s),
                ..base_weights
            };
            let total_rays = rays.len() as f64;
            let parts: Vec<_> = rays
                .par_chunks(chunk)
                .zip(self.grid_accs.par_iter_mut())
                .map(|(c, acc)| {
                    // lidar_step averages over its chunk: weight chunks by size, sensors
                    // equally.
                    let share = c.len() as f64 / total_rays / lidars;
                    let mut sink = Scaled::new(&model.field.grid, acc, share as f32);
                    let part = lidar_step(model, pose, map, &weights, c, &mut sink);
                    (c.len(), part)
                })
                .collect();
            let mut pose_grad = [0.0f32; 9];
            let mut map_grad = [0.0f32; 2];
            let mut rows = Vec::new();
            for (n, mut part) in parts {
                let share = n as f64 / total_rays / lidars;
                sums.loss += part.depth_loss * share;
                sums.mae += part.mean_abs_error_m * share * lidars;
                sums.intensity_loss += part.intensity_loss * share * lidars / with_intensity;
                sums.regulariser_loss += part.regulariser_loss * share;
                sums.beta_grad += part.beta_grad * share;
                add_scaled(&mut sums.geo, &part.mlp, share as f32);
                add_scaled(&mut decoder_grad, &part.decoder, share as f32);
                let g = pose_grad_flat(&part.pose, share);
                pose_grad.iter_mut().zip(g).for_each(|(a, b)| *a += b);
                map_grad[0] += (part.intensity_map[0] * share) as f32;
                map_grad[1] += (part.intensity_map[1] * share) as f32;
                rows.append(&mut part.pose_rows);
            }
            if !self.is_frozen(&self.lidars[s].name) {
                match self.config.lidar_pose_update {
                    PoseUpdate::Adam => pose_step(
                        &mut self.pose_opt[s],
                        &mut self.poses[s],
                        &pose_grad,
                        lr_pose,
                        1.0,
                    ),
                    // The step fraction follows the pose learning rate's schedule.
                    // Full steps after the warm-up: each solves the gathered rows, which
                    // already average the batches' noise (no learning-rate decay).
                    PoseUpdate::Newton(_) if lr_pose > 0.0 => {
                        if self.newton[s].gather(&mut rows) {
                            self.newton[s].step(&mut self.poses[s], 1.0);
                        }
                    }
                    PoseUpdate::Newton(_) => {}
                }
            }
            if self.intensity_norm[s].is_some() {
                let m = &mut self.intensity_maps[s];
                let mut flat = [m.scale, m.offset];
                self.intensity_map_opt[s].step(&mut flat, &map_grad, lr_field);
                (m.scale, m.offset) = (flat[0], flat[1]);
            }
        }
        if self.intensity_norm.iter().any(Option::is_some) {
            self.decoder_opt.step(
                &mut self.decoder_params,
                &grad_flat(&decoder_grad),
                lr_field,
            );
            mlp_set(&mut self.decoder.mlp, &self.decoder_params);
        }
    }

    /// Every camera's colour rays (§8.2): their gradients into `sums` (with the correspondence
    /// term's pose gradients in `align`), each camera's exposure stepped, then the cameras'
    /// poses (those in `held` keep theirs) and the appearance decoders.
    fn camera_terms(
        &mut self,
        sums: &mut StepSums,
        align: &AlignmentGrads,
        frozen: Vec<bool>,
        (lr_camera_pose, lr_field): (f32, f32),
    ) {
        let cameras = self.camera.as_ref().map_or(0, |c| c.cameras.len());
        let colour_moves_poses = self.iteration >= self.config.pose_warmup;
        if let Some(stage) = self.camera.as_ref() {
            let mut colour = stage.appearance.colour.zero_grad();
            let mut sky = stage.appearance.sky.zero_grad();
            let mut background_mlp = stage
                .background
                .as_ref()
                .map_or_else(MlpGrad::default, |b| b.field.geo.zero_grad());
            let rgb_weight = self.config.rgb_weight as f64;
            let opacity = self.opacity();
            let stale = self.silhouette_pixels.0.is_empty()
                || self.iteration >= self.silhouette_pixels.1 + SILHOUETTE_REFRESH;
            if self.config.silhouette_share > 0.0 && self.heatmap_sigma(1920.0).is_some() && stale {
                self.refresh_silhouettes();
            }
            let mut pose_grads = vec![[0.0f32; 9]; cameras];
            // Cameras without rays this step keep their pose.
            let mut held = frozen;
            for k in 0..cameras {
                let rays = self.draw_camera_rays(k);
                let Some(stage) = self.camera.as_mut() else {
                    break;
                };
                if rays.is_empty() {
                    held[k] = true;
                    continue;
                }
                let chunk = rays.len().div_ceil(self.grid_accs.len()).max(1);
                let (background, mut background_accs) = match stage.background.as_mut() {
                    Some(b) => (Some(&b.field), Some(b.grid_accs.iter_mut())),
                    None => (None, None),
                };
                let model = CameraModel {
                    field: &self.field,
                    background,
                    appearance: &stage.appearance,
                    opacity,
                    // A pose the colour does not move this step needs no spatial gradient:
                    // skip its table reads.
                    pose_levels: if colour_moves_poses && !held[k] {
                        self.config.colour_pose_levels
                    } else {
                        Some(0.0)
                    },
                };
                let (pose, exposure) = (&stage.poses[k], &stage.exposure[k]);
                let total_rays = rays.len() as f64;
                let jobs: Vec<_> = rays
                    .chunks(chunk)
                    .zip(self.grid_accs.iter_mut())
                    .map(|(c, acc)| (c, acc, background_accs.as_mut().and_then(|a| a.next())))
                    .collect();
                let parts: Vec<_> = jobs
                    .into_par_iter()
                    .map(|(c, acc, background_acc)| {
                        let w = (c.len() as f64 / total_rays / cameras as f64 * rgb_weight) as f32;
                        let mut sink = Scaled::new(&model.field.grid, acc, w);
                        let mut background_sink = background_acc
                            .zip(model.background)
                            .map(|(acc, b)| Scaled::new(&b.grid, acc, w));
                        let part =
                            colour_step(model, pose, exposure, c, &mut sink, &mut background_sink);
                        (c.len(), part)
                    })
                    .collect();
                let mut pose_grad = align.pose[k];
                let mut exposure_grad = [0.0f32; 6];
                for (n, part) in parts {
                    let share = n as f64 / total_rays / cameras as f64;
                    let w = share * rgb_weight;
                    sums.colour_loss += part.loss * share;
                    sums.beta_grad += part.beta_grad * w;
                    add_scaled(&mut sums.geo, &part.geo, w as f32);
                    add_scaled(&mut colour, &part.colour, w as f32);
                    add_scaled(&mut sky, &part.sky, w as f32);
                    add_scaled(&mut background_mlp, &part.background_mlp, w as f32);
                    if colour_moves_poses {
                        let g = pose_grad_flat(&part.pose, w);
                        pose_grad.iter_mut().zip(g).for_each(|(a, b)| *a += b);
                    }
                    for (a, b) in exposure_grad.iter_mut().zip(part.exposure) {
                        *a += (b * w) as f32;
                    }
                }
                // Stepped after every camera's rays (each camera's rays see only its own pose).
                pose_grads[k] = pose_grad;
                let e = &mut stage.exposure[k];
                let mut flat: Vec<f32> = e.scale.iter().chain(&e.offset).copied().collect();
                stage.exposure_opt[k].step(&mut flat, &exposure_grad, lr_field);
                e.scale.copy_from_slice(&flat[..3]);
                e.offset.copy_from_slice(&flat[3..]);
            }
            if let Some(stage) = self.camera.as_mut() {
                stage.step_poses(
                    &pose_grads,
                    &held,
                    lr_camera_pose,
                    &self.config,
                    self.iteration,
                );
                stage
                    .colour_opt
                    .step(&mut stage.colour_params, &grad_flat(&colour), lr_field);
                mlp_set(&mut stage.appearance.colour, &stage.colour_params);
                if let Some(b) = stage.background.as_mut() {
                    b.grid_opt.step_accumulated(
                        &mut b.field.grid.params,
                        &mut b.grid_accs,
                        lr_field,
                    );
                    b.mlp_opt
                        .step(&mut b.mlp_params, &grad_flat(&background_mlp), lr_field);
                    mlp_set(&mut b.field.geo, &b.mlp_params);
                }
                stage
                    .sky_opt
                    .step(&mut stage.sky_params, &grad_flat(&sky), lr_field);
                mlp_set(&mut stage.appearance.sky, &stage.sky_params);
            }
        }
    }

    /// The scene's shared parameters: the hash grid, the geometry decoder and β.
    fn step_scene(&mut self, sums: &StepSums, lr_field: f32) {
        self.grid_opt
            .step_accumulated(&mut self.field.grid.params, &mut self.grid_accs, lr_field);
        self.mlp_opt
            .step(&mut self.mlp_params, &grad_flat(&sums.geo), lr_field);
        mlp_set(&mut self.field.geo, &self.mlp_params);
        let mut lb = [self.ln_beta];
        self.beta_opt.step(
            &mut lb,
            &[(sums.beta_grad * self.beta() as f64) as f32],
            lr_field,
        );
        self.ln_beta = lb[0].clamp(0.0, 8.0);
    }
}
