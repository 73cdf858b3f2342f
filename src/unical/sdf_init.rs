//! Geometry initialisation from the LiDAR returns (an engineering step for the CPU, method.md
//! §18; the objective of §8 is unchanged): before rendering, the scene's SDF is fitted directly
//! to a truncated distance field of the aggregated returns under the initial calibration, so
//! volume rendering starts from surfaces in the right places instead of spending hundreds of
//! slow iterations growing them from empty space, and the pose gradients are meaningful early.
//!
//! Per LiDAR ray with origin o, direction d and range R (the same rays as the depth term):
//! - at the hit `o + R d` the SDF is zero;
//! - at [`FRONT_POINTS`] stratified random points in front of it the SDF is the distance to
//!   the nearest return, truncated
//!   at [`TRUNCATION_M`] (free space: the opacity `sigmoid(−β s)` must be small there, which a
//!   mere `s > 0` would not give);
//! - just behind it (5–20 cm) the SDF is minus that distance (inside);
//! - at the hit the SDF is a distance function, `(‖∇s‖ − 1)²` (the Eikonal stencil of
//!   [`super::regulariser`]).
//!
//! Distances come from [`PointIndex`], a hash of 0.5 m cells over the returns thinned to one per
//! 5 cm; every supervision point costs one field query and one backward pass, about a hundredth
//! of rendering the ray.

use glam::DVec3;

use super::field::SceneField;
use super::hash_grid::GradSink;
use super::mlp::MlpGrad;
use super::regulariser::eikonal_many;

/// The distance field is truncated here (the scene field starts at +0.5 m everywhere).
pub const TRUNCATION_M: f64 = 0.5;

type CellMap<V> = crate::util::FastMap<[i32; 3], V>;

/// Nearest-return distances up to [`TRUNCATION_M`].
pub struct PointIndex {
    cells: CellMap<Vec<DVec3>>,
}

impl PointIndex {
    const CELL_M: f64 = TRUNCATION_M;
    const THIN_M: f64 = 0.05;

    fn key(p: DVec3, size: f64) -> [i32; 3] {
        (p / size).floor().to_array().map(|v| v as i32)
    }

    /// Index `points`, keeping one per 5 cm cell.
    pub fn new(points: &[DVec3]) -> Self {
        let mut seen = crate::util::FastSet::default();
        let mut cells: CellMap<Vec<DVec3>> = CellMap::default();
        for p in points {
            if p.is_finite() && seen.insert(Self::key(*p, Self::THIN_M)) {
                cells
                    .entry(Self::key(*p, Self::CELL_M))
                    .or_default()
                    .push(*p);
            }
        }
        Self { cells }
    }

    /// Distance from `x` to the nearest indexed point, at most [`TRUNCATION_M`]. The cell of
    /// `x` first, then only the neighbouring cells whose box is nearer than the best so far
    /// (the same minimum as scanning all 27).
    pub fn distance(&self, x: DVec3) -> f64 {
        let [cx, cy, cz] = Self::key(x, Self::CELL_M);
        // Position inside the cell, in metres from its low corner.
        let inside = x - DVec3::new(cx as f64, cy as f64, cz as f64) * Self::CELL_M;
        let gap = |step: i32, at: f64| match step {
            -1 => at,
            1 => Self::CELL_M - at,
            _ => 0.0,
        };
        let mut best = TRUNCATION_M * TRUNCATION_M;
        for (dx, dy, dz) in NEIGHBOURS {
            let box2 =
                gap(dx, inside.x).powi(2) + gap(dy, inside.y).powi(2) + gap(dz, inside.z).powi(2);
            if box2 >= best {
                continue;
            }
            if let Some(points) = self.cells.get(&[cx + dx, cy + dy, cz + dz]) {
                for p in points {
                    best = best.min(p.distance_squared(x));
                }
            }
        }
        best.sqrt()
    }
}

