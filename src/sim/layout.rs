//! Where the simulated world's objects go: a triangle builder with one material table and an
//! occupancy grid, and the placement per scene (buildings with windows, doors and signs, poles
//! and street lights, parked cars, trees, sidewalks, checkerboards) along both sides of the
//! driven path with a seeded RNG, never within the road of any part of the path.

use std::collections::HashSet;

use glam::Vec3;

use super::bvh::Triangle;
use super::noise::{hash64, value2};
use super::world::{
    CURB_HEIGHT_M, Checkerboard, GroundMap, Material, ROAD_HALF_WIDTH_M, SIDEWALK_OUTER_M,
};

/// A tiny seeded RNG for placement.
pub(super) struct Rng(pub(super) u64);
impl Rng {
    pub(super) fn next(&mut self) -> f32 {
        self.0 = hash64(self.0);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    pub(super) fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next()
    }
    pub(super) fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[((self.next() * items.len() as f32) as usize).min(items.len() - 1)]
    }
}

pub(super) struct Builder {
    pub(super) tris: Vec<Triangle>,
    pub(super) materials: Vec<Material>,
    pub(super) occupied: HashSet<(i32, i32)>,
}

impl Builder {
    pub(super) fn material(&mut self, m: Material) -> u32 {
        if let Some(i) = self.materials.iter().position(|x| *x == m) {
            return i as u32;
        }
        self.materials.push(m);
        (self.materials.len() - 1) as u32
    }

    pub(super) fn quad(&mut self, a: Vec3, b: Vec3, c: Vec3, d: Vec3, m: u32) {
        self.tris.push(Triangle::new(a, b, c, m));
        self.tris.push(Triangle::new(a, c, d, m));
    }

    /// An oriented box: base centre on the ground plane at `base`, heading `yaw`, size (l, w, h).
    pub(super) fn boxed(&mut self, base: Vec3, yaw: f32, size: Vec3, m: u32) {
        let (f, l) = (
            Vec3::new(yaw.cos(), yaw.sin(), 0.0),
            Vec3::new(-yaw.sin(), yaw.cos(), 0.0),
        );
        let (hx, hy) = (f * size.x * 0.5, l * size.y * 0.5);
        let z0 = Vec3::new(0.0, 0.0, base.z);
        let z1 = Vec3::new(0.0, 0.0, base.z + size.z);
        let c = Vec3::new(base.x, base.y, 0.0);
        let corners = [c - hx - hy, c + hx - hy, c + hx + hy, c - hx + hy];
        for k in 0..4 {
            let (a, b) = (corners[k], corners[(k + 1) % 4]);
            self.quad(a + z0, b + z0, b + z1, a + z1, m);
        }
        self.quad(
            corners[0] + z1,
            corners[1] + z1,
            corners[2] + z1,
            corners[3] + z1,
            m,
        );
        self.quad(
            corners[3] + z0,
            corners[2] + z0,
            corners[1] + z0,
            corners[0] + z0,
            m,
        );
    }

    pub(super) fn cylinder(&mut self, base: Vec3, radius: f32, height: f32, sides: u32, m: u32) {
        let ring = |k: u32| {
            let a = k as f32 / sides as f32 * std::f32::consts::TAU;
            base + Vec3::new(a.cos() * radius, a.sin() * radius, 0.0)
        };
        let up = Vec3::new(0.0, 0.0, height);
        for k in 0..sides {
            let (a, b) = (ring(k), ring(k + 1));
            self.quad(a, b, b + up, a + up, m);
            self.tris.push(Triangle::new(base + up, a + up, b + up, m));
        }
    }

