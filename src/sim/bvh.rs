//! A bounding-volume hierarchy over triangles, for the simulator's ray casting.
//!
//! Build: binned SAH (12 bins on the longest centroid axis), leaves of ≤ 4 triangles, nodes in
//! one flat array (left child follows its parent, the right child's index is stored). Traversal:
//! an explicit stack, nearer child first, Möller–Trumbore intersection, all in f32.

use glam::Vec3;

#[derive(Clone, Copy, Debug)]
pub struct Triangle {
    pub v0: Vec3,
    pub e1: Vec3,
    pub e2: Vec3,
    pub material: u32,
    /// The flat face this triangle belongs to (both halves of a quad share one), so that
    /// anti-aliasing and shading interpolation do not see a quad's diagonal as an edge.
    pub face: u32,
}

impl Triangle {
    pub fn new(a: Vec3, b: Vec3, c: Vec3, material: u32) -> Self {
        Self {
            v0: a,
            e1: b - a,
            e2: c - a,
            material,
            face: u32::MAX,
        }
    }
    pub fn normal(&self) -> Vec3 {
        self.e1.cross(self.e2).normalize_or_zero()
    }
    fn bounds(&self) -> (Vec3, Vec3) {
        let (a, b, c) = (self.v0, self.v0 + self.e1, self.v0 + self.e2);
        (a.min(b).min(c), a.max(b).max(c))
    }
    fn centroid(&self) -> Vec3 {
        self.v0 + (self.e1 + self.e2) / 3.0
    }
}

#[derive(Clone, Copy, Debug)]
struct Node {
    min: Vec3,
    max: Vec3,
    /// Leaf: first triangle; inner: index of the right child.
    first_or_right: u32,
    /// Leaf: number of triangles (> 0); inner: 0.
    count: u32,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub triangle: u32,
}

#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    pub triangles: Vec<Triangle>,
}

const BINS: usize = 12;
const LEAF_SIZE: usize = 4;

fn area(min: Vec3, max: Vec3) -> f32 {
    let d = (max - min).max(Vec3::ZERO);
    2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
}

impl Bvh {
    pub fn build(mut triangles: Vec<Triangle>) -> Self {
        let mut nodes = Vec::with_capacity(2 * triangles.len() / LEAF_SIZE + 1);
        if !triangles.is_empty() {
            let n = triangles.len();
            build_node(&mut triangles, 0, n, &mut nodes);
        }
        Self { nodes, triangles }
    }

    /// Nearest hit with t in (t_min, t_max).
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<Hit> {
        self.traverse(origin, dir, t_min, t_max, false)
    }

    /// Distance along the ray to one triangle, if it is hit within (t_min, t_max).
    pub fn intersect_triangle(
        &self,
        triangle: u32,
        origin: Vec3,
        dir: Vec3,
        t_min: f32,
        t_max: f32,
    ) -> Option<f32> {
        let tri = self.triangles.get(triangle as usize)?;
        intersect_triangle(tri, origin, dir, t_min, t_max)
    }

    /// Whether anything blocks the segment (shadow rays).
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> bool {
        self.traverse(origin, dir, t_min, t_max, true).is_some()
    }

    fn traverse(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_min: f32,
        mut t_max: f32,
        any: bool,
    ) -> Option<Hit> {
        if self.nodes.is_empty() {
            return None;
        }
        let inv = Vec3::ONE / dir;
        let mut best: Option<Hit> = None;
        let mut stack = [0u32; 64];
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            let node = &self.nodes[stack[sp] as usize];
            if node.count > 0 {
                let first = node.first_or_right as usize;
                for (k, tri) in self.triangles[first..first + node.count as usize]
                    .iter()
                    .enumerate()
                {
                    if let Some(t) = intersect_triangle(tri, origin, dir, t_min, t_max) {
                        t_max = t;
                        best = Some(Hit {
                            t,
                            triangle: (first + k) as u32,
                        });
                        if any {
                            return best;
                        }
                    }
                }
                continue;
            }
            let left = stack[sp] + 1;
            let right = node.first_or_right;
            let tl = slab(&self.nodes[left as usize], origin, inv, t_min, t_max);
            let tr = slab(&self.nodes[right as usize], origin, inv, t_min, t_max);
            match (tl, tr) {
                (Some(a), Some(b)) => {
                    // Push the farther first so the nearer is popped next.
                    let (near, far) = if a <= b { (left, right) } else { (right, left) };
                    if sp + 2 <= stack.len() {
                        stack[sp] = far;
                        stack[sp + 1] = near;
                        sp += 2;
                    }
                }
                (Some(_), None) => {
                    stack[sp] = left;
                    sp += 1;
                }
                (None, Some(_)) => {
                    stack[sp] = right;
                    sp += 1;
                }
                (None, None) => {}
            }
        }
        best
    }
}

fn slab(node: &Node, origin: Vec3, inv: Vec3, t_min: f32, t_max: f32) -> Option<f32> {
    let t0 = (node.min - origin) * inv;
    let t1 = (node.max - origin) * inv;
    let near = t0.min(t1).max_element().max(t_min);
    let far = t0.max(t1).min_element().min(t_max);
    (near <= far).then_some(near)
}

