//! The procedural static world the simulator renders: a road laid along the driven path (lanes,
//! markings, curbs, sidewalks) and, per scene, buildings with windows, doors and signs, poles and
//! street lights, parked cars, trees, bushes, posters and checkerboards.
//!
//! How it works: the ground is the analytic plane z = 0, shaded from a raster of (distance to the
//! path, distance along it) so markings follow any trajectory; everything else is triangles in a
//! [`Bvh`]. Objects are placed along the path on both sides with a seeded RNG and an occupancy
//! grid, never within the road of any part of the path (figure-8 crossings stay clear;
//! `sim::layout`). Every
//! material has an albedo texture (procedural, band-limited to the pixel footprint) and a LiDAR
//! reflectivity.

use std::collections::HashSet;
use std::str::FromStr;

use glam::{DVec3, Vec3};

use super::bvh::Bvh;
use super::layout::{
    Builder, Rng, add_checkerboards, add_featureless, add_parking_lot, add_sidewalks, add_urban,
    assign_faces,
};
use super::noise::{
    NoiseBatch, band, fbm2_in, floor, floor_in, hash3, hash64, stripe, stripe_in, value2_in, wrap,
    wrap_in,
};
use super::raster::{Candidate, NONE};

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SceneKind {
    Urban,
    ParkingLot,
    Featureless,
    Checkerboard,
}

impl SceneKind {
    pub const ALL: [SceneKind; 4] = [
        Self::Urban,
        Self::ParkingLot,
        Self::Featureless,
        Self::Checkerboard,
    ];
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Urban => "urban",
            Self::ParkingLot => "parking-lot",
            Self::Featureless => "featureless",
            Self::Checkerboard => "checkerboard",
        }
    }
}

impl FromStr for SceneKind {
    type Err = crate::error::ParseError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL.into_iter().find(|k| k.as_str() == s).ok_or_else(|| {
            crate::error::ParseError::new(format!("unknown scene '{s}' (expected one of: urban, parking-lot, featureless, checkerboard)"))
        })
    }
}

/// Half-width of the paved road around the path, metres.
pub const ROAD_HALF_WIDTH_M: f32 = 7.0;
pub(super) const SIDEWALK_OUTER_M: f32 = 10.0;
pub(super) const CURB_HEIGHT_M: f32 = 0.15;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Material {
    Facade { color: [f32; 3], seed: u32 },
    Concrete,
    Sidewalk,
    Metal { color: [f32; 3] },
    CarPaint { color: [f32; 3] },
    Glass,
    Tire,
    Bark,
    Foliage { color: [f32; 3] },
    Poster { seed: u32 },
    Board { index: u32 },
    LampHead,
}

/// A checkerboard target: `squares_u × squares_v` squares of `square_m`, inner corners known.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkerboard {
    /// World position of the board's first square corner.
    pub origin: Vec3,
    pub u_axis: Vec3,
    pub v_axis: Vec3,
    pub squares_u: u32,
    pub squares_v: u32,
    pub square_m: f32,
    /// White border around the squares, metres.
    pub margin_m: f32,
}

impl Checkerboard {
    /// Inner corners (where four squares meet), in world coordinates.
    pub fn inner_corners(&self) -> Vec<Vec3> {
        let mut out = Vec::new();
        for j in 1..self.squares_v {
            for i in 1..self.squares_u {
                out.push(
                    self.origin
                        + self.u_axis * (i as f32 * self.square_m)
                        + self.v_axis * (j as f32 * self.square_m),
                );
            }
        }
        out
    }
}

mod ground;
pub use ground::GroundMap;

/// Where a ray ended.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceHit {
    pub t: f32,
    pub point: Vec3,
    pub normal: Vec3,
    /// `None` for the ground plane.
    pub material: Option<u32>,
    /// Identifies the flat face hit (for edge-adaptive anti-aliasing); the ground is u32::MAX.
    pub primitive: u32,
}

/// What a surface looks like to a camera and to a LiDAR.
#[derive(Clone, Copy, Debug)]
pub struct Surface {
    pub albedo: Vec3,
    /// Diffuse LiDAR reflectivity in [0, 1].
    pub reflectivity: f32,
}

