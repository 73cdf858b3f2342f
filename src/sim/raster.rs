//! Primary visibility by rasterisation: which triangle a camera sees first in each direction.
//!
//! Tracing every primary ray through the BVH dominated the simulator's image time. The camera's
//! rays all start at one point, so the first triangle along each of them is what a rasteriser
//! with a depth buffer computes, at a fraction of the cost. The rasteriser works in a virtual
//! pinhole image that covers every ray direction of the real camera (distortion included): its
//! samples sit at integer coordinates and keep the nearest triangle by interpolated 1/z. A ray
//! then looks at the four samples around its own virtual coordinates: if they agree, that
//! triangle (or none) is its candidate and the caller confirms it with one exact ray–triangle
//! intersection; if they disagree the ray is on a silhouette and the caller traces the BVH. The
//! ground plane is not rasterised (it is analytic in the world) and is compared by the caller.
//!
//! The image is rasterised in horizontal bands in parallel; each band walks the triangles'
//! screen bounds, so the work is the covered samples plus a small setup per triangle and band.

use glam::{Quat, Vec2, Vec3};
use rayon::prelude::*;

use super::bvh::Triangle;
use super::noise::floor;

/// A virtual pinhole camera: `u = fx·x/z + cx`, `v = fy·y/z + cy`, samples at integer (u, v).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pinhole {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

/// Rays closer than this to the image plane's horizon (z / |d|) are not rasterised.
const MIN_Z: f32 = 0.08;
const NEAR_M: f32 = 0.02;
/// The triangle id of a sample that sees no triangle.
pub const NONE: u32 = u32::MAX;
/// [`Pinhole::sample_of`] for a ray outside the virtual image.
pub const OUTSIDE: u32 = u32::MAX;
/// Largest virtual image side; wider fields of view get a smaller virtual focal length.
const MAX_SIDE: f32 = 4096.0;

impl Pinhole {
    /// The virtual camera covering `dirs` (unit rays in the camera frame, zero for invalid
    /// pixels) at focal lengths `fx`, `fy`; `None` when some ray points sideways or backwards
    /// (wide fisheyes), in which case the caller traces every ray.
    pub fn covering(dirs: &[Vec3], fx: f32, fy: f32, cx: f32, cy: f32) -> Option<Self> {
        let (mut lo, mut hi) = (Vec2::splat(f32::MAX), Vec2::splat(f32::MIN));
        for d in dirs.iter().filter(|d| **d != Vec3::ZERO) {
            if d.z < MIN_Z {
                return None;
            }
            let q = Vec2::new(d.x / d.z, d.y / d.z);
            lo = lo.min(q);
            hi = hi.max(q);
        }
        if lo.x > hi.x {
            return None;
        }
        // Same focal length as the real camera unless the virtual image would be too large.
        let scale = (MAX_SIDE / ((hi.x - lo.x) * fx + 3.0))
            .min(MAX_SIDE / ((hi.y - lo.y) * fy + 3.0))
            .min(1.0);
        let (fx, fy) = (fx * scale, fy * scale);
        // Keep the real principal point's fractional part so undistorted pixels land on samples.
        let shift = |lo: f32, f: f32, c: f32| ((-(lo * f + c)).ceil() + 1.0).max(0.0);
        let (sx, sy) = if scale == 1.0 {
            (shift(lo.x, fx, cx), shift(lo.y, fy, cy))
        } else {
            (1.0 - lo.x * fx - cx, 1.0 - lo.y * fy - cy)
        };
        let (cx, cy) = (cx + sx, cy + sy);
        Some(Self {
            width: (hi.x * fx + cx).ceil() as u32 + 2,
            height: (hi.y * fy + cy).ceil() as u32 + 2,
            fx,
            fy,
            cx,
            cy,
        })
    }

    fn project(&self, p: Vec3) -> Vec2 {
        Vec2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy)
    }

    /// The top-left of the four samples around a camera-frame ray direction (their index in
    /// the image), or [`OUTSIDE`] when the ray is not inside the rasterised image.
    pub fn sample_of(&self, dir: Vec3) -> u32 {
        if dir.z < MIN_Z * 0.5 {
            return OUTSIDE;
        }
        let q = self.project(dir);
        let (x0, y0) = (floor(q.x), floor(q.y));
        if !(x0 >= 0.0
            && y0 >= 0.0
            && x0 + 1.0 < self.width as f32
            && y0 + 1.0 < self.height as f32)
        {
            return OUTSIDE;
        }
        y0 as u32 * self.width + x0 as u32
    }
}