/// The 27 cells around a point's own, its own first (it usually holds the nearest return and
/// rules most of the others out).
const NEIGHBOURS: [(i32, i32, i32); 27] = {
    let mut out = [(0, 0, 0); 27];
    let mut k = 1;
    let mut i: i32 = 0;
    while i < 27 {
        let (dx, dy, dz) = (i % 3 - 1, (i / 3) % 3 - 1, i / 9 - 1);
        if !(dx == 0 && dy == 0 && dz == 0) {
            out[k] = (dx, dy, dz);
            k += 1;
        }
        i += 1;
    }
    out
};

/// Free-space points per ray (stratified between the sensor and the hit).
pub const FRONT_POINTS: usize = 3;

/// One ray's supervision points and their target distances.
#[derive(Clone, Copy, Debug)]
pub struct SdfRay {
    pub origin: DVec3,
    pub dir: DVec3,
    pub range_m: f64,
    /// The free-space points, as fractions of the way to 5 cm before the hit, and their
    /// target SDFs.
    pub fronts: [(f64, f64); FRONT_POINTS],
    /// How far behind the hit (5–20 cm) the inside point is, in [0, 1], and its target SDF.
    pub u_behind: f64,
    pub behind_sdf_m: f64,
}

impl SdfRay {
    fn front(&self, u: f64) -> DVec3 {
        self.origin + self.dir * (self.range_m - 0.05) * u.clamp(0.0, 1.0)
    }

    pub fn behind(&self) -> DVec3 {
        self.origin + self.dir * (self.range_m + 0.05 + 0.15 * self.u_behind.clamp(0.0, 1.0))
    }

    /// A ray with its targets from the index; `u_front` ∈ [0, 1) jitters the strata.
    pub fn new(
        origin: DVec3,
        dir: DVec3,
        range_m: f64,
        u_front: f64,
        u_behind: f64,
        index: &PointIndex,
    ) -> Self {
        let mut ray = Self {
            origin,
            dir,
            range_m,
            fronts: [(0.0, 0.0); FRONT_POINTS],
            u_behind,
            behind_sdf_m: 0.0,
        };
        for k in 0..FRONT_POINTS {
            let u = (k as f64 + u_front) / FRONT_POINTS as f64;
            ray.fronts[k] = (u, index.distance(ray.front(u)));
        }
        ray.behind_sdf_m = -index.distance(ray.behind());
        ray
    }
}

/// Weight of the Eikonal constraint at the hit.
const EIKONAL_WEIGHT: f64 = 0.1;

/// Mean loss over `rays` and its gradients (scaled by `weight`) into the field.
pub fn sdf_fit_step(
    field: &SceneField,
    rays: &[SdfRay],
    weight: f32,
    grid: &mut impl GradSink,
    mlp: &mut MlpGrad,
) -> f64 {
    let n = rays.len().max(1) as f64;
    let w = weight as f64 / n;
    let width = field.geo.output_dim().max(1);
    let mut loss = 0.0;
    // Blocks of rays, each one batch through the field (their targets, then their stencils).
    for block in rays.chunks(SDF_FIT_BLOCK) {
        let (mut points, mut targets) = (Vec::new(), Vec::new());
        for ray in block {
            let hit = ray.origin + ray.dir * ray.range_m;
            let fronts = ray.fronts.map(|(u, target)| (ray.front(u), target));
            for (x, target) in [(hit, 0.0), (ray.behind(), ray.behind_sdf_m)]
                .into_iter()
                .chain(fronts)
            {
                points.push(x);
                targets.push(target);
            }
        }
        let samples = field.query_many(&points);
        let mut d_out = vec![0.0; samples.len() * width];
        for ((sample, target), row) in samples
            .iter()
            .zip(&targets)
            .zip(d_out.chunks_exact_mut(width))
        {
            let r = sample.sdf() as f64 - target;
            loss += r * r / n;
            row[0] = (2.0 * r * w) as f32;
        }
        field.backward_many(&samples, &d_out, grid, mlp, None);
        let hits: Vec<DVec3> = block.iter().map(|r| r.origin + r.dir * r.range_m).collect();
        let eik_weight = (EIKONAL_WEIGHT * w) as f32;
        loss += EIKONAL_WEIGHT * eikonal_many(field, &hits, eik_weight, grid, mlp) / n;
    }
    loss
}

/// Rays per batch of [`sdf_fit_step`].
const SDF_FIT_BLOCK: usize = 16;