pub struct World {
    pub kind: SceneKind,
    pub bvh: Bvh,
    pub materials: Vec<Material>,
    pub ground: GroundMap,
    pub boards: Vec<Checkerboard>,
    pub sun_dir: Vec3,
    pub seed: u64,
}

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("World")
            .field("kind", &self.kind)
            .field("triangles", &self.bvh.triangles.len())
            .finish()
    }
}

impl World {
    /// Build a scene around the driven path (points in the world frame, z ignored).
    pub fn build(kind: SceneKind, path: &[DVec3], seed: u64) -> Self {
        Self::build_for_rig(kind, path, seed, 0.0)
    }

    /// [`Self::build`] for a rig whose highest LiDAR is `raised_m` above a car's (1.9 m): the
    /// checkerboard scene then adds a second ring of boards that much higher and farther, in
    /// the dense middle beams of tall LiDARs (a truck's), leaving a car's scene unchanged.
    pub fn build_for_rig(kind: SceneKind, path: &[DVec3], seed: u64, raised_m: f64) -> Self {
        let path: Vec<Vec3> = path
            .iter()
            .map(|p| Vec3::new(p.x as f32, p.y as f32, 0.0))
            .collect();
        let ground = GroundMap::build(&path, 0.25, 45.0);
        let mut b = Builder {
            tris: Vec::new(),
            materials: Vec::new(),
            occupied: HashSet::new(),
        };
        let mut rng = Rng(hash64(seed ^ 0x5157));
        if kind != SceneKind::ParkingLot {
            add_sidewalks(&mut b, &path, &ground);
        }
        let mut boards = Vec::new();
        match kind {
            SceneKind::Urban => add_urban(&mut b, &path, &ground, &mut rng),
            SceneKind::ParkingLot => add_parking_lot(&mut b, &path, &ground, &mut rng),
            SceneKind::Featureless => add_featureless(&mut b, &path, &ground, &mut rng),
            SceneKind::Checkerboard => {
                boards = add_checkerboards(&mut b, &path, &mut rng, raised_m.max(0.0) as f32);
                add_urban(&mut b, &path, &ground, &mut rng);
            }
        }
        let sun_dir = Vec3::new(0.45, -0.35, 0.82).normalize_or_zero();
        assign_faces(&mut b.tris);
        Self {
            kind,
            bvh: Bvh::build(b.tris),
            materials: b.materials,
            ground,
            boards,
            sun_dir,
            seed,
        }
    }