fn intersect_triangle(
    tri: &Triangle,
    origin: Vec3,
    dir: Vec3,
    t_min: f32,
    t_max: f32,
) -> Option<f32> {
    let p = dir.cross(tri.e2);
    let det = tri.e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv_det = 1.0 / det;
    let s = origin - tri.v0;
    let u = s.dot(p) * inv_det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(tri.e1);
    let v = dir.dot(q) * inv_det;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = tri.e2.dot(q) * inv_det;
    (t > t_min && t < t_max).then_some(t)
}

fn build_node(tris: &mut [Triangle], start: usize, end: usize, nodes: &mut Vec<Node>) -> u32 {
    let index = nodes.len() as u32;
    let (mut min, mut max) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    let (mut cmin, mut cmax) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    for t in &tris[start..end] {
        let (a, b) = t.bounds();
        min = min.min(a);
        max = max.max(b);
        let c = t.centroid();
        cmin = cmin.min(c);
        cmax = cmax.max(c);
    }
    nodes.push(Node {
        min,
        max,
        first_or_right: start as u32,
        count: (end - start) as u32,
    });
    let n = end - start;
    if n <= LEAF_SIZE {
        return index;
    }
    let extent = cmax - cmin;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    if extent[axis] < 1e-9 {
        return index; // all centroids coincide: keep as a (large) leaf
    }
    // Binned SAH.
    let bin_of = |t: &Triangle| {
        (((t.centroid()[axis] - cmin[axis]) / extent[axis] * BINS as f32) as usize).min(BINS - 1)
    };
    let mut bin_bounds = [(Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)); BINS];
    let mut bin_count = [0usize; BINS];
    for t in &tris[start..end] {
        let b = bin_of(t);
        let (a, c) = t.bounds();
        bin_bounds[b] = (bin_bounds[b].0.min(a), bin_bounds[b].1.max(c));
        bin_count[b] += 1;
    }
    let mut best = (f32::MAX, 0usize);
    for split in 1..BINS {
        let (mut lmin, mut lmax, mut ln) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN), 0);
        let (mut rmin, mut rmax, mut rn) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN), 0);
        for b in 0..BINS {
            if bin_count[b] == 0 {
                continue;
            }
            if b < split {
                lmin = lmin.min(bin_bounds[b].0);
                lmax = lmax.max(bin_bounds[b].1);
                ln += bin_count[b];
            } else {
                rmin = rmin.min(bin_bounds[b].0);
                rmax = rmax.max(bin_bounds[b].1);
                rn += bin_count[b];
            }
        }
        if ln == 0 || rn == 0 {
            continue;
        }
        let cost = area(lmin, lmax) * ln as f32 + area(rmin, rmax) * rn as f32;
        if cost < best.0 {
            best = (cost, split);
        }
    }
    if best.0 == f32::MAX {
        return index;
    }
    // Partition.
    let slice = &mut tris[start..end];
    let mut i = 0;
    let mut j = slice.len();
    while i < j {
        if bin_of(&slice[i]) < best.1 {
            i += 1;
        } else {
            j -= 1;
            slice.swap(i, j);
        }
    }
    let mid = start + i;
    if mid == start || mid == end {
        return index;
    }
    nodes[index as usize].count = 0;
    build_node(tris, start, mid, nodes);
    let right = build_node(tris, mid, end, nodes);
    nodes[index as usize].first_or_right = right;
    index
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(tris: &[Triangle], o: Vec3, d: Vec3) -> Option<f32> {
        tris.iter()
            .filter_map(|t| intersect_triangle(t, o, d, 1e-4, f32::MAX))
            .min_by(f32::total_cmp)
    }

    #[test]
    fn matches_brute_force() {
        let mut tris = Vec::new();
        for i in 0..500u32 {
            let h = |k: u32| crate::sim::noise::hash3(i as i32, k as i32, 0, 9) * 40.0 - 20.0;
            let a = Vec3::new(h(0), h(1), h(2));
            tris.push(Triangle::new(
                a,
                a + Vec3::new(h(3) * 0.1, h(4) * 0.1, h(5) * 0.1),
                a + Vec3::new(h(6) * 0.1, h(7) * 0.1, h(8) * 0.1),
                i,
            ));
        }
        let bvh = Bvh::build(tris.clone());
        let mut hits = 0;
        for k in 0..2000 {
            let h = |j: u32| crate::sim::noise::hash3(k, j as i32, 1, 3) * 2.0 - 1.0;
            let o = Vec3::new(h(0), h(1), h(2)) * 30.0;
            let d = Vec3::new(h(3), h(4), h(5)).normalize_or_zero();
            let got = bvh.intersect(o, d, 1e-4, f32::MAX).map(|h| h.t);
            let want = brute(&tris, o, d);
            assert_eq!(got.is_some(), want.is_some());
            if let (Some(a), Some(b)) = (got, want) {
                assert!((a - b).abs() < 1e-4);
                hits += 1;
                assert!(bvh.occluded(o, d, 1e-4, f32::MAX));
            }
        }
        assert!(hits > 10, "{hits}");
    }
}
