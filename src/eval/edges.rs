//! A target-free LiDAR–camera alignment score: the mean distance (px) from projected LiDAR depth
//! discontinuities to the nearest image edge.
//!
//! How it works: image edges are Sobel gradient maxima above a threshold relative to the image's
//! own gradient distribution; an exact Euclidean distance transform (Felzenszwalb–Huttenlocher,
//! two 1D passes) gives every pixel its distance to the nearest edge. LiDAR discontinuities are
//! found per beam: points are grouped by elevation, ordered by azimuth, and where consecutive
//! returns jump in range by more than `max(0.5 m, 10 %)` the nearer one is a silhouette point.
//! Those points are projected with the calibration under test; misalignment moves them off the
//! silhouettes and the score grows.

use image::RgbImage;

/// Edge map (true = edge) of an RGB image.
pub fn image_edges(img: &RgbImage) -> Vec<bool> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let gray = crate::features::grey::grey_levels(img);
    let mut mag = vec![0.0f32; w * h];
    let mut dir_horizontal = vec![false; w * h];
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let g = |dx: isize, dy: isize| {
                gray[(y as isize + dy) as usize * w + (x as isize + dx) as usize]
            };
            let gx = (g(1, -1) + 2.0 * g(1, 0) + g(1, 1)) - (g(-1, -1) + 2.0 * g(-1, 0) + g(-1, 1));
            let gy = (g(-1, 1) + 2.0 * g(0, 1) + g(1, 1)) - (g(-1, -1) + 2.0 * g(0, -1) + g(1, -1));
            mag[y * w + x] = (gx * gx + gy * gy).sqrt();
            dir_horizontal[y * w + x] = gx.abs() >= gy.abs();
        }
    }
    // Threshold: the 95th percentile of non-zero gradients, at least 40 (of 255·4).
    let mut sorted: Vec<f32> = mag.iter().copied().filter(|m| *m > 1.0).collect();
    let threshold = if sorted.is_empty() {
        f32::MAX
    } else {
        let k = (sorted.len() * 19 / 20).min(sorted.len() - 1);
        let (_, kth, _) = sorted.select_nth_unstable_by(k, f32::total_cmp);
        kth.max(40.0)
    };
    // Non-maximum suppression across the gradient direction keeps edges one pixel thin.
    let mut edges = vec![false; w * h];
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let k = y * w + x;
            let m = mag[k];
            if m < threshold {
                continue;
            }
            let (a, b) = if dir_horizontal[k] {
                (mag[k - 1], mag[k + 1])
            } else {
                (mag[k - w], mag[k + w])
            };
            edges[k] = m >= a && m >= b;
        }
    }
    edges
}

/// Exact Euclidean distance (px) from every pixel to the nearest `true` pixel.
pub fn distance_transform(mask: &[bool], w: usize, h: usize) -> Vec<f32> {
    const INF: f32 = 1e20;
    let mut f: Vec<f32> = mask.iter().map(|&m| if m { 0.0 } else { INF }).collect();
    let mut buf = vec![0.0f32; w.max(h)];
    let mut out = vec![0.0f32; w.max(h)];
    // Columns, then rows, of squared distances.
    for x in 0..w {
        for y in 0..h {
            buf[y] = f[y * w + x];
        }
        dt_1d(&buf[..h], &mut out[..h]);
        for y in 0..h {
            f[y * w + x] = out[y];
        }
    }
    for y in 0..h {
        buf[..w].copy_from_slice(&f[y * w..(y + 1) * w]);
        dt_1d(&buf[..w], &mut out[..w]);
        f[y * w..(y + 1) * w].copy_from_slice(&out[..w]);
    }
    f.into_iter().map(|d| d.sqrt()).collect()
}

/// 1D squared-distance transform of a sampled function (lower envelope of parabolas).
fn dt_1d(f: &[f32], d: &mut [f32]) {
    let n = f.len();
    if n == 0 {
        return;
    }
    let mut v = vec![0usize; n];
    let mut z = vec![0.0f32; n + 1];
    let mut k = 0usize;
    z[0] = f32::MIN;
    z[1] = f32::MAX;
    for q in 1..n {
        loop {
            let p = v[k];
            let s = ((f[q] + (q * q) as f32) - (f[p] + (p * p) as f32))
                / (2.0 * q as f32 - 2.0 * p as f32);
            if s <= z[k] && k > 0 {
                k -= 1;
                continue;
            }
            if s <= z[k] {
                // k == 0: replace the first parabola.
                v[0] = q;
                z[0] = f32::MIN;
                z[1] = f32::MAX;
                break;
            }
            k += 1;
            v[k] = q;
            z[k] = s;
            z[k + 1] = f32::MAX;
            break;
        }
    }
    k = 0;
    for q in 0..n {
        while z[k + 1] < q as f32 {
            k += 1;
        }
        let p = v[k];
        d[q] = (q as f32 - p as f32).powi(2) + f[p];
    }
}