    /// A lumpy sphere (subdivided octahedron with noise displacement), for foliage.
    pub(super) fn blob(&mut self, center: Vec3, radius: f32, seed: u64, m: u32) {
        let dirs = [Vec3::X, Vec3::Y, -Vec3::X, -Vec3::Y];
        let n = 4;
        let point = |d: Vec3| {
            let d = d.normalize_or_zero();
            let bump = 0.75 + 0.5 * value2(d.x * 2.3 + d.z * 1.7, d.y * 2.3 - d.z, seed);
            center + d * radius * bump
        };
        for pole in [Vec3::Z, -Vec3::Z] {
            for k in 0..4 {
                let (a, b) = (dirs[k], dirs[(k + 1) % 4]);
                // Subdivide the face (pole, a, b) into n² triangles.
                let p = |i: u32, j: u32| {
                    let (fi, fj) = (i as f32 / n as f32, j as f32 / n as f32);
                    pole * (1.0 - fi - fj) + a * fi + b * fj
                };
                for i in 0..n {
                    for j in 0..n - i {
                        let (v0, v1, v2) = (point(p(i, j)), point(p(i + 1, j)), point(p(i, j + 1)));
                        if pole.z > 0.0 {
                            self.tris.push(Triangle::new(v0, v1, v2, m))
                        } else {
                            self.tris.push(Triangle::new(v0, v2, v1, m))
                        }
                        if i + j + 1 < n {
                            let v3 = point(p(i + 1, j + 1));
                            if pole.z > 0.0 {
                                self.tris.push(Triangle::new(v1, v3, v2, m))
                            } else {
                                self.tris.push(Triangle::new(v1, v2, v3, m))
                            }
                        }
                    }
                }
            }
        }
    }

    /// Claim the 1 m cells of a footprint; false (and nothing claimed) if any is taken.
    pub(super) fn claim(&mut self, center: Vec3, yaw: f32, length: f32, width: f32) -> bool {
        let (f, l) = (
            Vec3::new(yaw.cos(), yaw.sin(), 0.0),
            Vec3::new(-yaw.sin(), yaw.cos(), 0.0),
        );
        let mut cells = Vec::new();
        let (nl, nw) = ((length / 0.5).ceil() as i32, (width / 0.5).ceil() as i32);
        for a in 0..=nl {
            for b in 0..=nw {
                let p = center
                    + f * (a as f32 * 0.5 - length * 0.5)
                    + l * (b as f32 * 0.5 - width * 0.5);
                cells.push((p.x.floor() as i32, p.y.floor() as i32));
            }
        }
        if cells.iter().any(|c| self.occupied.contains(c)) {
            return false;
        }
        self.occupied.extend(cells);
        true
    }
}

/// Points along the path every `step` metres with their heading (yaw) and the left normal.
/// Number the flat faces: a triangle joins its predecessor's face when both have the same
/// material, lie in one plane and share a vertex (the builder emits a quad's halves in a row).
pub(super) fn assign_faces(tris: &mut [Triangle]) {
    let mut face = 0u32;
    for k in 0..tris.len() {
        if k > 0 {
            let (a, b) = (&tris[k - 1], &tris[k]);
            let (na, nb) = (a.normal(), b.normal());
            let verts = |t: &Triangle| [t.v0, t.v0 + t.e1, t.v0 + t.e2];
            let shared = verts(a)
                .iter()
                .any(|p| verts(b).iter().any(|q| p.distance_squared(*q) < 1e-8));
            let coplanar = na.dot(nb) > 0.9999 && (b.v0 - a.v0).dot(na).abs() < 1e-3;
            if !(a.material == b.material && coplanar && shared) {
                face += 1;
            }
        }
        tris[k].face = face;
    }
}

pub(super) fn stations(path: &[Vec3], step: f32) -> Vec<(Vec3, f32)> {
    let mut out = Vec::new();
    let mut carry = 0.0;
    for seg in path.windows(2) {
        let (a, b) = (seg[0], seg[1]);
        let d = Vec3::new(b.x - a.x, b.y - a.y, 0.0);
        let len = d.length();
        if len < 1e-6 {
            continue;
        }
        let yaw = d.y.atan2(d.x);
        let mut s = carry;
        while s < len {
            out.push((a + d * (s / len), yaw));
            s += step;
        }
        carry = s - len;
    }
    out
}

