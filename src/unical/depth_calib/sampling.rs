//! Where a UniCal step draws its rays: LiDAR returns (evenly over every LiDAR, each ray from
//! its return's firing time), camera pixels (uniform, then from the keypoint heat maps and the
//! LiDARs' depth-edge silhouettes, §10, refreshed every [`super::SILHOUETTE_REFRESH`] steps,
//! below the LiDARs' highest beam where asked) and the samples along a camera ray.

use super::*;

impl DepthCalibration {
    /// Sample distances of a camera ray from `o` along `d` in the occupied space (10 cm steps,
    /// from 0.3 m to `camera_far_m`, stratified by `jitter`).
    pub(super) fn camera_taus(&self, o: DVec3, d: DVec3, jitter: f64) -> Vec<f32> {
        self.occupancy.sample(
            o,
            d,
            0.3,
            self.config.camera_far_m,
            self.config.step_m,
            jitter,
            self.config.max_samples_per_ray,
        )
    }

    /// The heat maps' σ in pixels of an image `width` wide at this iteration (§10: geometric
    /// from the first to the last value), or `None` while pixels are drawn uniformly.
    pub fn heatmap_sigma(&self, width: f64) -> Option<f64> {
        let total = self.config.iterations.max(1) as f64;
        let start = (self.config.heatmap_start_fraction as f64 * total).round();
        if self.config.heatmap_start_fraction >= 1.0 || (self.iteration as f64) < start {
            return None;
        }
        let progress = ((self.iteration as f64 - start) / (total - start).max(1.0)).clamp(0.0, 1.0);
        let (first, last) = self.config.heatmap_sigma_px;
        let sigma_1920 = first * (last / first).powf(progress);
        Some(sigma_1920 * width / 1920.0)
    }

    /// Project every LiDAR's silhouette points (of its sweep nearest each frame) into every
    /// camera frame under the current poses, for [`DepthCalibConfig::silhouette_share`].
    pub(super) fn refresh_silhouettes(&mut self) {
        let Some(stage) = &self.camera else {
            return;
        };
        if self.silhouette_points.is_empty() {
            self.silhouette_points = self
                .lidars
                .iter()
                .map(|l| {
                    l.sweeps
                        .par_iter()
                        .map(|s| {
                            crate::eval::edges::depth_discontinuities(&s.points_in_sensor, 0.05)
                                .into_iter()
                                .map(|i| i as u32)
                                .collect()
                        })
                        .collect()
                })
                .collect();
        }
        let lidar_poses: Vec<Rigid> = self.poses.iter().map(|p| p.to_rigid()).collect();
        let (lidars, trajectory, points) =
            (&self.lidars, &self.trajectory, &self.silhouette_points);
        let pixels = stage
            .cameras
            .iter()
            .zip(&stage.poses)
            .map(|(cam, pose)| {
                let vehicle_from_camera = pose.to_rigid();
                cam.frames
                    .par_iter()
                    .map(|f| {
                        let Some(middle) = cam.camera_from_world_at(
                            trajectory,
                            vehicle_from_camera,
                            cam.middle_stamp_nanos(f.stamp_nanos),
                        ) else {
                            return Vec::new();
                        };
                        let mut out = Vec::new();
                        for ((lidar, vehicle_from_lidar), indices) in
                            lidars.iter().zip(&lidar_poses).zip(points)
                        {
                            let Some((s, idx)) = lidar
                                .sweeps
                                .iter()
                                .zip(indices)
                                .min_by_key(|(s, _)| (s.stamp_nanos - f.stamp_nanos).abs())
                            else {
                                continue;
                            };
                            for &i in idx {
                                let [x, y, z] = s.points_in_sensor[i as usize];
                                let offset_s = s
                                    .time_offset_secs
                                    .as_ref()
                                    .and_then(|t| t.get(i as usize))
                                    .map_or(0.0, |&t| t as f64);
                                let stamp = s.stamp_nanos + (offset_s * 1e9) as i64;
                                let Ok(wv_point) = trajectory.world_from_vehicle(stamp) else {
                                    continue;
                                };
                                let p = DVec3::new(x as f64, y as f64, z as f64);
                                let p_world =
                                    wv_point.transform_point(vehicle_from_lidar.transform_point(p));
                                if let Some(px) = cam.project_world_from(
                                    trajectory,
                                    vehicle_from_camera,
                                    f.stamp_nanos,
                                    middle,
                                    p_world,
                                ) {
                                    out.push((px.x as f32, px.y as f32));
                                }
                            }
                        }
                        out
                    })
                    .collect()
            })
            .collect();
        self.silhouette_pixels = (pixels, self.iteration);
    }

