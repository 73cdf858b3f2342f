//! The occupancy grid that decides where a ray is sampled (method.md §7): 0.5 m voxels marked by
//! the aggregated LiDAR points, dilated by one voxel so that small extrinsic errors do not cut
//! surfaces away, over the scene box. Rays are sampled every 10 cm inside occupied voxels
//! (stratified jitter when training), and the field is never evaluated in empty space.

use glam::DVec3;

#[derive(Clone, Debug)]
pub struct OccupancyGrid {
    pub box_min: DVec3,
    pub voxel_m: f64,
    pub dims: [usize; 3],
    occupied: Vec<bool>,
    /// Per block of [`BLOCK`]³ voxels, whether any is occupied: a ray steps through an empty
    /// block without testing each of its samples.
    blocks: Vec<bool>,
}

/// Voxels per block edge of [`OccupancyGrid`]'s coarse level.
const BLOCK: usize = 8;

impl OccupancyGrid {
    /// Voxels of `voxel_m` over the bounding box of `points_world` plus `margin_m`, marked by the
    /// points and dilated by `dilate` voxels.
    pub fn from_points(points_world: &[DVec3], voxel_m: f64, margin_m: f64, dilate: usize) -> Self {
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for p in points_world.iter().filter(|p| p.is_finite()) {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        if lo.x > hi.x {
            lo = DVec3::ZERO;
            hi = DVec3::ZERO;
        }
        let box_min = lo - DVec3::splat(margin_m);
        let size = hi + DVec3::splat(margin_m) - box_min;
        let dims = [0, 1, 2].map(|d| ((size[d] / voxel_m).ceil() as usize).max(1));
        let mut grid = Self {
            box_min,
            voxel_m,
            dims,
            occupied: vec![false; dims[0] * dims[1] * dims[2]],
            blocks: Vec::new(),
        };
        let mut marked = vec![false; grid.occupied.len()];
        for p in points_world {
            if let Some(i) = grid.voxel_index(*p) {
                marked[i] = true;
            }
        }
        let r = dilate as isize;
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    if !marked[grid.flat(x, y, z)] {
                        continue;
                    }
                    for dz in -r..=r {
                        for dy in -r..=r {
                            for dx in -r..=r {
                                let (nx, ny, nz) =
                                    (x as isize + dx, y as isize + dy, z as isize + dz);
                                if nx >= 0
                                    && ny >= 0
                                    && nz >= 0
                                    && (nx as usize) < dims[0]
                                    && (ny as usize) < dims[1]
                                    && (nz as usize) < dims[2]
                                {
                                    let i = grid.flat(nx as usize, ny as usize, nz as usize);
                                    grid.occupied[i] = true;
                                }
                            }
                        }
                    }
                }
            }
        }
        grid.mark_blocks();
        grid
    }

    /// The block level from the voxels.
    fn mark_blocks(&mut self) {
        let b = self.dims.map(|d| d.div_ceil(BLOCK));
        self.blocks = vec![false; b[0] * b[1] * b[2]];
        for (i, _) in self.occupied.iter().enumerate().filter(|(_, o)| **o) {
            let (x, y, z) = (
                i % self.dims[0],
                (i / self.dims[0]) % self.dims[1],
                i / (self.dims[0] * self.dims[1]),
            );
            self.blocks[((z / BLOCK) * b[1] + y / BLOCK) * b[0] + x / BLOCK] = true;
        }
    }

    /// Where a ray at `p` (inside the box) along `dir` leaves `p`'s block, as a distance from
    /// `p`, when that block is empty (`None`: it is not, or `p` is outside the box).
    fn empty_block_exit(&self, p: DVec3, dir: DVec3) -> Option<f64> {
        let v = (p - self.box_min) / self.voxel_m;
        if !(v.x >= 0.0 && v.y >= 0.0 && v.z >= 0.0) {
            return None;
        }
        let cell = [v.x as usize, v.y as usize, v.z as usize];
        if (0..3).any(|d| cell[d] >= self.dims[d]) {
            return None;
        }
        let b = self.dims.map(|d| d.div_ceil(BLOCK));
        let block = cell.map(|c| c / BLOCK);
        if self.blocks[(block[2] * b[1] + block[1]) * b[0] + block[0]] {
            return None;
        }
        let edge_m = BLOCK as f64 * self.voxel_m;
        let mut exit = f64::INFINITY;
        for d in 0..3 {
            let lo = self.box_min[d] + block[d] as f64 * edge_m;
            let bound = if dir[d] > 1e-12 {
                lo + edge_m
            } else if dir[d] < -1e-12 {
                lo
            } else {
                continue;
            };
            exit = exit.min((bound - p[d]) / dir[d]);
        }
        Some(exit)
    }

    fn flat(&self, x: usize, y: usize, z: usize) -> usize {
        (z * self.dims[1] + y) * self.dims[0] + x
    }

    fn voxel_index(&self, p: DVec3) -> Option<usize> {
        let v = (p - self.box_min) / self.voxel_m;
        if !(v.x >= 0.0 && v.y >= 0.0 && v.z >= 0.0) {
            return None;
        }
        let (x, y, z) = (v.x as usize, v.y as usize, v.z as usize);
        (x < self.dims[0] && y < self.dims[1] && z < self.dims[2]).then(|| self.flat(x, y, z))
    }

    pub fn box_max(&self) -> DVec3 {
        self.box_min
            + DVec3::new(
                self.dims[0] as f64,
                self.dims[1] as f64,
                self.dims[2] as f64,
            ) * self.voxel_m
    }

    pub fn is_occupied(&self, p: DVec3) -> bool {
        self.voxel_index(p).is_some_and(|i| self.occupied[i])
    }

    /// The occupied voxels as disjoint `[min, max)` boxes in world metres.
    pub fn occupied_boxes(&self) -> impl Iterator<Item = (DVec3, DVec3)> + '_ {
        let [nx, ny, _] = self.dims;
        self.occupied
            .iter()
            .enumerate()
            .filter(|(_, o)| **o)
            .map(move |(i, _)| {
                let (x, y, z) = (i % nx, (i / nx) % ny, i / (nx * ny));
                let lo = self.box_min + DVec3::new(x as f64, y as f64, z as f64) * self.voxel_m;
                (lo, lo + DVec3::splat(self.voxel_m))
            })
    }

    pub fn occupied_fraction(&self) -> f64 {
        self.occupied.iter().filter(|o| **o).count() as f64 / self.occupied.len().max(1) as f64
    }

    /// Distances τ along the ray `origin + τ·dir` (unit `dir`) at `step_m` spacing, offset by
    /// `jitter` ∈ [0,1) of a step, inside occupied voxels and `[near, far]`, at most `max` of them.
    pub fn sample(
        &self,
        origin: DVec3,
        dir: DVec3,
        near_m: f64,
        far_m: f64,
        step_m: f64,
        jitter: f64,
        max: usize,
    ) -> Vec<f32> {
        let mut out = Vec::new();
        // Clip to the box (slab test) so long rays do not walk empty space outside it.
        let (bmin, bmax) = (self.box_min, self.box_max());
        let (mut t0, mut t1) = (near_m, far_m);
        for d in 0..3 {
            if dir[d].abs() < 1e-12 {
                if origin[d] < bmin[d] || origin[d] > bmax[d] {
                    return out;
                }
                continue;
            }
            let (a, b) = (
                (bmin[d] - origin[d]) / dir[d],
                (bmax[d] - origin[d]) / dir[d],
            );
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        if t0 >= t1 {
            return out;
        }
        let mut t = t0 + step_m * jitter.clamp(0.0, 0.999);
        while t <= t1 && out.len() < max {
            let p = origin + dir * t;
            if let Some(exit) = self.empty_block_exit(p, dir) {
                // Every sample short of the exit (less a micrometre, against rounding) lies in
                // the empty block: step over them as the walk would, without testing each.
                let until = t + exit - 1e-6;
                t += step_m;
                while t < until && t <= t1 {
                    t += step_m;
                }
                continue;
            }
            if self.is_occupied(p) {
                out.push(t as f32);
            }
            t += step_m;
        }
        out
    }

    /// Like [`OccupancyGrid::sample`] up to `far_m`, but when more than `max` samples fall in
    /// occupied space, keeps the *last* `max`: for a LiDAR return at `far_m − margin` the
    /// samples around the hit matter most, and a long grazing ray over the ground must not
    /// lose its hit to the sample cap.
    #[allow(clippy::too_many_arguments)]
    pub fn sample_towards(
        &self,
        origin: DVec3,
        dir: DVec3,
        near_m: f64,
        far_m: f64,
        step_m: f64,
        jitter: f64,
        max: usize,
    ) -> Vec<f32> {
        let mut out = self.sample(origin, dir, near_m, far_m, step_m, jitter, usize::MAX);
        if out.len() > max {
            out.drain(..out.len() - max);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ground patch at z = 0 and one point on a wall at x = 10.
    fn grid() -> OccupancyGrid {
        let mut pts: Vec<DVec3> = (0..40)
            .flat_map(|i| {
                (0..40).map(move |j| DVec3::new(i as f64 * 0.25, j as f64 * 0.25 - 5.0, 0.0))
            })
            .collect();
        pts.push(DVec3::new(10.0, 0.0, 2.0));
        OccupancyGrid::from_points(&pts, 0.5, 1.0, 1)
    }

    #[test]
    fn occupied_boxes_are_the_occupied_voxels() {
        let g = grid();
        let boxes: Vec<(DVec3, DVec3)> = g.occupied_boxes().collect();
        let total = g.dims[0] * g.dims[1] * g.dims[2];
        assert_eq!(
            boxes.len(),
            (g.occupied_fraction() * total as f64).round() as usize
        );
        for (lo, hi) in &boxes {
            assert!(((*hi - *lo) - DVec3::splat(0.5)).abs().max_element() < 1e-9);
            assert!(g.is_occupied((*lo + *hi) * 0.5));
        }
        // The wall point's voxel is one of them.
        let wall = DVec3::new(10.0, 0.0, 2.0);
        assert!(
            boxes
                .iter()
                .any(|(lo, hi)| wall.cmpge(*lo).all() && wall.cmplt(*hi).all())
        );
    }

    /// Stepping over empty blocks gives exactly the samples of testing every step.
    #[test]
    fn skipping_empty_blocks_changes_no_sample() {
        let mut pts: Vec<DVec3> = (0..30)
            .map(|i| {
                DVec3::new(
                    i as f64 * 1.7,
                    (i * 7 % 11) as f64 * 2.3 - 12.0,
                    (i % 5) as f64,
                )
            })
            .collect();
        pts.push(DVec3::new(-20.0, -30.0, -3.0));
        pts.push(DVec3::new(60.0, 30.0, 9.0));
        let g = OccupancyGrid::from_points(&pts, 0.5, 1.0, 1);
        let every_step = |o: DVec3, d: DVec3, jitter: f64| {
            let mut out = Vec::new();
            let mut t = 0.3 + 0.1 * jitter;
            while t <= 150.0 {
                if g.is_occupied(o + d * t) {
                    out.push(t as f32);
                }
                t += 0.1;
            }
            out
        };
        let mut total = 0;
        for k in 0..200 {
            let a = k as f64 * 0.618_034 * std::f64::consts::TAU;
            let e = ((k * 37 % 19) as f64 / 19.0 - 0.5) * 0.6;
            let d = DVec3::new(a.cos() * e.cos(), a.sin() * e.cos(), e.sin());
            let o = DVec3::new((k % 13) as f64 * 3.0, (k % 7) as f64 * 2.0 - 6.0, 1.0);
            let jitter = (k as f64 * 0.377).fract();
            let want = every_step(o, d, jitter);
            let got = g.sample(o, d, 0.3, 150.0, 0.1, jitter, usize::MAX);
            total += want.len();
            // The box clip starts the walk at the box when the origin is outside it.
            if (0..3).all(|i| o[i] >= g.box_min[i] && o[i] <= g.box_max()[i]) {
                assert_eq!(got, want, "ray {k}");
            }
        }
        assert!(
            total > 100,
            "{total} samples: the rays must cross occupied space"
        );
    }

    #[test]
    fn samples_only_near_surfaces_at_the_step() {
        let g = grid();
        assert!(g.occupied_fraction() < 0.5);
        // A horizontal ray at z = 2 crosses empty space and then the wall voxel (dilated).
        let s = g.sample(
            DVec3::new(0.0, 0.0, 2.0),
            DVec3::X,
            0.0,
            50.0,
            0.1,
            0.0,
            1000,
        );
        assert!(!s.is_empty());
        assert!(s.iter().all(|t| (*t - 10.0).abs() <= 1.0 + 1e-6), "{s:?}");
        for w in s.windows(2) {
            assert!((w[1] - w[0] - 0.1).abs() < 1e-4);
        }
        // A ray down to the ground is sampled around z = 0 only.
        let s = g.sample(
            DVec3::new(3.0, 0.0, 2.0),
            -DVec3::Z,
            0.0,
            50.0,
            0.1,
            0.5,
            1000,
        );
        assert!(
            s.iter().all(|t| *t >= 1.0 - 1e-6 && *t <= 3.0 + 1e-6),
            "{s:?}"
        );
        assert!(s.iter().any(|t| (*t - 2.0).abs() < 0.1));
        // A ray that misses the box gives nothing.
        assert!(
            g.sample(
                DVec3::new(0.0, 0.0, 50.0),
                DVec3::Z,
                0.0,
                50.0,
                0.1,
                0.0,
                10
            )
            .is_empty()
        );
    }

    #[test]
    fn a_long_grazing_ray_keeps_the_samples_at_its_end() {
        let g = grid();
        // Along the ground patch (occupied for 10 m): the cap keeps the far end.
        let o = DVec3::new(0.0, 0.0, 0.2);
        let all = g.sample(o, DVec3::X, 0.0, 9.0, 0.1, 0.0, usize::MAX);
        assert!(all.len() > 50, "{}", all.len());
        let head = g.sample(o, DVec3::X, 0.0, 9.0, 0.1, 0.0, 20);
        let tail = g.sample_towards(o, DVec3::X, 0.0, 9.0, 0.1, 0.0, 20);
        assert_eq!(head[..], all[..20]);
        assert_eq!(tail[..], all[all.len() - 20..]);
    }
}