pub(super) fn footprint_clear(
    ground: &GroundMap,
    center: Vec3,
    yaw: f32,
    length: f32,
    width: f32,
    min_d: f32,
) -> bool {
    let (f, l) = (
        Vec3::new(yaw.cos(), yaw.sin(), 0.0),
        Vec3::new(-yaw.sin(), yaw.cos(), 0.0),
    );
    for (a, b) in [
        (-0.5, -0.5),
        (0.5, -0.5),
        (0.5, 0.5),
        (-0.5, 0.5),
        (0.0, 0.0),
    ] {
        let p = center + f * (a * length) + l * (b * width);
        if ground.abs_distance(p.x, p.y) < min_d {
            return false;
        }
    }
    true
}

pub(super) const CAR_COLORS: [[f32; 3]; 8] = [
    [0.85, 0.85, 0.87],
    [0.08, 0.08, 0.09],
    [0.55, 0.06, 0.05],
    [0.10, 0.18, 0.45],
    [0.45, 0.47, 0.50],
    [0.80, 0.75, 0.60],
    [0.12, 0.30, 0.16],
    [0.90, 0.55, 0.10],
];
pub(super) const FACADE_COLORS: [[f32; 3]; 6] = [
    [0.62, 0.55, 0.48],
    [0.70, 0.68, 0.62],
    [0.45, 0.30, 0.24],
    [0.78, 0.74, 0.66],
    [0.52, 0.56, 0.60],
    [0.66, 0.50, 0.38],
];

pub(super) fn add_sidewalks(b: &mut Builder, path: &[Vec3], ground: &GroundMap) {
    let m = b.material(Material::Sidewalk);
    let st = stations(path, 2.0);
    let up = Vec3::new(0.0, 0.0, CURB_HEIGHT_M);
    for w in st.windows(2) {
        let ((p0, y0), (p1, y1)) = (w[0], w[1]);
        for side in [1.0f32, -1.0] {
            let l0 = Vec3::new(-y0.sin(), y0.cos(), 0.0) * side;
            let l1 = Vec3::new(-y1.sin(), y1.cos(), 0.0) * side;
            let (a0, a1) = (p0 + l0 * ROAD_HALF_WIDTH_M, p1 + l1 * ROAD_HALF_WIDTH_M);
            let (o0, o1) = (p0 + l0 * SIDEWALK_OUTER_M, p1 + l1 * SIDEWALK_OUTER_M);
            // Skip where this piece of sidewalk would lie on another part of the road.
            let clear = [a0, a1, o0, o1, (o0 + o1) * 0.5]
                .iter()
                .all(|q| ground.abs_distance(q.x, q.y) > ROAD_HALF_WIDTH_M - 0.2);
            if !clear {
                continue;
            }
            let (a, bq, c, d) = if side > 0.0 {
                (a0, a1, o1, o0)
            } else {
                (a1, a0, o0, o1)
            };
            b.quad(a + up, bq + up, c + up, d + up, m); // top
            b.quad(bq, a, a + up, bq + up, m); // curb face
        }
    }
}

pub(super) fn add_car(b: &mut Builder, pos: Vec3, yaw: f32, rng: &mut Rng) {
    let paint = b.material(Material::CarPaint {
        color: rng.pick(&CAR_COLORS),
    });
    let glass = b.material(Material::Glass);
    let tire = b.material(Material::Tire);
    let (len, wid) = (rng.range(4.2, 4.9), rng.range(1.75, 1.9));
    let f = Vec3::new(yaw.cos(), yaw.sin(), 0.0);
    let l = Vec3::new(-yaw.sin(), yaw.cos(), 0.0);
    b.boxed(
        pos + Vec3::new(0.0, 0.0, 0.3),
        yaw,
        Vec3::new(len, wid, 0.75),
        paint,
    );
    b.boxed(
        pos - f * 0.2 + Vec3::new(0.0, 0.0, 1.05),
        yaw,
        Vec3::new(len * 0.5, wid * 0.9, 0.45),
        glass,
    );
    b.boxed(
        pos - f * 0.2 + Vec3::new(0.0, 0.0, 1.5),
        yaw,
        Vec3::new(len * 0.48, wid * 0.88, 0.05),
        paint,
    );
    for (a, c) in [(0.33, 0.5), (0.33, -0.5), (-0.33, 0.5), (-0.33, -0.5)] {
        let wheel = pos + f * (a * len) + l * (c * (wid - 0.1));
        b.boxed(wheel, yaw, Vec3::new(0.66, 0.24, 0.66), tire);
    }
}

