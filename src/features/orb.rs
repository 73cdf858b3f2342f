//! Keypoints with binary descriptors, needing no learned weights (method.md §15.6): FAST-9
//! corners ranked by the Harris response, an orientation from the intensity centroid of a
//! radius-15 disc, and a 256-bit steered BRIEF descriptor: 256 intensity comparisons between
//! point pairs of a fixed pattern (drawn once from an isotropic Gaussian of σ = 31/5 px by a
//! seeded generator, clipped to radius 13) rotated by the keypoint's orientation, on a smoothed
//! image (ORB's recipe: Rublee et al., ICCV 2011).

use crate::eval::fast::fast9;

/// Pixels kept free at the image border (the rotated pattern and the centroid disc fit).
const BORDER: usize = 16;
const CENTROID_RADIUS: i32 = 15;
const PATTERN_RADIUS: f32 = 13.0;

/// One keypoint: position (px), orientation (rad), Harris response, descriptor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Keypoint {
    pub x: f32,
    pub y: f32,
    pub angle_rad: f32,
    pub response: f32,
    pub descriptor: [u64; 4],
}

/// Detect up to `max_keypoints` keypoints of a `w × h` grayscale image.
pub fn detect(gray: &[u8], w: usize, h: usize, max_keypoints: usize) -> Vec<Keypoint> {
    if w < 2 * BORDER + 1 || h < 2 * BORDER + 1 || gray.len() != w * h {
        return Vec::new();
    }
    let mut corners: Vec<(usize, usize, f32)> = fast9(gray, w, h, 20)
        .into_iter()
        .map(|(x, y, _)| (x as usize, y as usize))
        .filter(|&(x, y)| x >= BORDER && y >= BORDER && x < w - BORDER && y < h - BORDER)
        .map(|(x, y)| (x, y, harris(gray, w, x, y)))
        .collect();
    corners.sort_by(|a, b| b.2.total_cmp(&a.2));
    corners.truncate(max_keypoints);
    let smooth = box_blur5(gray, w, h);
    let pattern = pattern();
    corners
        .into_iter()
        .map(|(x, y, response)| {
            let angle_rad = centroid_angle(gray, w, x, y);
            Keypoint {
                x: x as f32,
                y: y as f32,
                angle_rad,
                response,
                descriptor: describe(&smooth, w, x, y, angle_rad, &pattern),
            }
        })
        .collect()
}

/// Harris response `det(M) − 0.04 tr(M)²` of the central-difference gradients in a 7 × 7 window.
fn harris(gray: &[u8], w: usize, x: usize, y: usize) -> f32 {
    let (mut xx, mut yy, mut xy) = (0.0f32, 0.0f32, 0.0f32);
    for v in y - 3..=y + 3 {
        for u in x - 3..=x + 3 {
            let gx = gray[v * w + u + 1] as f32 - gray[v * w + u - 1] as f32;
            let gy = gray[(v + 1) * w + u] as f32 - gray[(v - 1) * w + u] as f32;
            xx += gx * gx;
            yy += gy * gy;
            xy += gx * gy;
        }
    }
    xx * yy - xy * xy - 0.04 * (xx + yy) * (xx + yy)
}

/// Orientation of the intensity centroid of the disc around (x, y).
fn centroid_angle(gray: &[u8], w: usize, x: usize, y: usize) -> f32 {
    let (mut m10, mut m01) = (0.0f32, 0.0f32);
    let r = CENTROID_RADIUS;
    for dy in -r..=r {
        for dx in -r..=r {
            if dx * dx + dy * dy > r * r {
                continue;
            }
            let v = gray[(y as i32 + dy) as usize * w + (x as i32 + dx) as usize] as f32;
            m10 += dx as f32 * v;
            m01 += dy as f32 * v;
        }
    }
    m01.atan2(m10)
}

/// 5 × 5 box filter (edges clamped).
fn box_blur5(gray: &[u8], w: usize, h: usize) -> Vec<u8> {
    let at = |x: i32, y: i32| {
        gray[(y.clamp(0, h as i32 - 1) as usize) * w + x.clamp(0, w as i32 - 1) as usize] as u32
    };
    let mut out = vec![0u8; w * h];
    for y in 0..h as i32 {
        for x in 0..w as i32 {
            let mut s = 0;
            for dy in -2..=2 {
                for dx in -2..=2 {
                    s += at(x + dx, y + dy);
                }
            }
            out[y as usize * w + x as usize] = (s / 25) as u8;
        }
    }
    out
}