/// What the rasterised samples around a ray say about its first triangle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Candidate {
    /// All four neighbouring samples see this triangle.
    Triangle(u32),
    /// No neighbouring sample sees any triangle.
    Nothing,
    /// The samples disagree (a silhouette) or the ray is outside the virtual image.
    Trace,
}

/// The nearest triangle at every sample of a virtual pinhole image.
#[derive(Clone, Debug)]
pub struct VisibilityBuffer {
    pub camera: Pinhole,
    ids: Vec<u32>,
}

/// A triangle in virtual image coordinates with its vertices' 1/z.
#[derive(Clone, Copy)]
struct ScreenTriangle {
    a: Vec2,
    b: Vec2,
    c: Vec2,
    inv_z: Vec3,
    id: u32,
    min: Vec2,
    max: Vec2,
}

/// Clip a camera-frame triangle against z ≥ NEAR_M; returns up to four vertices (a polygon).
fn clip_near(p: [Vec3; 3]) -> ([Vec3; 4], usize) {
    let mut out = [Vec3::ZERO; 4];
    let mut n = 0;
    for i in 0..3 {
        let (a, b) = (p[i], p[(i + 1) % 3]);
        let (ina, inb) = (a.z >= NEAR_M, b.z >= NEAR_M);
        if ina {
            out[n] = a;
            n += 1;
        }
        if ina != inb && n < 4 {
            let t = (NEAR_M - a.z) / (b.z - a.z);
            out[n] = a + (b - a) * t;
            n += 1;
        }
    }
    (out, n)
}

fn edge(a: Vec2, b: Vec2, p: Vec2) -> f32 {
    (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x)
}

impl VisibilityBuffer {
    /// Rasterise `triangles` seen from a camera at `origin` (world) with `camera_from_world`.
    pub fn render(
        triangles: &[Triangle],
        camera: Pinhole,
        origin: Vec3,
        camera_from_world: Quat,
    ) -> Self {
        let (w, h) = (camera.width as f32, camera.height as f32);
        let screen: Vec<ScreenTriangle> = triangles
            .par_iter()
            .enumerate()
            .with_min_len(256)
            .flat_map_iter(|(id, tri)| {
                let world = [tri.v0, tri.v0 + tri.e1, tri.v0 + tri.e2];
                let cam = world.map(|v| camera_from_world * (v - origin));
                let (poly, n) = clip_near(cam);
                let mut out = Vec::new();
                for k in 1..n.saturating_sub(1) {
                    let verts = [poly[0], poly[k], poly[k + 1]];
                    let [a, b, c] = verts.map(|v| camera.project(v));
                    let min = a.min(b).min(c).max(Vec2::ZERO).ceil();
                    let max = a.max(b).max(c).min(Vec2::new(w - 1.0, h - 1.0)).floor();
                    if min.x > max.x || min.y > max.y || !(min.is_finite() && max.is_finite()) {
                        continue;
                    }
                    out.push(ScreenTriangle {
                        a,
                        b,
                        c,
                        inv_z: Vec3::new(1.0 / verts[0].z, 1.0 / verts[1].z, 1.0 / verts[2].z),
                        id: id as u32,
                        min,
                        max,
                    });
                }
                out
            })
            .collect();
        let width = camera.width as usize;
        let mut ids = vec![NONE; width * camera.height as usize];
        let band_rows = 32usize;
        ids.par_chunks_mut(width * band_rows)
            .enumerate()
            .for_each(|(band, out)| {
                let y0 = (band * band_rows) as f32;
                let y1 = y0 + (out.len() / width) as f32 - 1.0;
                let mut depth = vec![0.0f32; out.len()];
                for t in &screen {
                    let (ylo, yhi) = (t.min.y.max(y0), t.max.y.min(y1));
                    if ylo > yhi {
                        continue;
                    }
                    let area = edge(t.a, t.b, t.c);
                    if area.abs() < 1e-12 {
                        continue;
                    }
                    let inv_area = 1.0 / area;
                    let mut y = ylo;
                    while y <= yhi {
                        let row = (y - y0) as usize * width;
                        // The row's span inside the triangle, one pixel wider on each side than
                        // the edge functions' zero crossings (the test below decides).
                        let (mut lo, mut hi) = (t.min.x, t.max.x);
                        for (a, b) in [(t.b, t.c), (t.c, t.a), (t.a, t.b)] {
                            // edge(a, b, (x, y)) · inv_area = f0 + slope · x
                            let slope = -(b.y - a.y) * inv_area;
                            let f0 = ((b.x - a.x) * (y - a.y) + (b.y - a.y) * a.x) * inv_area;
                            if slope > 0.0 {
                                lo = lo.max(floor(-f0 / slope) - 1.0);
                            } else if slope < 0.0 {
                                hi = hi.min(floor(-f0 / slope) + 2.0);
                            }
                        }
                        let mut x = lo;
                        while x <= hi {
                            let p = Vec2::new(x, y);
                            // Barycentric weights; inclusive on every edge for either winding.
                            let w0 = edge(t.b, t.c, p) * inv_area;
                            let w1 = edge(t.c, t.a, p) * inv_area;
                            let w2 = 1.0 - w0 - w1;
                            if w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0 {
                                let iz = w0 * t.inv_z.x + w1 * t.inv_z.y + w2 * t.inv_z.z;
                                let k = row + x as usize;
                                if iz > depth[k] {
                                    depth[k] = iz;
                                    out[k] = t.id;
                                }
                            }
                            x += 1.0;
                        }
                        y += 1.0;
                    }
                }
            });
        Self { camera, ids }
    }