pub(super) fn add_pole(b: &mut Builder, pos: Vec3, yaw_to_road: f32, light: bool) {
    let metal = b.material(Material::Metal {
        color: [0.35, 0.36, 0.38],
    });
    let h = if light { 7.5 } else { 3.0 };
    b.cylinder(pos, 0.1, h, 8, metal);
    if light {
        let dir = Vec3::new(yaw_to_road.cos(), yaw_to_road.sin(), 0.0);
        let head = b.material(Material::LampHead);
        b.boxed(
            pos + dir * 1.0 + Vec3::new(0.0, 0.0, h - 0.15),
            yaw_to_road,
            Vec3::new(2.0, 0.12, 0.12),
            metal,
        );
        b.boxed(
            pos + dir * 1.9 + Vec3::new(0.0, 0.0, h - 0.3),
            yaw_to_road,
            Vec3::new(0.6, 0.3, 0.18),
            head,
        );
    } else {
        // A traffic sign plate.
        let sign = b.material(Material::Poster {
            seed: (pos.x.to_bits() ^ pos.y.to_bits()) % 97,
        });
        b.boxed(
            pos + Vec3::new(0.0, 0.0, 2.2),
            yaw_to_road + std::f32::consts::FRAC_PI_2,
            Vec3::new(0.05, 0.75, 0.75),
            sign,
        );
    }
}

pub(super) fn add_tree(b: &mut Builder, pos: Vec3, rng: &mut Rng) {
    let bark = b.material(Material::Bark);
    let leaf = b.material(Material::Foliage {
        color: rng.pick(&[[0.20, 0.33, 0.12], [0.15, 0.28, 0.10], [0.28, 0.36, 0.14]]),
    });
    let h = rng.range(2.5, 4.0);
    b.cylinder(pos, 0.15, h, 8, bark);
    let r = rng.range(1.6, 2.6);
    b.blob(
        pos + Vec3::new(0.0, 0.0, h + r * 0.6),
        r,
        (pos.x * 100.0) as u64,
        leaf,
    );
}