#[cfg(test)]
mod tests {
    use super::super::field::tiny_field;
    use super::super::hash_grid::SparseGrad;
    use super::*;

    #[test]
    fn gradient_matches_finite_differences() {
        let field = tiny_field(2, 2.0, 20.0);
        let rays: Vec<SdfRay> = (0..8)
            .map(|i| SdfRay {
                origin: DVec3::new(0.5 * i as f64, -1.0, 1.8),
                dir: DVec3::new(1.0, 0.1 * i as f64, -0.3).normalize_or_zero(),
                range_m: 4.0 + 0.7 * i as f64,
                fronts: [0.2, 0.5, 0.9].map(|u| (u * (i as f64 * 0.37).fract(), 0.3)),
                u_behind: (i as f64 * 0.61).fract(),
                behind_sdf_m: -0.1,
            })
            .collect();
        let (mut g, mut m) = (SparseGrad::default(), field.geo.zero_grad());
        let loss = sdf_fit_step(&field, &rays, 1.0, &mut g, &mut m);
        assert!(loss > 0.0);
        let total = |f: &SceneField| {
            let (mut g, mut m) = (SparseGrad::default(), f.geo.zero_grad());
            sdf_fit_step(f, &rays, 0.0, &mut g, &mut m)
        };
        let mut checked = 0;
        for layer in 0..field.geo.layers.len() {
            let grads = &m.weights[layer];
            let mut order: Vec<usize> = (0..grads.len()).collect();
            order.sort_by(|a, b| grads[*b].abs().total_cmp(&grads[*a].abs()));
            for &k in order.iter().take(3) {
                let (mut up, mut down) = (field.clone(), field.clone());
                up.geo.layers[layer].weights_mut()[k] += 1e-3;
                down.geo.layers[layer].weights_mut()[k] -= 1e-3;
                let fd = (total(&up) - total(&down)) / 2e-3;
                let an = grads[k] as f64;
                assert!(
                    (fd - an).abs() < 0.03 * (fd.abs() + an.abs()) + 2e-3,
                    "layer {layer} weight {k}: {fd} vs {an}"
                );
                checked += usize::from(an.abs() > 1e-2);
            }
        }
        assert!(checked >= 3, "too few non-zero gradients ({checked})");
    }

    #[test]
    fn the_index_gives_truncated_nearest_distances() {
        let points: Vec<DVec3> = (0..200)
            .map(|i| DVec3::new(i as f64 * 0.02, 0.0, 0.0))
            .collect();
        let index = PointIndex::new(&points);
        assert!((index.distance(DVec3::new(1.0, 0.3, 0.0)) - 0.3).abs() < 0.03);
        assert!(index.distance(DVec3::new(1.0, 0.0, 0.0)) < 0.03);
        assert_eq!(index.distance(DVec3::new(1.0, 2.0, 0.0)), TRUNCATION_M);
        assert_eq!(index.distance(DVec3::new(-3.0, 0.0, 0.0)), TRUNCATION_M);
    }

    /// Skipping cells farther than the best so far gives exactly the minimum over every stored
    /// point (scattered points, queries on both sides of cell borders).
    #[test]
    fn pruned_search_equals_brute_force() {
        let mut rng = 7u64;
        let mut next = || {
            rng = crate::sim::noise::hash64(rng);
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        let points: Vec<DVec3> = (0..3000)
            .map(|_| DVec3::new(next() * 4.0 - 2.0, next() * 4.0 - 2.0, next() * 1.0))
            .collect();
        let index = PointIndex::new(&points);
        let stored: Vec<DVec3> = index.cells.values().flatten().copied().collect();
        assert!(stored.len() > 1000);
        for _ in 0..2000 {
            let x = DVec3::new(next() * 5.0 - 2.5, next() * 5.0 - 2.5, next() * 2.0 - 0.5);
            let brute = stored
                .iter()
                .map(|p| p.distance_squared(x))
                .fold(TRUNCATION_M * TRUNCATION_M, f64::min)
                .sqrt();
            assert_eq!(index.distance(x), brute, "{x}");
        }
    }
}