/// Indices of silhouette points: the nearer of two azimuth-neighbours on one beam whose ranges
/// differ by more than max(0.5 m, 10 %). `elevation_bin_deg` groups points into beams.
pub fn depth_discontinuities(points_in_lidar: &[[f32; 3]], elevation_bin_deg: f32) -> Vec<usize> {
    let mut keyed: Vec<(i32, f32, f32, usize)> = points_in_lidar
        .iter()
        .enumerate()
        .filter_map(|(i, p)| {
            let r_xy = (p[0] * p[0] + p[1] * p[1]).sqrt();
            let range = (r_xy * r_xy + p[2] * p[2]).sqrt();
            if range < 0.5 {
                return None;
            }
            let el = p[2].atan2(r_xy).to_degrees();
            Some((
                (el / elevation_bin_deg).round() as i32,
                p[1].atan2(p[0]),
                range,
                i,
            ))
        })
        .collect();
    keyed.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut out = Vec::new();
    for pair in keyed.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        if a.0 != b.0 || (b.1 - a.1).abs() > 1.0f32.to_radians() {
            continue;
        }
        let (near, far) = if a.2 < b.2 { (a, b) } else { (b, a) };
        if far.2 - near.2 > (0.5f32).max(0.1 * near.2) {
            out.push(near.3);
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// The pixels that lie in the image (rounded to the nearest pixel), each with its distance (px)
/// to the nearest edge from a precomputed distance transform.
pub fn edge_distances<'a>(
    pixels: &'a [[f32; 2]],
    distance: &'a [f32],
    w: usize,
    h: usize,
) -> impl Iterator<Item = ([f32; 2], f32)> + 'a {
    pixels.iter().filter_map(move |p| {
        let (x, y) = (p[0].round(), p[1].round());
        (x >= 0.0 && y >= 0.0 && x < w as f32 && y < h as f32)
            .then(|| (*p, distance[y as usize * w + x as usize]))
    })
}

/// Mean distance (px) from pixels to the nearest edge, using a precomputed distance transform;
/// `None` when no pixel lies in the image.
pub fn mean_edge_distance(
    pixels: &[[f32; 2]],
    distance: &[f32],
    w: usize,
    h: usize,
) -> Option<f64> {
    let (sum, n) = edge_distances(pixels, distance, w, h)
        .fold((0.0f64, 0usize), |(sum, n), (_, d)| (sum + d as f64, n + 1));
    (n > 0).then(|| sum / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_transform_is_exact_on_a_small_grid() {
        let (w, h) = (7, 5);
        let mut mask = vec![false; w * h];
        mask[2 * w + 3] = true;
        mask[4 * w] = true;
        let d = distance_transform(&mask, w, h);
        for y in 0..h {
            for x in 0..w {
                let a = ((x as f32 - 3.0).powi(2) + (y as f32 - 2.0).powi(2)).sqrt();
                let b = ((x as f32).powi(2) + (y as f32 - 4.0).powi(2)).sqrt();
                assert!((d[y * w + x] - a.min(b)).abs() < 1e-5, "({x},{y})");
            }
        }
    }

    #[test]
    fn a_step_image_has_one_vertical_edge_line() {
        let img = RgbImage::from_fn(20, 10, |x, _| {
            if x < 10 {
                image::Rgb([20, 20, 20])
            } else {
                image::Rgb([220, 220, 220])
            }
        });
        let e = image_edges(&img);
        for y in 1..9 {
            let xs: Vec<usize> = (0..20).filter(|&x| e[y * 20 + x]).collect();
            assert!(
                !xs.is_empty() && xs.iter().all(|&x| x == 9 || x == 10),
                "{xs:?}"
            );
        }
    }

    #[test]
    fn discontinuities_mark_the_nearer_side() {
        // One beam: a wall at 10 m with a post at 4 m in the middle.
        let mut pts = Vec::new();
        for k in 0..40 {
            let az = (k as f32 - 20.0) * 0.2f32.to_radians();
            let r = if (18..22).contains(&k) { 4.0 } else { 10.0 };
            pts.push([r * az.cos(), r * az.sin(), 0.0]);
        }
        let d = depth_discontinuities(&pts, 0.1);
        assert_eq!(d, vec![18, 21]);
    }
}
