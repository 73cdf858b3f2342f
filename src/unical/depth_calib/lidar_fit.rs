//! The LiDAR-only parts of [`DepthCalibration`]: the geometry initialisation's step (the SDF
//! fitted to the LiDAR returns under the initial extrinsics, before any pose moves), and the
//! LiDAR objective evaluated on its own for probes and tests (residuals, a batch of rays, the
//! loss and its pose gradient at a given extrinsic).

use super::*;

impl DepthCalibration {
    /// One iteration of the geometry initialisation: the SDF fitted to LiDAR returns under the
    /// current (initial) extrinsics, in parallel chunks, Adam on the grid and geometry MLP.
    pub(super) fn geometry_init_step(&mut self) -> DepthReport {
        let (alignment_loss, alignment_matches) = self.alignment_pose_step();
        let lidars = self.lidars.len().max(1);
        let per_sensor = self.config.geometry_init_rays.div_ceil(lidars);
        let mut rays = Vec::with_capacity(per_sensor * lidars);
        for s in 0..self.lidars.len() {
            if !self.shapes_scene(s) {
                continue;
            }
            let pose = self.poses[s];
            let mut drawn = 0;
            for _ in 0..2 * per_sensor {
                if drawn == per_sensor {
                    break;
                }
                let Some((wv, u, range, _)) = self.draw_return(s) else {
                    continue;
                };
                let (origin, dir) = pose.ray(wv, u);
                let uniform = |rng: &mut u64| (next(rng) >> 11) as f64 / (1u64 << 53) as f64;
                let (u_front, u_behind) = (uniform(&mut self.rng), uniform(&mut self.rng));
                rays.push((origin, dir, range, u_front, u_behind));
                drawn += 1;
            }
        }
        let index = self
            .point_index
            .get_or_insert_with(|| PointIndex::new(&self.aggregated));
        let rays: Vec<SdfRay> = rays
            .into_par_iter()
            .map(|(o, d, range, u_front, u_behind)| {
                SdfRay::new(o, d, range, u_front, u_behind, index)
            })
            .collect();
        let chunk = rays.len().div_ceil(self.grid_accs.len()).max(1);
        let total = rays.len().max(1) as f64;
        let field = &self.field;
        let parts: Vec<(f64, crate::unical::mlp::MlpGrad)> = rays
            .par_chunks(chunk)
            .zip(self.grid_accs.par_iter_mut())
            .map(|(c, acc)| {
                let share = c.len() as f64 / total;
                let mut sink = Scaled::new(&field.grid, acc, 1.0);
                let mut mlp = field.geo.zero_grad();
                let loss = sdf_fit_step(field, c, share as f32, &mut sink, &mut mlp);
                (loss * share, mlp)
            })
            .collect();
        let mut geo = self.field.geo.zero_grad();
        let mut loss = 0.0;
        for (l, g) in parts {
            loss += l;
            add_scaled(&mut geo, &g, 1.0);
        }
        let lr = decayed_lr(
            self.config.lr_field,
            0.1,
            self.iteration,
            self.config.iterations,
        );
        self.grid_opt
            .step_accumulated(&mut self.field.grid.params, &mut self.grid_accs, lr);
        self.mlp_opt
            .step(&mut self.mlp_params, &grad_flat(&geo), lr);
        mlp_set(&mut self.field.geo, &self.mlp_params);
        self.iteration += 1;
        DepthReport {
            loss: 0.0,
            mean_abs_error_m: 0.0,
            beta: self.beta(),
            colour_loss: 0.0,
            intensity_loss: 0.0,
            regulariser_loss: 0.0,
            geometry_init_loss: Some(loss),
            alignment_loss,
            alignment_matches,
        }
    }

    /// Diagnostics: `(true range, rendered − true range, elevation of the ray in the world,
    /// rad)` for `count` random returns of LiDAR `sensor` under the current state.
    pub fn depth_residuals(&mut self, sensor: usize, count: usize) -> Vec<DepthResidual> {
        let rays = self.draw_rays(sensor, count);
        let (field, opacity, pose) = (&self.field, self.opacity(), self.poses[sensor]);
        rays.par_iter()
            .map(|r| {
                let c = crate::unical::lidar_terms::render_composite(field, opacity, &pose, r);
                let (_, d) = pose.ray(r.world_from_vehicle, r.dir_in_sensor);
                DepthResidual {
                    range_m: r.range_m,
                    error_m: c.depth_m - r.range_m,
                    elevation_rad: d.z.asin() as f32,
                    accumulation: c.accumulation,
                }
            })
            .collect()
    }

    /// Diagnostics: `count` rays of LiDAR `sensor` drawn under its current pose (their sample
    /// distances fixed), to evaluate [`DepthCalibration::lidar_objective`] on one batch.
    pub fn lidar_batch(&mut self, sensor: usize, count: usize) -> Vec<DepthRay> {
        self.draw_rays(sensor, count)
    }

    /// Diagnostics: the weighted LiDAR objective of `rays` (depth, intensity, regulariser) with
    /// `sensor` at `pose`, its gradient with respect to that pose, and (with preconditioned
    /// pose steps) the robust point-to-plane system those steps solve.
    pub fn lidar_objective(
        &self,
        sensor: usize,
        pose: &PoseParams,
        rays: &[DepthRay],
    ) -> (f64, crate::unical::pose::PoseGrad, TangentSystem) {
        self.lidar_objective_where(sensor, pose, rays, |_| true)
    }

    /// [`Self::lidar_objective`] with the preconditioned steps' system built from the rows
    /// `keep` accepts (e.g. only surfaces another sensor sees too).
    pub fn lidar_objective_where(
        &self,
        sensor: usize,
        pose: &PoseParams,
        rays: &[DepthRay],
        keep: impl Fn(&crate::unical::pose_newton::PoseRow) -> bool,
    ) -> (f64, crate::unical::pose::PoseGrad, TangentSystem) {
        let model = LidarModel {
            field: &self.field,
            opacity: self.opacity(),
            decoder: self.intensity_norm[sensor].map(|_| &self.decoder),
            pose_levels: None,
        };
        let weights = self.config.lidar_weights();
        let mut sink: Option<crate::unical::hash_grid::SparseGrad> = None;
        let part = lidar_step(
            model,
            pose,
            &self.intensity_maps[sensor],
            &weights,
            rays,
            &mut sink,
        );
        let loss = weights.depth as f64 * part.depth_loss
            + weights.intensity as f64 * part.intensity_loss
            + weights.regulariser as f64 * part.regulariser_loss;
        let system = match self.config.lidar_pose_update {
            PoseUpdate::Newton(n) => {
                let mut rows = part.pose_rows;
                rows.retain(|r| keep(r));
                robust_system(&rows, n.robust_scale, n.robust_floor_m)
            }
            PoseUpdate::Adam => TangentSystem::default(),
        };
        (loss, part.pose, system)
    }
}