    /// The candidate first triangle along a camera-frame ray direction.
    pub fn candidate(&self, dir: Vec3) -> Candidate {
        self.candidate_at(self.camera.sample_of(dir))
    }

    /// The candidate for a ray whose [`Pinhole::sample_of`] is `sample` (rays of a fixed
    /// pixel grid look it up once per camera instead of projecting every image).
    pub fn candidate_at(&self, sample: u32) -> Candidate {
        if sample == OUTSIDE {
            return Candidate::Trace;
        }
        let [id, right, below, diagonal] = self.around(sample);
        if right != id || below != id || diagonal != id {
            return Candidate::Trace;
        }
        if id == NONE {
            Candidate::Nothing
        } else {
            Candidate::Triangle(id)
        }
    }

    /// The triangles of the four samples around a camera-frame ray direction ([`NONE`] for a
    /// sample that sees none), or `None` when the ray is outside the rasterised image.
    pub fn neighbourhood(&self, dir: Vec3) -> Option<[u32; 4]> {
        let sample = self.camera.sample_of(dir);
        (sample != OUTSIDE).then(|| self.around(sample))
    }

    /// The triangles of the sample `sample` (not [`OUTSIDE`]) and of its right, lower and
    /// lower-right neighbours.
    fn around(&self, sample: u32) -> [u32; 4] {
        let (k, w) = (sample as usize, self.camera.width as usize);
        [
            self.ids[k],
            self.ids[k + 1],
            self.ids[k + w],
            self.ids[k + w + 1],
        ]
    }

