//! How crowded the scene's hash tables are: per level of the grid, the lattice points inside the
//! occupied part of the scene against the table slots they are stored in.
//!
//! How it works. The scene box maps to \[0,1\]³ and level `l`'s lattice point `c` sits at
//! `(c − 0.5)/scale_l` along each axis ([`HashGrid::encode`]'s half-cell offset). For each
//! occupied voxel (disjoint, half-open boxes) the lattice points inside it are the integers
//! in `[⌈lo·scale + 0.5⌉, ⌈hi·scale + 0.5⌉)` per axis, so no point is counted twice; each is
//! hashed with [`HashGrid::lattice_slot`] and marked in a bit set of the level's slots. A level
//! whose points outnumber its used slots shares entries between places that have nothing to do
//! with each other (Instant-NGP leaves those collisions to the gradients to sort out): a camera's
//! colour gradient through such a level carries texture from elsewhere in the scene.
//!
//! Coarse levels are under-counted (a ray sample also reads the corners just outside an
//! occupied voxel), but those levels are dense: one point per slot whatever the count.

use super::hash_grid::HashGrid;

/// One level's load over the occupied space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LevelLoad {
    pub level: usize,
    /// Lattice points per axis.
    pub resolution: u32,
    /// Whether the level's lattice exceeds its table, so points are hashed into it.
    pub hashed: bool,
    /// Lattice points inside the occupied boxes.
    pub points: u64,
    /// Slots those points are stored in.
    pub used_slots: u64,
    /// The level's slots.
    pub slots: u64,
}

impl LevelLoad {
    /// Lattice points per used slot: 1 without collisions.
    pub fn points_per_used_slot(&self) -> f64 {
        self.points as f64 / self.used_slots.max(1) as f64
    }
}

/// Every level's load over `boxes` (`[lo, hi)` in the grid's \[0,1\]³, disjoint).
pub fn level_loads(grid: &HashGrid, boxes: &[([f64; 3], [f64; 3])]) -> Vec<LevelLoad> {
    (0..grid.config.levels.max(1))
        .map(|l| {
            let (scale, resolution, slots, dense) = grid.level_layout(l);
            let scale = scale as f64;
            let mut used = vec![0u64; slots.div_ceil(64)];
            let mut points = 0u64;
            for (lo, hi) in boxes {
                let range = |d: usize| {
                    let a = (lo[d].clamp(0.0, 1.0) * scale + 0.5).ceil() as u32;
                    let b = (hi[d].clamp(0.0, 1.0) * scale + 0.5).ceil() as u32;
                    a..b.max(a)
                };
                for z in range(2) {
                    for y in range(1) {
                        for x in range(0) {
                            let slot = grid.lattice_slot(l, [x, y, z]);
                            used[slot / 64] |= 1 << (slot % 64);
                            points += 1;
                        }
                    }
                }
            }
            LevelLoad {
                level: l,
                resolution,
                hashed: !dense,
                points,
                used_slots: used.iter().map(|w| w.count_ones() as u64).sum(),
                slots: slots as u64,
            }
        })
        .collect()
}

/// One line for a run's output: the table size, and per hashed level the points per used slot
/// (`1.0` while the level's table holds its part of the scene without collisions).
pub fn summary(loads: &[LevelLoad], log2_table_size: u32) -> String {
    let hashed: Vec<&LevelLoad> = loads.iter().filter(|l| l.hashed).collect();
    match (hashed.first(), hashed.last()) {
        (Some(first), Some(last)) => format!(
            "2^{log2_table_size} slots per level; lattice points in the occupied space per used slot, levels {}–{}: {}",
            first.level,
            last.level,
            hashed
                .iter()
                .map(|l| format!("{:.1}", l.points_per_used_slot()))
                .collect::<Vec<_>>()
                .join(" ")
        ),
        _ => format!("2^{log2_table_size} slots per level; every level dense (no collisions)"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::unical::hash_grid::HashGridConfig;

    fn grid(log2_table_size: u32) -> HashGrid {
        HashGrid::new(
            HashGridConfig {
                levels: 4,
                log2_table_size,
                base_resolution: 4.0,
                max_resolution: 64.0,
            },
            0,
        )
    }

    /// The unit cube cut into `n³` disjoint boxes.
    fn cubes(n: usize) -> Vec<([f64; 3], [f64; 3])> {
        let s = 1.0 / n as f64;
        let mut out = Vec::new();
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let lo = [x as f64 * s, y as f64 * s, z as f64 * s];
                    out.push((lo, lo.map(|v| v + s)));
                }
            }
        }
        out
    }

    #[test]
    fn the_whole_box_counts_each_lattice_point_once_however_it_is_cut() {
        let g = grid(12);
        let whole = level_loads(&g, &[([0.0; 3], [1.0; 3])]);
        let cut = level_loads(&g, &cubes(5));
        assert_eq!(whole, cut);
        for load in &whole {
            let (scale, resolution, _, _) = g.level_layout(load.level);
            // Points at (c − 0.5)/scale in [0, 1): c = 1 … ⌈scale + 0.5⌉ − 1.
            let per_axis = ((scale as f64 + 0.5).ceil() - 1.0) as u64;
            assert_eq!(load.points, per_axis.pow(3), "level {}", load.level);
            assert!(per_axis <= resolution as u64);
            if !load.hashed {
                assert_eq!(
                    load.used_slots, load.points,
                    "a dense level has no collisions"
                );
            }
        }
    }

    #[test]
    fn a_larger_table_spreads_the_same_points_over_more_slots() {
        let boxes = cubes(4);
        let (small, large) = (
            level_loads(&grid(10), &boxes),
            level_loads(&grid(14), &boxes),
        );
        let (s, l) = (small[3], large[3]);
        assert!(s.hashed && l.hashed);
        assert_eq!(s.points, l.points);
        assert!(s.used_slots <= s.slots && s.points_per_used_slot() > 10.0);
        assert!(l.points_per_used_slot() < s.points_per_used_slot() / 4.0);
        let line = summary(&small, 10);
        assert!(
            line.starts_with("2^10 slots per level") && line.contains("levels 1–3"),
            "{line}"
        );
    }

    #[test]
    fn an_empty_scene_loads_nothing() {
        let loads = level_loads(&grid(10), &[]);
        assert!(loads.iter().all(|l| l.points == 0 && l.used_slots == 0));
        assert_eq!(loads[0].points_per_used_slot(), 0.0);
    }
}
