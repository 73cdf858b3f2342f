//! The surface-alignment term's part of a step (§9): a matched pixel pair's rays rendered to
//! their surface points, the term's gradients on the scene and the poses, and the camera-only
//! pose step of an alignment release.

use super::*;

impl DepthCalibration {
    /// A matched pixel's ray at its frame's time, sampled like a colour ray.
    pub(super) fn align_ray(
        &mut self,
        (camera, frame): (usize, usize),
        pixel: DVec2,
    ) -> Option<AlignRay> {
        let stage = self.camera.as_ref()?;
        let cam = stage.cameras.get(camera)?;
        let stamp = cam.row_stamp_nanos(cam.frames.get(frame)?.stamp_nanos, pixel.y);
        let u = cam.intrinsics.unproject(pixel)?;
        let wv = self.trajectory.world_from_vehicle(stamp).ok()?;
        let (o, d) = stage.poses[camera].ray(wv, u);
        let jitter = unit(&mut self.rng);
        let taus_m = self.camera_taus(o, d, jitter);
        Some(AlignRay {
            world_from_vehicle: wv,
            dir_in_sensor: u,
            pixel,
            taus_m,
        })
    }

    /// The correspondence term of this step (§9): every camera takes a random pair it is part
    /// of and up to `alignment_matches_per_camera` of its matches; gradients are weighted by
    /// λ_align / cameras, the hash table's go to the first accumulator.
    pub(super) fn alignment_gradients(&mut self) -> AlignmentGrads {
        let cameras = self.camera.as_ref().map_or(0, |c| c.cameras.len());
        let mut out = AlignmentGrads {
            pose: vec![[0.0; 9]; cameras],
            geo: self.field.geo.zero_grad(),
            beta_grad: 0.0,
            loss: 0.0,
            kept: 0,
        };
        if self.config.alignment == AlignmentLoss::None || self.correspondences.pairs.is_empty() {
            return out;
        }
        // Draw every batch first (the generator advances), then evaluate them.
        let mut batches = Vec::new();
        for k in 0..cameras {
            let owned = self.correspondences.by_camera[k].len();
            if owned == 0 {
                continue;
            }
            let pi =
                self.correspondences.by_camera[k][(next(&mut self.rng) % owned as u64) as usize];
            let (a, b, count) = {
                let p = &self.correspondences.pairs[pi];
                (p.a, p.b, p.pixels.len())
            };
            let n = self.config.alignment_matches_per_camera.min(count);
            let mut rays = Vec::with_capacity(n);
            for _ in 0..n {
                let j = (next(&mut self.rng) % count as u64) as usize;
                let (ua, ub) = self.correspondences.pairs[pi].pixels[j];
                if let (Some(ra), Some(rb)) = (self.align_ray(a, ua), self.align_ray(b, ub)) {
                    rays.push((ra, rb));
                }
            }
            batches.push((a.0, b.0, rays));
        }
        let Some(stage) = self.camera.as_ref() else {
            return out;
        };
        let opacity = self.opacity();
        let w = self.config.alignment_weight as f64 / cameras.max(1) as f64;
        let track_information = self.config.camera_hold_unobserved.is_some();
        let settings = AlignSettings {
            information: track_information,
            ..self.config.alignment_settings
        };
        let alignment = self.config.alignment;
        let batch_count = batches.len().max(1) as f64;
        let field = &self.field;
        // Batches in parallel, each group of them into its own accumulator (deterministic).
        let group = batches.len().div_ceil(self.grid_accs.len()).max(1);
        let steps: Vec<Vec<(usize, usize, AlignStep)>> = batches
            .chunks(group)
            .zip(self.grid_accs.iter_mut())
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|(chunk, acc)| {
                chunk
                    .iter()
                    .map(|(a, b, rays)| {
                        let camera = |k: usize| AlignCamera {
                            pose: &stage.poses[k],
                            intrinsics: &stage.cameras[k].intrinsics,
                            pixel_scale: 1920.0 / stage.cameras[k].intrinsics.width.max(1) as f64,
                        };
                        let step = match alignment {
                            AlignmentLoss::SurfaceAlignment => surface_alignment_step(
                                field,
                                opacity,
                                (camera(*a), camera(*b)),
                                rays,
                                &settings,
                                &mut Scaled::new(&field.grid, &mut *acc, w as f32),
                            ),
                            AlignmentLoss::ProjectedRayDistance => projected_ray_step(
                                (camera(*a), camera(*b)),
                                rays,
                                settings.max_error_px,
                            ),
                            AlignmentLoss::None => AlignStep::default(),
                        };
                        (*a, *b, step)
                    })
                    .collect()
            })
            .collect();
        let mut information = vec![PoseInformation::default(); cameras];
        for (a, b, step) in steps.into_iter().flatten() {
            if track_information {
                information[a].merge(&step.info_a);
                information[b].merge(&step.info_b);
            }
            let (ga, gb) = (
                pose_grad_flat(&step.pose_a, w),
                pose_grad_flat(&step.pose_b, w),
            );
            out.pose[a].iter_mut().zip(ga).for_each(|(x, y)| *x += y);
            out.pose[b].iter_mut().zip(gb).for_each(|(x, y)| *x += y);
            add_scaled(&mut out.geo, &step.geo, w as f32);
            out.beta_grad += step.beta_grad * w;
            out.loss += step.loss / batch_count;
            out.kept += step.kept;
        }
        if let Some(stage) = self.camera.as_mut().filter(|_| track_information) {
            for (held, new) in stage.information.iter_mut().zip(&information) {
                held.decay(INFORMATION_FORGETTING);
                held.merge(new);
            }
        }
        out
    }

    /// During the geometry initialisation, from [`DepthCalibConfig::alignment_release`]: the
    /// cameras step on the correspondence term alone, rendered through the SDF as it is being
    /// fitted (whose parameters take no gradient from it). Returns the term and its kept
    /// matches.
    pub(super) fn alignment_pose_step(&mut self) -> (f64, usize) {
        if self.iteration < self.config.camera_release() || self.camera.is_none() {
            return (0.0, 0);
        }
        let lr = self.camera_rate_now();
        let mut align = self.alignment_gradients();
        if !self.config.alignment_release_rotates {
            // Adam's moments stay at zero for the rotation: it does not move.
            align.pose.iter_mut().for_each(|g| g[..6].fill(0.0));
        }
        // Its hash-grid gradients went to the accumulators: the SDF fit must not see them.
        drop(GradAccumulator::drain_all(&mut self.grid_accs));
        let frozen = self.frozen_cameras();
        if let Some(stage) = self.camera.as_mut() {
            stage.step_poses(&align.pose, &frozen, lr, &self.config, self.iteration);
        }
        (align.loss, align.kept)
    }
}