    /// Nearest surface along a ray (ground plane or triangles).
    pub fn trace(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<SurfaceHit> {
        let ground = self.ground_hit(origin, dir, t_max);
        let limit = ground.map_or(t_max, |h| h.t);
        match self.bvh.intersect(origin, dir, 1e-3, limit) {
            Some(h) => Some(self.triangle_hit(origin, dir, h.t, h.triangle)),
            None => ground,
        }
    }

    /// [`World::trace`] helped by a rasterised candidate for the first triangle: the candidate
    /// is confirmed by one exact intersection, and only silhouettes (or a candidate the ray
    /// narrowly misses) go through the BVH. Same answer as `trace` wherever the candidate is
    /// right.
    pub fn trace_with(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        candidate: Candidate,
    ) -> Option<SurfaceHit> {
        self.resolve(origin, dir, t_max, candidate)
            .unwrap_or_else(|| self.trace(origin, dir, t_max))
    }

    /// The first surface along a ray whose rasterised neighbourhood saw `triangles`
    /// ([`NONE`]: a sample that saw none): the nearest of their exact intersections and the
    /// ground, by at most four triangle tests instead of a BVH trace; a ray that misses them
    /// all is traced (it may hit a triangle no sample saw). A thin occluder that fell between
    /// the samples in front of a hit triangle can be missed; anti-aliasing sub-samples, which
    /// sit between samples that already disagree, use it.
    pub fn trace_among(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        triangles: [u32; 4],
    ) -> Option<SurfaceHit> {
        let ground = self.ground_hit(origin, dir, t_max);
        let limit = ground.map_or(t_max, |h| h.t);
        let mut best: Option<(f32, u32)> = None;
        for (i, &id) in triangles.iter().enumerate() {
            if id == NONE || triangles[..i].contains(&id) {
                continue;
            }
            if let Some(t) = self.bvh.intersect_triangle(id, origin, dir, 1e-3, f32::MAX)
                && t < best.map_or(f32::MAX, |b| b.0)
            {
                best = Some((t, id));
            }
        }
        match best {
            Some((t, id)) if t < limit => Some(self.triangle_hit(origin, dir, t, id)),
            Some(_) => ground,
            None => self.trace(origin, dir, t_max),
        }
    }

    /// The first surface from a rasterised candidate and at most one exact intersection
    /// (`Some(None)`: nothing within range), or `None` when only a BVH trace can tell.
    fn resolve(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        candidate: Candidate,
    ) -> Option<Option<SurfaceHit>> {
        match candidate {
            Candidate::Trace => None,
            Candidate::Nothing => Some(self.ground_hit(origin, dir, t_max)),
            Candidate::Triangle(id) => {
                let ground = self.ground_hit(origin, dir, t_max);
                let limit = ground.map_or(t_max, |h| h.t);
                match self
                    .bvh
                    .intersect_triangle(id, origin, dir, 1e-3, f32::MAX)?
                {
                    t if t < limit => Some(Some(self.triangle_hit(origin, dir, t, id))),
                    _ => Some(ground),
                }
            }
        }
    }

    fn ground_hit(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<SurfaceHit> {
        if dir.z >= -1e-6 {
            return None;
        }
        let t = -origin.z / dir.z;
        (t > 1e-3 && t < t_max).then(|| SurfaceHit {
            t,
            point: origin + dir * t,
            normal: Vec3::Z,
            material: None,
            primitive: u32::MAX,
        })
    }

    fn triangle_hit(&self, origin: Vec3, dir: Vec3, t: f32, triangle: u32) -> SurfaceHit {
        let tri = &self.bvh.triangles[triangle as usize];
        let mut n = tri.normal();
        if n.dot(dir) > 0.0 {
            n = -n;
        }
        SurfaceHit {
            t,
            point: origin + dir * t,
            normal: n,
            material: Some(tri.material),
            primitive: tri.face,
        }
    }

    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_max: f32) -> bool {
        self.bvh.occluded(origin, dir, 1e-3, t_max)
    }

    /// Albedo and reflectivity at a hit; `footprint` is the pixel's size on the surface (m), which
    /// band-limits the procedural textures.
    pub fn surface(&self, hit: &SurfaceHit, footprint: f32) -> Surface {
        surface_dispatch(self, hit, footprint)
    }

    /// [`World::surface`]'s body; `WIDE` selects the forms written for vectors (`sim::wide`).
    #[inline(always)]
    fn surface_in<const WIDE: bool>(&self, hit: &SurfaceHit, footprint: f32) -> Surface {
        let p = hit.point;
        let fp = footprint.max(1e-4);
        match hit.material.and_then(|m| self.materials.get(m as usize)) {
            None => self.ground_surface::<WIDE>(p, fp),
            Some(m) => {
                // Planar texture coordinates: along the face (horizontal) and height.
                let n = hit.normal;
                let t = Vec3::new(-n.y, n.x, 0.0).normalize_or_zero();
                let (u, v) = if n.z.abs() > 0.7 {
                    (p.x, p.y)
                } else {
                    (p.dot(t), p.z)
                };
                material_surface::<WIDE>(m, u, v, p, n, fp, &self.boards, self.seed)
            }
        }
    }

    #[inline(always)]
    fn ground_surface<const WIDE: bool>(&self, p: Vec3, fp: f32) -> Surface {
        let seed = self.seed;
        // Wide code evaluates all the asphalt's noise in one batch of lanes (even the cracks'
        // and the paint's, which the one-at-a-time code computes only where they show).
        let batch = if WIDE {
            Some({
                let mut b = NoiseBatch::<16>::default();
                let lanes = (
                    b.fbm2(p.x, p.y, 0.6, 6, fp, seed ^ 11),
                    b.fbm2(p.x, p.y, 0.05, 3, fp, seed ^ 12),
                    b.fbm2(p.x, p.y, 0.35, 3, fp, seed ^ 17),
                    b.value2(p.x * 25.0, p.y * 25.0, seed ^ 16),
                    b.value2(p.x * 0.1, p.y * 0.1, seed ^ 18),
                    b.value2(p.x * 3.0, p.y * 3.0, seed ^ 13),
                );
                (b.eval(), lanes)
            })
        } else {
            None
        };
        let grain = match &batch {
            Some((v, lanes)) => lanes.0.finish(v),
            None => fbm2_in::<WIDE>(p.x, p.y, 0.6, 6, fp, seed ^ 11),
        };
        let (d, s) = self.ground.sample(p.x, p.y);
        let ad = d.abs();
        let asphalt = Vec3::splat(0.16 + 0.10 * grain) + Vec3::new(0.0, 0.0, 0.01);
        let patch = match &batch {
            Some((v, lanes)) => lanes.1.finish(v),
            None => fbm2_in::<WIDE>(p.x, p.y, 0.05, 3, fp, seed ^ 12),
        };
        let asphalt = asphalt * (0.85 + 0.3 * patch);
        // Aggregate speckle (4 cm stones) and darker tar-sealed cracks, faded below the footprint.
        let speck_fade = ((1.0 / 25.0) / (2.0 * fp)).clamp(0.0, 1.0);
        let speck_noise = match &batch {
            Some((v, lanes)) => v[lanes.3],
            None => value2_in::<WIDE>(p.x * 25.0, p.y * 25.0, seed ^ 16),
        };
        let speck = ((speck_noise - 0.7) * 8.0).clamp(0.0, 1.0) * speck_fade;
        // Cracks only where their mask is open (most of the road has none: no noise there).
        let mask_noise = match &batch {
            Some((v, lanes)) => v[lanes.4],
            None => value2_in::<WIDE>(p.x * 0.1, p.y * 0.1, seed ^ 18),
        };
        let crack_mask = ((mask_noise - 0.55) * 5.0).clamp(0.0, 1.0);
        let crack = if crack_mask > 0.0 {
            let crack_noise = match &batch {
                Some((v, lanes)) => lanes.2.finish(v),
                None => fbm2_in::<WIDE>(p.x, p.y, 0.35, 3, fp, seed ^ 17),
            };
            band(crack_noise - 0.5, 0.004, fp * 0.5) * crack_mask
        } else {
            0.0
        };
        let asphalt = (asphalt + Vec3::splat(0.08 * speck)) * (1.0 - 0.6 * crack);
        if self.kind == SceneKind::ParkingLot {
            // Parking bays: lines every 2.6 m across, rows 5.5 m deep.
            let (lx, ly) = (p.x / 2.6, p.y / 11.0);
            let bay_line = stripe_in::<WIDE>(lx + 0.02, 0.04, fp / 2.6)
                * (1.0 - stripe_in::<WIDE>(ly + 0.25, 0.5, fp / 11.0));
            let row_line = band((wrap_in::<WIDE>(p.y, 11.0)) - 5.5, 0.06, fp);
            let paint = (bay_line + row_line).min(1.0) * if ad > 4.0 { 1.0 } else { 0.0 };
            let albedo = asphalt * (1.0 - paint) + Vec3::splat(0.80) * paint;
            return Surface {
                albedo,
                reflectivity: 0.08 + 0.6 * paint,
            };
        }
        if ad <= ROAD_HALF_WIDTH_M + 0.5 {
            let dash = stripe_in::<WIDE>(s / 9.0, 0.35, fp / 9.0);
            let mut paint = 0.0;
            let mut yellow = 0.0;
            if self.kind != SceneKind::Featureless {
                // Lane dividers at ±1.75 m (dashed), ±5.25 m (dashed), edge lines at ±6.7 m.
                paint += band(ad - 1.85, 0.07, fp) * dash;
                paint += band(ad - 5.25, 0.07, fp) * dash;
                // Crosswalk blocks every 120 m.
                let cw = band(wrap_in::<WIDE>(s + 30.0, 120.0) - 60.0, 2.0, fp)
                    * stripe_in::<WIDE>(d / 1.2, 0.5, fp / 1.2)
                    * if ad < 6.5 { 1.0 } else { 0.0 };
                paint += cw;
                yellow = band(ad - 0.0, 0.08, fp).max(0.0) * 0.0;
            }
            paint += band(ad - 6.7, 0.08, fp);
            let paint = paint.min(1.0);
            // Worn paint (its noise only where there is paint).
            let marking = if paint > 0.0 {
                let wear = match &batch {
                    Some((v, lanes)) => v[lanes.5],
                    None => value2_in::<WIDE>(p.x * 3.0, p.y * 3.0, seed ^ 13),
                };
                Vec3::new(0.85, 0.85, 0.82) * (0.75 + 0.25 * wear)
            } else {
                Vec3::ZERO
            };
            let albedo =
                asphalt * (1.0 - paint) + marking * paint + Vec3::new(0.1, 0.08, 0.0) * yellow;
            // Road paint is retro-reflective: bright in LiDAR intensity.
            return Surface {
                albedo,
                reflectivity: 0.07 + 0.08 * grain + 0.55 * paint,
            };
        }
        // Off-road: grass and dirt.
        let (g, dirt) = if WIDE {
            let mut b = NoiseBatch::<16>::default();
            let (g, dirt) = (
                b.fbm2(p.x, p.y, 0.3, 6, fp, seed ^ 14),
                b.fbm2(p.x, p.y, 0.04, 3, fp, seed ^ 15),
            );
            let v = b.eval();
            (g.finish(&v), dirt.finish(&v))
        } else {
            (
                fbm2_in::<WIDE>(p.x, p.y, 0.3, 6, fp, seed ^ 14),
                fbm2_in::<WIDE>(p.x, p.y, 0.04, 3, fp, seed ^ 15),
            )
        };
        let grass = Vec3::new(0.18, 0.30, 0.10) * (0.7 + 0.6 * g);
        let soil = Vec3::new(0.36, 0.29, 0.20) * (0.8 + 0.4 * g);
        let mix = ((dirt - 0.45) * 6.0).clamp(0.0, 1.0);
        Surface {
            albedo: grass * (1.0 - mix) + soil * mix,
            reflectivity: 0.35 + 0.15 * g,
        }
    }
}

super::wide::dispatch_wide! {
    /// [`World::surface`] compiled for the CPU's widest vectors (`sim::wide`).
    fn surface_dispatch(world: &World, hit: &SurfaceHit, footprint: f32) -> Surface => surface_wide
}

#[inline(always)]
fn surface_wide<const WIDE: bool>(world: &World, hit: &SurfaceHit, footprint: f32) -> Surface {
    world.surface_in::<WIDE>(hit, footprint)
}

#[inline(always)]
fn material_surface<const WIDE: bool>(
    m: &Material,
    u: f32,
    v: f32,
    p: Vec3,
    n: Vec3,
    fp: f32,
    boards: &[Checkerboard],
    seed: u64,
) -> Surface {
    let s = |k: u64| seed ^ k;
    match *m {
        Material::Facade { color, seed: fs } => {
            // Wide code evaluates the façade's fBm and its windows' reflection noise together.
            let batch = if WIDE {
                Some({
                    let mut b = NoiseBatch::<8>::default();
                    let lanes = (
                        b.fbm2(u, v, 0.8, 5, fp, s(21 + fs as u64)),
                        b.value2(u * 0.3, v * 0.5, s(23 + fs as u64)),
                    );
                    (b.eval(), lanes)
                })
            } else {
                None
            };
            let grain = match &batch {
                Some((values, lanes)) => lanes.0.finish(values),
                None => fbm2_in::<WIDE>(u, v, 0.8, 5, fp, s(21 + fs as u64)),
            };
            let base = Vec3::from_array(color) * (0.85 + 0.3 * grain);
            // Bricks on some façades.
            let brick = if fs % 3 == 0 {
                let row = floor_in::<WIDE>(v / 0.075);
                let mortar = stripe_in::<WIDE>(v / 0.075, 0.15, fp / 0.075).max(stripe_in::<WIDE>(
                    u / 0.24 + 0.5 * (row as i32 % 2) as f32,
                    0.06,
                    fp / 0.24,
                ));
                1.0 - 0.35 * mortar
            } else {
                1.0
            };
            // Window grid: 3 m bays, 3.2 m floors, ground floor shop fronts.
            let (bay, floor) = (3.0 + (fs % 3) as f32 * 0.4, 3.2);
            let wu = stripe_in::<WIDE>(u / bay + 0.2, 0.55, fp / bay);
            let wv = stripe_in::<WIDE>((v - 0.9) / floor, 0.5, fp / floor);
            let ground_floor = if v < 3.0 { 1.0 } else { 0.0 };
            let shop =
                ground_floor * stripe_in::<WIDE>(u / 7.0, 0.7, fp / 7.0) * band(v - 1.6, 1.1, fp);
            let window = (wu * wv * (1.0 - ground_floor) + shop).min(1.0);
            let frame_edge = (wu * wv * (1.0 - ground_floor))
                * (1.0
                    - stripe_in::<WIDE>(u / bay + 0.23, 0.49, fp / bay)
                        * stripe_in::<WIDE>((v - 0.82) / floor, 0.45, fp / floor));
            // Mullions and transoms split each window into panes.
            let fu = wrap_in::<WIDE>(u / bay + 0.2, 1.0);
            let fv = wrap_in::<WIDE>((v - 0.9) / floor, 1.0);
            let mullion = (band(fu - 0.275, 0.012, fp / bay) + band(fv - 0.33, 0.016, fp / floor))
                .min(1.0)
                * wu
                * wv
                * (1.0 - ground_floor);
            let window = window * (1.0 - mullion);
            let sky_reflection = if window > 0.0 {
                let reflection = match &batch {
                    Some((values, lanes)) => values[lanes.1],
                    None => value2_in::<WIDE>(u * 0.3, v * 0.5, s(23 + fs as u64)),
                };
                Vec3::new(0.25, 0.32, 0.40) * (0.6 + 0.8 * reflection)
            } else {
                Vec3::ZERO
            };
            let albedo = Vec3::splat(0.85) * mullion
                + base * brick * (1.0 - window - mullion).max(0.0)
                + sky_reflection * window * 0.6
                + Vec3::splat(0.9) * frame_edge * 0.3;
            Surface {
                albedo,
                reflectivity: 0.45 * (1.0 - window) + 0.05 * window,
            }
        }
        Material::Concrete => {
            let g = fbm2_in::<WIDE>(u, v, 1.0, 5, fp, s(31));
            Surface {
                albedo: Vec3::splat(0.5 + 0.2 * g),
                reflectivity: 0.5,
            }
        }
        Material::Sidewalk => {
            let g = fbm2_in::<WIDE>(p.x, p.y, 1.5, 5, fp, s(32));
            let joints = stripe_in::<WIDE>(p.x / 1.5, 0.03, fp / 1.5).max(stripe_in::<WIDE>(
                p.y / 1.5,
                0.03,
                fp / 1.5,
            ));
            let top = if n.z > 0.7 { 1.0 - 0.4 * joints } else { 0.9 };
            Surface {
                albedo: Vec3::splat((0.52 + 0.15 * g) * top),
                reflectivity: 0.55,
            }
        }
        Material::Metal { color } => {
            let g = fbm2_in::<WIDE>(u, v, 2.0, 4, fp, s(33));
            Surface {
                albedo: Vec3::from_array(color) * (0.8 + 0.3 * g),
                reflectivity: 0.6,
            }
        }
        Material::CarPaint { color } => {
            let shade = 0.9 + 0.1 * (n.z * 0.5 + 0.5);
            // A dark belt line and door seams.
            let belt = band(v - 0.95, 0.03, fp);
            let seam = stripe_in::<WIDE>(u / 1.3 + 0.1, 0.02, fp / 1.3) * band(v - 0.6, 0.3, fp);
            let albedo = Vec3::from_array(color) * shade * (1.0 - 0.7 * (belt + seam).min(1.0));
            Surface {
                albedo,
                reflectivity: 0.7,
            }
        }
        Material::Glass => Surface {
            albedo: Vec3::new(0.06, 0.07, 0.09),
            reflectivity: 0.03,
        },
        Material::Tire => Surface {
            albedo: Vec3::splat(0.04),
            reflectivity: 0.04,
        },
        Material::Bark => {
            let g = fbm2_in::<WIDE>(u * 3.0, v * 0.5, 2.0, 4, fp, s(34));
            Surface {
                albedo: Vec3::new(0.28, 0.20, 0.13) * (0.6 + 0.6 * g),
                reflectivity: 0.35,
            }
        }
        Material::Foliage { color } => {
            let g = fbm2_in::<WIDE>(p.x + p.z, p.y - p.z, 3.0, 5, fp, s(35));
            Surface {
                albedo: Vec3::from_array(color) * (0.5 + 0.9 * g),
                reflectivity: 0.5,
            }
        }
        Material::Poster { seed: ps } => poster(u, v, fp, seed ^ (ps as u64 * 7919)),
        Material::Board { index } => match boards.get(index as usize) {
            Some(b) => {
                let rel = p - b.origin;
                let (a, c) = (
                    rel.dot(b.u_axis) / b.square_m,
                    rel.dot(b.v_axis) / b.square_m,
                );
                let inside =
                    a >= 0.0 && c >= 0.0 && a < b.squares_u as f32 && c < b.squares_v as f32;
                let front = n.dot(b.u_axis.cross(b.v_axis)) < 0.0;
                if inside && front {
                    // Box-filtered checker: product of two ±1 square waves.
                    let w = fp / b.square_m;
                    let sa = 2.0 * stripe_in::<WIDE>(a * 0.5, 0.5, w * 0.5) - 1.0;
                    let sc = 2.0 * stripe_in::<WIDE>(c * 0.5, 0.5, w * 0.5) - 1.0;
                    let black = 0.5 + 0.5 * sa * sc;
                    Surface {
                        albedo: Vec3::splat(0.9 - 0.85 * black),
                        reflectivity: 0.8 - 0.7 * black,
                    }
                } else {
                    Surface {
                        albedo: Vec3::splat(if front { 0.92 } else { 0.35 }),
                        reflectivity: 0.8,
                    }
                }
            }
            None => Surface {
                albedo: Vec3::splat(0.5),
                reflectivity: 0.5,
            },
        },
        Material::LampHead => Surface {
            albedo: Vec3::new(0.9, 0.88, 0.8),
            reflectivity: 0.8,
        },
    }
}

/// A high-contrast poster: coloured panels, bold "text" bars and a logo disc.
fn poster(u: f32, v: f32, fp: f32, seed: u64) -> Surface {
    let cell = floor(u / 0.8) as i32;
    let row = floor(v / 0.6) as i32;
    let palette = [
        Vec3::new(0.9, 0.15, 0.1),
        Vec3::new(0.95, 0.85, 0.1),
        Vec3::new(0.1, 0.3, 0.8),
        Vec3::new(0.95, 0.95, 0.92),
        Vec3::new(0.05, 0.05, 0.06),
        Vec3::new(0.1, 0.6, 0.3),
    ];
    let pick = |a: i32, b: i32, k: u64| {
        palette[(hash3(a, b, 0, seed ^ k) * palette.len() as f32) as usize % palette.len()]
    };
    let bg = pick(cell / 3, row / 3, 1);
    let text_row = stripe(v / 0.18, 0.45, fp / 0.18);
    let word = stripe(u / (0.3 + 0.4 * hash3(row, 0, 0, seed)), 0.7, fp / 0.5);
    let text = text_row
        * word
        * if hash3(cell, row, 1, seed) > 0.4 {
            1.0
        } else {
            0.0
        };
    let ink = pick(cell, row, 2);
    let cu = wrap(u, 2.4) - 1.2;
    let cv = wrap(v, 1.8) - 0.9;
    let disc = band((cu * cu + cv * cv).sqrt() - 0.0, 0.45, fp);
    let logo = pick(cell / 3, row / 3, 3);
    let albedo = bg * (1.0 - text) + ink * text;
    let albedo = albedo * (1.0 - disc * 0.8) + logo * disc * 0.8;
    Surface {
        albedo,
        reflectivity: 0.3 + 0.4 * albedo.length() / 1.7,
    }
}

#[cfg(test)]
mod tests;