pub(super) fn add_urban(b: &mut Builder, path: &[Vec3], ground: &GroundMap, rng: &mut Rng) {
    // Buildings in rows on both sides.
    for side in [1.0f32, -1.0] {
        for (p, yaw) in stations(path, 4.0) {
            let l = Vec3::new(-yaw.sin(), yaw.cos(), 0.0) * side;
            let (width, depth, height) = (
                rng.range(8.0, 20.0),
                rng.range(8.0, 14.0),
                rng.range(5.5, 22.0),
            );
            let setback = SIDEWALK_OUTER_M + rng.range(0.5, 4.0);
            let center = p + l * (setback + depth * 0.5);
            if !footprint_clear(ground, center, yaw, width, depth, SIDEWALK_OUTER_M + 0.3)
                || !b.claim(center, yaw, width, depth)
            {
                continue;
            }
            let facade = b.material(Material::Facade {
                color: rng.pick(&FACADE_COLORS),
                seed: (rng.next() * 1000.0) as u32,
            });
            b.boxed(center, yaw, Vec3::new(width, depth, height), facade);
            // Door, signs and posters on the street face.
            let f = Vec3::new(yaw.cos(), yaw.sin(), 0.0);
            let face = center - l * (depth * 0.5 + 0.03);
            let door = b.material(Material::Metal {
                color: [0.25, 0.15, 0.10],
            });
            b.boxed(
                face + f * rng.range(-width * 0.3, width * 0.3),
                yaw,
                Vec3::new(1.2, 0.08, 2.2),
                door,
            );
            if rng.next() < 0.7 {
                let poster = b.material(Material::Poster {
                    seed: (rng.next() * 10_000.0) as u32,
                });
                let at = face - l * 0.02
                    + f * rng.range(-width * 0.3, width * 0.3)
                    + Vec3::new(0.0, 0.0, rng.range(0.4, 1.0));
                b.boxed(
                    at,
                    yaw,
                    Vec3::new(rng.range(1.5, 3.5), 0.05, rng.range(1.2, 2.2)),
                    poster,
                );
            }
            if rng.next() < 0.5 {
                let sign = b.material(Material::Poster {
                    seed: (rng.next() * 10_000.0) as u32,
                });
                let at = face - l * 0.3
                    + f * rng.range(-width * 0.3, width * 0.3)
                    + Vec3::new(0.0, 0.0, 3.3);
                b.boxed(at, yaw, Vec3::new(rng.range(2.0, 5.0), 0.25, 0.8), sign);
            }
            if rng.next() < 0.25 {
                let billboard = b.material(Material::Poster {
                    seed: (rng.next() * 10_000.0) as u32,
                });
                b.boxed(
                    center + Vec3::new(0.0, 0.0, height),
                    yaw,
                    Vec3::new(6.0, 0.3, 3.0),
                    billboard,
                );
            }
        }
        // Rows behind the street front: taller blocks that fill the skyline.
        for (setback, step, hmax) in [(26.0f32, 9.0f32, 32.0f32), (48.0, 12.0, 45.0)] {
            for (p, yaw) in stations(path, step) {
                let l = Vec3::new(-yaw.sin(), yaw.cos(), 0.0) * side;
                let (width, depth, height) = (
                    rng.range(10.0, 24.0),
                    rng.range(10.0, 18.0),
                    rng.range(9.0, hmax),
                );
                let center = p + l * (setback + rng.range(0.0, 6.0) + depth * 0.5);
                if !footprint_clear(ground, center, yaw, width, depth, 20.0)
                    || !b.claim(center, yaw, width, depth)
                {
                    continue;
                }
                let facade = b.material(Material::Facade {
                    color: rng.pick(&FACADE_COLORS),
                    seed: (rng.next() * 1000.0) as u32,
                });
                b.boxed(center, yaw, Vec3::new(width, depth, height), facade);
            }
        }
        // Street furniture on the sidewalk.
        for (k, (p, yaw)) in stations(path, 12.5).into_iter().enumerate() {
            let l = Vec3::new(-yaw.sin(), yaw.cos(), 0.0) * side;
            let at = p + l * (ROAD_HALF_WIDTH_M + 0.6) + Vec3::new(0.0, 0.0, CURB_HEIGHT_M);
            if !footprint_clear(ground, at, yaw, 0.5, 0.5, ROAD_HALF_WIDTH_M + 0.3)
                || !b.claim(at, yaw, 0.6, 0.6)
            {
                continue;
            }
            let to_road = (-l.y).atan2(-l.x);
            match k % 4 {
                0 => add_pole(b, at, to_road, true),
                2 => add_tree(b, at + l * 1.2, rng),
                1 if rng.next() < 0.5 => add_pole(b, at, to_road, false),
                _ => {
                    if rng.next() < 0.5 {
                        let bush = b.material(Material::Foliage {
                            color: [0.18, 0.30, 0.12],
                        });
                        b.blob(at + l * 1.5 + Vec3::new(0.0, 0.0, 0.4), 0.7, k as u64, bush);
                    }
                }
            }
        }
        // Parked cars in the outer lane.
        for (p, yaw) in stations(path, 7.0) {
            if rng.next() < 0.45 {
                continue;
            }
            let l = Vec3::new(-yaw.sin(), yaw.cos(), 0.0) * side;
            let at = p + l * 5.6;
            // Not on any other part of the road's inner lanes (crossings).
            if ground.abs_distance(at.x, at.y) < 5.0 || !b.claim(at, yaw, 5.0, 2.0) {
                continue;
            }
            let heading = if side > 0.0 {
                yaw
            } else {
                yaw + std::f32::consts::PI
            };
            add_car(b, at, heading, rng);
        }
    }
}