    pub(super) fn draw_camera_rays(&mut self, camera: usize) -> Vec<ColourRay> {
        let Some(stage) = &self.camera else {
            return Vec::new();
        };
        let (cam, pose) = (&stage.cameras[camera], stage.poses[camera]);
        let mut rays = Vec::with_capacity(self.config.rays_per_camera);
        if cam.frames.is_empty() {
            return rays;
        }
        let (w, h) = (cam.intrinsics.width as u64, cam.intrinsics.height as u64);
        let sigma = self.heatmap_sigma(w as f64);
        let mut attempts = 0;
        while rays.len() < self.config.rays_per_camera && attempts < 4 * self.config.rays_per_camera
        {
            attempts += 1;
            let frame = (next(&mut self.rng) % cam.frames.len() as u64) as usize;
            let f = &cam.frames[frame];
            let silhouettes = self
                .silhouette_pixels
                .0
                .get(camera)
                .and_then(|frames| frames.get(frame))
                .filter(|pixels| !pixels.is_empty());
            let from_silhouette = sigma.is_some()
                && silhouettes.is_some()
                && unit(&mut self.rng) < self.config.silhouette_share;
            let from_heatmap = !from_silhouette
                && sigma.is_some_and(|_| {
                    !f.keypoints.is_empty()
                        && unit(&mut self.rng) >= self.config.heatmap_uniform_share
                });
            let centre = match (from_silhouette, silhouettes) {
                (true, Some(pixels)) => {
                    Some(pixels[(next(&mut self.rng) % pixels.len() as u64) as usize])
                }
                _ if from_heatmap => {
                    let k = &f.keypoints[(next(&mut self.rng) % f.keypoints.len() as u64) as usize];
                    Some((k.x, k.y))
                }
                _ => None,
            };
            let (x, y) = match sigma.zip(centre) {
                // A draw from Σ_k G_σ(u − u_k): a random keypoint (or silhouette pixel) plus
                // Gaussian noise.
                Some((sigma, (kx, ky))) => {
                    let (gx, gy) = gaussian_pair(&mut self.rng);
                    let px = (kx as f64 + sigma * gx).round().clamp(0.0, (w - 1) as f64);
                    let py = (ky as f64 + sigma * gy).round().clamp(0.0, (h - 1) as f64);
                    (px as u64, py as u64)
                }
                None => (
                    next(&mut self.rng) % w.max(1),
                    next(&mut self.rng) % h.max(1),
                ),
            };
            if f.masked.get((y * w + x) as usize) == Some(&true) {
                continue;
            }
            let k = 3 * (y * w + x) as usize;
            let Some(px) = f.rgb.get(k..k + 3) else {
                continue;
            };
            let Some(u) = cam.intrinsics.unproject(DVec2::new(x as f64, y as f64)) else {
                continue;
            };
            let stamp = cam.row_stamp_nanos(f.stamp_nanos, y as f64);
            let Ok(wv) = self.trajectory.world_from_vehicle(stamp) else {
                continue;
            };
            let (o, d) = pose.ray(wv, u);
            if stage
                .ray_top_elevation_rad
                .is_some_and(|top| crate::unical::coverage::ray_elevation_rad(wv, d) > top)
            {
                continue;
            }
            let jitter = unit(&mut self.rng);
            let taus = self.camera_taus(o, d, jitter);
            let background_taus_m = stage.background.as_ref().map_or_else(Vec::new, |b| {
                let jitter = (next(&mut self.rng) >> 11) as f64 / (1u64 << 53) as f64;
                b.field.taus(o, d, jitter)
            });
            rays.push(ColourRay {
                world_from_vehicle: wv,
                dir_in_sensor: u,
                target: [px[0], px[1], px[2]].map(|v| v as f32 / 255.0),
                taus_m: taus,
                background_taus_m,
            });
        }
        rays
    }

    /// A random return of `sensor`: `world_from_vehicle` at its firing time, its direction
    /// in the sensor frame, range and normalised intensity (`None` if unusable).
    pub(super) fn draw_return(
        &mut self,
        sensor: usize,
    ) -> Option<(Rigid, DVec3, f64, Option<f32>)> {
        let sweeps = &self.lidars[sensor].sweeps;
        if sweeps.is_empty() {
            return None;
        }
        let s = &sweeps[(next(&mut self.rng) % sweeps.len() as u64) as usize];
        if s.points_in_sensor.is_empty() {
            return None;
        }
        let i = (next(&mut self.rng) % s.points_in_sensor.len() as u64) as usize;
        let p = s.points_in_sensor[i];
        let intensity = self.intensity_norm[sensor]
            .zip(s.intensity.get(i))
            .map(|(k, raw)| (raw * k).clamp(0.0, 1.0));
        let v = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        let range = v.length();
        let u = v.try_normalize()?;
        if range < 1.0 {
            return None;
        }
        let t = s.stamp_nanos
            + s.time_offset_secs
                .as_ref()
                .and_then(|t| t.get(i))
                .map_or(0, |x| (*x as f64 * 1e9) as i64);
        let wv = self.trajectory.world_from_vehicle(t).ok()?;
        Some((wv, u, range, intensity))
    }

    pub(super) fn draw_rays(&mut self, sensor: usize, count: usize) -> Vec<DepthRay> {
        let pose = self.poses[sensor];
        let mut rays = Vec::with_capacity(count);
        if self.lidars[sensor].sweeps.is_empty() {
            return rays;
        }
        let mut attempts = 0;
        while rays.len() < count && attempts < 4 * count {
            attempts += 1;
            let Some((wv, u, range, intensity)) = self.draw_return(sensor) else {
                continue;
            };
            let (o, d) = pose.ray(wv, u);
            let jitter = (next(&mut self.rng) >> 11) as f64 / (1u64 << 53) as f64;
            let taus = self.occupancy.sample_towards(
                o,
                d,
                0.5,
                range + 2.0,
                self.config.step_m,
                jitter,
                self.config.max_samples_per_ray,
            );
            if taus.is_empty() {
                continue;
            }
            rays.push(DepthRay {
                world_from_vehicle: wv,
                dir_in_sensor: u,
                range_m: range as f32,
                intensity,
                taus_m: taus,
            });
        }
        rays
    }
}