    /// Share of samples that see a triangle (for tests and diagnostics).
    pub fn coverage(&self) -> f64 {
        self.ids.iter().filter(|&&i| i != NONE).count() as f64 / self.ids.len().max(1) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::bvh::Bvh;
    use crate::sim::noise::hash3;

    /// Random boxes of triangles in front of a camera looking along +x (world), like a street.
    fn scene() -> Vec<Triangle> {
        let mut tris = Vec::new();
        for i in 0..300 {
            let h = |k: i32| hash3(i, k, 0, 5);
            let c = Vec3::new(5.0 + h(0) * 60.0, h(1) * 40.0 - 20.0, h(2) * 6.0);
            let s = Vec3::new(0.2 + h(3) * 3.0, 0.2 + h(4) * 3.0, 0.2 + h(5) * 3.0);
            let a = c + Vec3::new(-s.x, -s.y, 0.0);
            let b = c + Vec3::new(s.x, s.y * (h(6) - 0.5), s.z);
            let d = c + Vec3::new(s.x * (h(7) - 0.5), s.y, -s.z);
            tris.push(Triangle::new(a, b, d, i as u32));
        }
        // A triangle crossing the camera plane (needs near clipping).
        tris.push(Triangle::new(
            Vec3::new(-5.0, 3.0, -1.0),
            Vec3::new(20.0, 3.0, -1.0),
            Vec3::new(20.0, 3.0, 4.0),
            999,
        ));
        tris
    }

    /// The random street of [`scene`] seen by a 320 × 200 pinhole camera at the origin looking
    /// along +x (camera frame: x right, y down, z forward; world: z up), rasterised.
    struct View {
        bvh: Bvh,
        world_from_camera: Quat,
        origin: Vec3,
        dirs: Vec<Vec3>,
        vis: VisibilityBuffer,
    }

    const WIDTH: u32 = 320;
    const HEIGHT: u32 = 200;

    /// The camera-frame ray through pixel (x, y).
    fn pixel_dir(x: f32, y: f32) -> Vec3 {
        let (f, cx, cy) = (180.0f32, 159.5f32, 99.5f32);
        Vec3::new((x - cx) / f, (y - cy) / f, 1.0).normalize_or_zero()
    }

    fn view() -> View {
        let bvh = Bvh::build(scene());
        let world_from_camera =
            Quat::from_mat3(&glam::Mat3::from_cols(-Vec3::Y, -Vec3::Z, Vec3::X));
        let origin = Vec3::new(0.0, 0.0, 1.5);
        let dirs: Vec<Vec3> = (0..WIDTH * HEIGHT)
            .map(|k| pixel_dir((k % WIDTH) as f32, (k / WIDTH) as f32))
            .collect();
        let pin = Pinhole::covering(&dirs, 180.0, 180.0, 159.5, 99.5).unwrap();
        let vis =
            VisibilityBuffer::render(&bvh.triangles, pin, origin, world_from_camera.inverse());
        View {
            bvh,
            world_from_camera,
            origin,
            dirs,
            vis,
        }
    }

    #[test]
    fn candidates_agree_with_ray_tracing() {
        let View {
            bvh,
            world_from_camera,
            origin,
            dirs,
            vis,
        } = view();
        assert!(vis.coverage() > 0.2, "{}", vis.coverage());
        let (mut sole, mut trace) = (0, 0);
        for d in &dirs {
            let dw = world_from_camera * *d;
            let truth = bvh
                .intersect(origin, dw, 1e-3, f32::MAX)
                .map(|h| h.triangle);
            match vis.candidate(*d) {
                Candidate::Triangle(id) => {
                    sole += 1;
                    assert_eq!(truth, Some(id), "ray {d}");
                }
                Candidate::Nothing => assert_eq!(truth, None, "ray {d}"),
                Candidate::Trace => trace += 1,
            }
        }
        assert!(sole > 10_000, "{sole}");
        // Silhouettes are a small share of the image.
        assert!(trace < dirs.len() / 5, "{trace} of {}", dirs.len());
    }

    #[test]
    fn sub_pixel_rays_hit_a_triangle_their_neighbourhood_saw() {
        // What `World::trace_among` relies on: between four samples, the first triangle is
        // one of theirs (or, when the ray misses all of them, it is traced).
        let View {
            bvh,
            world_from_camera,
            origin,
            vis,
            ..
        } = view();
        let (mut silhouettes, mut outside_set) = (0, 0);
        for k in 0..WIDTH * HEIGHT {
            let (x, y) = ((k % WIDTH) as f32 + 0.25, (k / WIDTH) as f32 - 0.25);
            let d = pixel_dir(x, y);
            if vis.candidate(d) != Candidate::Trace {
                continue;
            }
            let Some(ids) = vis.neighbourhood(d) else {
                continue;
            };
            silhouettes += 1;
            let truth = bvh.intersect(origin, world_from_camera * d, 1e-3, f32::MAX);
            let seen = truth.is_none_or(|h| ids.contains(&h.triangle));
            let missed_all = ids.iter().all(|&id| {
                id == NONE
                    || bvh
                        .intersect_triangle(id, origin, world_from_camera * d, 1e-3, f32::MAX)
                        .is_none()
            });
            if !seen && !missed_all {
                outside_set += 1;
            }
        }
        assert!(silhouettes > 1000, "{silhouettes}");
        assert!(
            outside_set * 200 < silhouettes,
            "{outside_set} of {silhouettes} sub-pixel rays hit a triangle no sample saw"
        );
    }

    #[test]
    fn near_plane_clipping_keeps_the_visible_part() {
        let (poly, n) = clip_near([
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(0.0, 1.0, 1.0),
        ]);
        assert_eq!(n, 4);
        assert!(poly[..n].iter().all(|p| p.z >= NEAR_M - 1e-6));
        let (_, none) = clip_near([Vec3::NEG_Z; 3]);
        assert_eq!(none, 0);
    }

    #[test]
    fn sideways_rays_are_not_rasterised() {
        let dirs = [Vec3::Z, Vec3::new(1.0, 0.0, 0.01).normalize_or_zero()];
        assert!(Pinhole::covering(&dirs, 100.0, 100.0, 50.0, 50.0).is_none());
        let p = Pinhole::covering(&[Vec3::Z], 100.0, 100.0, 50.0, 50.0).unwrap();
        assert_eq!(p.project(Vec3::Z), Vec2::new(p.cx, p.cy));
    }
}