pub(super) fn add_parking_lot(b: &mut Builder, path: &[Vec3], ground: &GroundMap, rng: &mut Rng) {
    // A few parked cars in bays away from the driven path, light poles and one low building.
    let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    for p in path {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    for _ in 0..40 {
        let x = (rng.range(lo.x - 25.0, hi.x + 25.0) / 2.6).floor() * 2.6 + 1.3;
        let y = (rng.range(lo.y - 25.0, hi.y + 25.0) / 11.0).floor() * 11.0
            + 2.75 * if rng.next() < 0.5 { 1.0 } else { 3.0 };
        let at = Vec3::new(x, y, 0.0);
        if ground.abs_distance(x, y) < 4.0 || !b.claim(at, std::f32::consts::FRAC_PI_2, 5.0, 2.2) {
            continue;
        }
        add_car(
            b,
            at,
            std::f32::consts::FRAC_PI_2
                + if rng.next() < 0.5 {
                    0.0
                } else {
                    std::f32::consts::PI
                },
            rng,
        );
    }
    for k in 0..8 {
        let at = Vec3::new(
            rng.range(lo.x - 30.0, hi.x + 30.0),
            rng.range(lo.y - 30.0, hi.y + 30.0),
            0.0,
        );
        if ground.abs_distance(at.x, at.y) > 4.0 && b.claim(at, 0.0, 0.6, 0.6) {
            add_pole(b, at, k as f32, true);
        }
    }
    let facade = b.material(Material::Facade {
        color: [0.7, 0.68, 0.62],
        seed: 4,
    });
    let at = Vec3::new((lo.x + hi.x) * 0.5, hi.y + 40.0, 0.0);
    b.boxed(at, 0.0, Vec3::new(60.0, 15.0, 6.0), facade);
}

pub(super) fn add_featureless(b: &mut Builder, path: &[Vec3], ground: &GroundMap, rng: &mut Rng) {
    for (k, (p, yaw)) in stations(path, 60.0).into_iter().enumerate() {
        let side = if k % 2 == 0 { 1.0 } else { -1.0 };
        let l = Vec3::new(-yaw.sin(), yaw.cos(), 0.0) * side;
        let at = p + l * (ROAD_HALF_WIDTH_M + 0.8) + Vec3::new(0.0, 0.0, CURB_HEIGHT_M);
        if footprint_clear(ground, at, yaw, 0.5, 0.5, ROAD_HALF_WIDTH_M + 0.3)
            && b.claim(at, 0.0, 0.6, 0.6)
            && rng.next() < 0.8
        {
            add_pole(b, at, (-l.y).atan2(-l.x), true);
        }
    }
}

/// Stationary scene: boards in front of and beside the vehicle, facing it, in varied poses.
pub(super) fn add_checkerboards(
    b: &mut Builder,
    path: &[Vec3],
    rng: &mut Rng,
    raised_m: f32,
) -> Vec<Checkerboard> {
    // Only a clearly taller rig gets the second ring (a car's scene stays exactly as it was:
    // PandaSet's PandarGT sits 0.3 m above the Pandar64).
    let raised_m = if raised_m > 0.6 { raised_m } else { 0.0 };
    // The stationary vehicle stands in the middle of its short road.
    let mid = path.len() / 2;
    let origin = path.get(mid).copied().unwrap_or(Vec3::ZERO);
    let heading = match (path.get(mid.saturating_sub(1)), path.get(mid + 1)) {
        (Some(a), Some(c)) => (c.y - a.y).atan2(c.x - a.x),
        _ => 0.0,
    };
    let metal = b.material(Material::Metal {
        color: [0.3, 0.3, 0.3],
    });
    let mut boards = Vec::new();
    // (bearing from heading in degrees, distance m, height m, tilt deg, swing deg)
    let layout = [
        (0.0, 7.0, 1.6, 0.0, 0.0),
        (-25.0, 6.0, 1.2, 15.0, -20.0),
        (25.0, 8.0, 1.8, -10.0, 25.0),
        (60.0, 6.5, 1.4, 10.0, 10.0),
        (-60.0, 7.5, 1.5, -15.0, -10.0),
        (90.0, 6.0, 1.5, 5.0, 0.0),
        (-90.0, 6.0, 1.5, -5.0, 0.0),
        (180.0, 7.0, 1.5, 0.0, 15.0),
    ];
    // A tall rig's ring: the same poses turned 20° (not hidden behind the first ring), 1.5×
    // as far and raised (its stands are taller).
    let raised = layout.map(|(bearing, dist, height, tilt, swing)| {
        (bearing + 20.0, dist * 1.5, height + raised_m, tilt, swing)
    });
    let rings = if raised_m > 0.0 {
        layout
            .iter()
            .chain(raised.iter())
            .copied()
            .collect::<Vec<_>>()
    } else {
        layout.to_vec()
    };
    for (k, (bearing, dist, height, tilt, swing)) in rings.into_iter().enumerate() {
        let bearing = heading + (bearing as f32 + rng.range(-4.0, 4.0)).to_radians();
        let center = origin
            + Vec3::new(bearing.cos(), bearing.sin(), 0.0) * dist
            + Vec3::new(0.0, 0.0, height);
        // Board normal points back at the vehicle (at its sensors' height), then swung and
        // tilted.
        let toward = (origin + Vec3::new(0.0, 0.0, 1.5 + raised_m) - center).normalize_or_zero();
        let yaw = toward.y.atan2(toward.x) + (swing as f32).to_radians();
        let pitch = (tilt as f32).to_radians();
        let normal = Vec3::new(
            yaw.cos() * pitch.cos(),
            yaw.sin() * pitch.cos(),
            pitch.sin(),
        );
        let u_axis = Vec3::Z.cross(normal).normalize_or_zero();
        let v_axis = normal.cross(u_axis).normalize_or_zero() * -1.0; // v points down
        let (su, sv, sq, margin) = (8u32, 6u32, 0.1f32, 0.08f32);
        let board_origin =
            center - u_axis * (su as f32 * sq * 0.5) - v_axis * (sv as f32 * sq * 0.5);
        let index = boards.len() as u32;
        let m = b.material(Material::Board { index });
        let w = su as f32 * sq + 2.0 * margin;
        let h = sv as f32 * sq + 2.0 * margin;
        let c0 = board_origin - u_axis * margin - v_axis * margin;
        let (a, bb, c, d) = (
            c0,
            c0 + u_axis * w,
            c0 + u_axis * w + v_axis * h,
            c0 + v_axis * h,
        );
        // Front face toward the vehicle (normal = -(u × v) is handled in shading), back face too.
        b.quad(a, d, c, bb, m);
        b.quad(
            a + normal * -0.02,
            bb + normal * -0.02,
            c + normal * -0.02,
            d + normal * -0.02,
            m,
        );
        // A stand.
        let foot = Vec3::new(center.x, center.y, 0.0) - normal * 0.1;
        b.cylinder(foot, 0.03, (center.z - h * 0.5).max(0.1), 6, metal);
        boards.push(Checkerboard {
            origin: board_origin,
            u_axis,
            v_axis,
            squares_u: su,
            squares_v: sv,
            square_m: sq,
            margin_m: margin,
        });
        let _ = k;
    }
    boards
}