/// The 256 test pairs, the same on every run (a seeded xorshift and Box–Muller).
fn pattern() -> Vec<[f32; 4]> {
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        ((state >> 11) as f64 / (1u64 << 53) as f64).max(1e-12) as f32
    };
    let sigma = 31.0 / 5.0;
    let mut gaussian_point = || loop {
        let (u1, u2) = (uniform(), uniform());
        let r = (-2.0 * u1.ln()).sqrt() * sigma;
        let (s, c) = (2.0 * std::f32::consts::PI * u2).sin_cos();
        let p = (r * c, r * s);
        if p.0 * p.0 + p.1 * p.1 <= PATTERN_RADIUS * PATTERN_RADIUS {
            return p;
        }
    };
    (0..256)
        .map(|_| {
            let (a, b) = (gaussian_point(), gaussian_point());
            [a.0, a.1, b.0, b.1]
        })
        .collect()
}

fn describe(
    smooth: &[u8],
    w: usize,
    x: usize,
    y: usize,
    angle: f32,
    pattern: &[[f32; 4]],
) -> [u64; 4] {
    let (s, c) = angle.sin_cos();
    let at = |px: f32, py: f32| {
        let u = (x as f32 + c * px - s * py).round() as usize;
        let v = (y as f32 + s * px + c * py).round() as usize;
        smooth[v * w + u]
    };
    let mut d = [0u64; 4];
    for (k, p) in pattern.iter().enumerate() {
        if at(p[0], p[1]) < at(p[2], p[3]) {
            d[k / 64] |= 1 << (k % 64);
        }
    }
    d
}

/// Number of differing bits.
pub fn hamming(a: &[u64; 4], b: &[u64; 4]) -> u32 {
    a.iter().zip(b).map(|(x, y)| (x ^ y).count_ones()).sum()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A deterministic textured image: blobs of varied brightness on a noisy ramp.
    pub(crate) fn texture(w: usize, h: usize) -> Vec<u8> {
        let mut img = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut v = 60.0 + 40.0 * ((x as f32 * 0.05).sin() + (y as f32 * 0.07).cos());
                for k in 0..40 {
                    let cx = ((k * 7919) % w) as f32;
                    let cy = ((k * 104_729) % h) as f32;
                    let r = 4.0 + (k % 5) as f32 * 2.0;
                    if (x as f32 - cx).powi(2) + (y as f32 - cy).powi(2) < r * r {
                        v = 40.0 + ((k * 37) % 200) as f32;
                    }
                }
                img[y * w + x] = v.clamp(0.0, 255.0) as u8;
            }
        }
        img
    }

    #[test]
    fn keypoints_are_found_inside_the_border_and_capped() {
        let (w, h) = (200, 150);
        let img = texture(w, h);
        let all = detect(&img, w, h, 10_000);
        assert!(all.len() >= 30, "{}", all.len());
        for k in &all {
            assert!(k.x >= BORDER as f32 && k.y >= BORDER as f32);
            assert!(k.x < (w - BORDER) as f32 && k.y < (h - BORDER) as f32);
        }
        let few = detect(&img, w, h, 10);
        assert_eq!(few.len(), 10);
        assert!(few.windows(2).all(|p| p[0].response >= p[1].response));
        assert!(detect(&img, 20, 20, 10).is_empty(), "too small");
    }

    #[test]
    fn descriptors_survive_a_shift_and_differ_between_points() {
        let (w, h) = (200, 150);
        let img = texture(w, h);
        // The same image shifted by (7, 4): every keypoint's descriptor must reappear there.
        let mut shifted = vec![0u8; w * h];
        for y in 4..h {
            for x in 7..w {
                shifted[y * w + x] = img[(y - 4) * w + x - 7];
            }
        }
        let a = detect(&img, w, h, 200);
        let b = detect(&shifted, w, h, 400);
        let mut same = 0;
        for k in a
            .iter()
            .filter(|k| k.x < (w - 30) as f32 && k.y < (h - 30) as f32)
        {
            if let Some(m) = b.iter().find(|m| m.x == k.x + 7.0 && m.y == k.y + 4.0) {
                assert_eq!(hamming(&k.descriptor, &m.descriptor), 0);
                assert!((k.angle_rad - m.angle_rad).abs() < 1e-5);
                same += 1;
            }
        }
        assert!(same >= 10, "{same}");
        let distinct = a
            .windows(2)
            .filter(|p| hamming(&p[0].descriptor, &p[1].descriptor) > 20)
            .count();
        assert!(distinct * 10 >= a.len() * 8, "descriptors are distinctive");
    }
}
