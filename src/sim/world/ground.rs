//! The ground's distance map: for each cell of a raster around the path, the signed distance
//! to the path (left positive) and the distance along it, so the road, its markings and the
//! kerbs are a lookup.

use glam::Vec3;

/// Distance to the path (signed: left positive) and along it, rasterised.
#[derive(Clone, Debug)]
pub struct GroundMap {
    x0: f32,
    y0: f32,
    res: f32,
    w: usize,
    h: usize,
    dist: Vec<f32>,
    along: Vec<f32>,
}

impl GroundMap {
    const FAR: f32 = 1.0e3;

    pub(super) fn build(path: &[Vec3], res: f32, reach: f32) -> Self {
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for p in path {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        let margin = reach + 5.0;
        let (x0, y0) = (lo.x - margin, lo.y - margin);
        let w = (((hi.x - lo.x) + 2.0 * margin) / res).ceil() as usize + 1;
        let h = (((hi.y - lo.y) + 2.0 * margin) / res).ceil() as usize + 1;
        let mut dist = vec![Self::FAR; w * h];
        let mut along = vec![0.0f32; w * h];
        let mut s_acc = 0.0f32;
        for seg in path.windows(2) {
            let (a, b) = (seg[0], seg[1]);
            let ab = Vec3::new(b.x - a.x, b.y - a.y, 0.0);
            let len = ab.length();
            if len < 1e-6 {
                continue;
            }
            let dir = ab / len;
            let left = Vec3::new(-dir.y, dir.x, 0.0);
            let (bx0, bx1) = (a.x.min(b.x) - reach, a.x.max(b.x) + reach);
            let (by0, by1) = (a.y.min(b.y) - reach, a.y.max(b.y) + reach);
            let (i0, i1) = (
                ((bx0 - x0) / res).floor().max(0.0) as usize,
                (((bx1 - x0) / res).ceil() as usize).min(w - 1),
            );
            let (j0, j1) = (
                ((by0 - y0) / res).floor().max(0.0) as usize,
                (((by1 - y0) / res).ceil() as usize).min(h - 1),
            );
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let p = Vec3::new(x0 + i as f32 * res - a.x, y0 + j as f32 * res - a.y, 0.0);
                    let t = p.dot(dir).clamp(0.0, len);
                    let d_abs = (p - dir * t).length();
                    let k = j * w + i;
                    if d_abs < dist[k].abs() {
                        let side = if p.dot(left) >= 0.0 { 1.0 } else { -1.0 };
                        dist[k] = side * d_abs;
                        along[k] = s_acc + t;
                    }
                }
            }
            s_acc += len;
        }
        Self {
            x0,
            y0,
            res,
            w,
            h,
            dist,
            along,
        }
    }

    /// (signed distance to the path, distance along it) at a ground point, bilinear.
    pub fn sample(&self, x: f32, y: f32) -> (f32, f32) {
        let fx = (x - self.x0) / self.res;
        let fy = (y - self.y0) / self.res;
        if fx < 0.0 || fy < 0.0 || fx >= (self.w - 1) as f32 || fy >= (self.h - 1) as f32 {
            return (Self::FAR, 0.0);
        }
        let (i, j) = (fx as usize, fy as usize);
        let (tx, ty) = (fx - i as f32, fy - j as f32);
        let k = j * self.w + i;
        let lerp = |v: &[f32]| {
            let top = v[k] + (v[k + 1] - v[k]) * tx;
            let bot = v[k + self.w] + (v[k + self.w + 1] - v[k + self.w]) * tx;
            top + (bot - top) * ty
        };
        // Signed distance flips sign across the path: interpolate magnitudes, keep the sign of
        // the nearest sample (the road is symmetric, so only |d| matters for shading).
        let d = [
            self.dist[k],
            self.dist[k + 1],
            self.dist[k + self.w],
            self.dist[k + self.w + 1],
        ];
        let mag = {
            let m = [d[0].abs(), d[1].abs(), d[2].abs(), d[3].abs()];
            let top = m[0] + (m[1] - m[0]) * tx;
            let bot = m[2] + (m[3] - m[2]) * tx;
            top + (bot - top) * ty
        };
        (mag * d[0].signum(), lerp(&self.along))
    }

    pub fn abs_distance(&self, x: f32, y: f32) -> f32 {
        self.sample(x, y).0.abs()
    }
}
