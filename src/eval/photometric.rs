//! Photometric consistency of a rendered image against the observed one (method.md §13; the
//! paper's Tables A9 and A11): PSNR and SSIM.
//!
//! Images are interleaved 8-bit channels of equal size; values are taken in [0, 1]. PSNR is
//! `10 log10(1 / MSE)` over every channel (infinite for identical images). SSIM follows Wang et
//! al. (2004): local means, variances and covariance under an 11 × 11 Gaussian window of σ = 1.5
//! (separable, computed where the window fits the image), `C1 = 0.01²`, `C2 = 0.03²`, the map
//! averaged over the image and then over the channels.

/// Window radius (11 × 11) and σ of SSIM's Gaussian window.
const RADIUS: usize = 5;
const SIGMA: f64 = 1.5;
const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

/// Peak signal-to-noise ratio in dB of `a` against `b` (`None` if their sizes differ or are 0).
pub fn psnr(a: &[u8], b: &[u8]) -> Option<f64> {
    if a.len() != b.len() || a.is_empty() {
        return None;
    }
    let sum: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| {
            let d = (*x as f64 - *y as f64) / 255.0;
            d * d
        })
        .sum();
    let mse = sum / a.len() as f64;
    Some(if mse == 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    })
}

/// Mean structural similarity of two `width × height` images of `channels` interleaved
/// channels (`None` if the sizes disagree or the image is smaller than the 11 × 11 window).
pub fn ssim(a: &[u8], b: &[u8], width: usize, height: usize, channels: usize) -> Option<f64> {
    let n = width * height * channels;
    let window = 2 * RADIUS + 1;
    if a.len() != n || b.len() != n || channels == 0 || width < window || height < window {
        return None;
    }
    let kernel = gaussian_kernel();
    let mut total = 0.0;
    for ch in 0..channels {
        let plane = |img: &[u8]| -> Vec<f64> {
            img.iter()
                .skip(ch)
                .step_by(channels)
                .map(|v| *v as f64 / 255.0)
                .collect()
        };
        let (x, y) = (plane(a), plane(b));
        let product =
            |p: &[f64], q: &[f64]| -> Vec<f64> { p.iter().zip(q).map(|(u, v)| u * v).collect() };
        let blur = |img: &[f64]| blur_valid(img, width, height, &kernel);
        let (mx, my) = (blur(&x), blur(&y));
        let (xx, yy, xy) = (
            blur(&product(&x, &x)),
            blur(&product(&y, &y)),
            blur(&product(&x, &y)),
        );
        let mut sum = 0.0;
        for i in 0..mx.len() {
            let (ux, uy) = (mx[i], my[i]);
            let vx = (xx[i] - ux * ux).max(0.0);
            let vy = (yy[i] - uy * uy).max(0.0);
            let cov = xy[i] - ux * uy;
            sum += ((2.0 * ux * uy + C1) * (2.0 * cov + C2))
                / ((ux * ux + uy * uy + C1) * (vx + vy + C2));
        }
        total += sum / mx.len() as f64;
    }
    Some(total / channels as f64)
}

fn gaussian_kernel() -> Vec<f64> {
    let k: Vec<f64> = (0..=2 * RADIUS)
        .map(|i| {
            let x = i as f64 - RADIUS as f64;
            (-x * x / (2.0 * SIGMA * SIGMA)).exp()
        })
        .collect();
    let sum: f64 = k.iter().sum();
    k.into_iter().map(|v| v / sum).collect()
}

/// Separable blur keeping only the positions where the whole window fits:
/// `(width − 2r) × (height − 2r)` values.
fn blur_valid(img: &[f64], width: usize, height: usize, kernel: &[f64]) -> Vec<f64> {
    let out_w = width - 2 * RADIUS;
    let out_h = height - 2 * RADIUS;
    let mut rows = vec![0.0; out_w * height];
    for y in 0..height {
        let line = &img[y * width..(y + 1) * width];
        for x in 0..out_w {
            rows[y * out_w + x] = kernel.iter().zip(&line[x..]).map(|(k, v)| k * v).sum();
        }
    }
    let mut out = vec![0.0; out_w * out_h];
    for y in 0..out_h {
        for x in 0..out_w {
            out[y * out_w + x] = kernel
                .iter()
                .enumerate()
                .map(|(j, k)| k * rows[(y + j) * out_w + x])
                .sum();
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn textured(width: usize, height: usize) -> Vec<u8> {
        (0..width * height * 3)
            .map(|i| ((i * 7919 + (i / 3) * 31) % 251) as u8)
            .collect()
    }

    #[test]
    fn identical_images_are_infinitely_sharp_and_fully_similar() {
        let img = textured(32, 24);
        assert_eq!(psnr(&img, &img), Some(f64::INFINITY));
        let s = ssim(&img, &img, 32, 24, 3).unwrap_or(0.0);
        assert!((s - 1.0).abs() < 1e-12, "{s}");
    }

    #[test]
    fn psnr_of_a_constant_offset_is_known() {
        // Every value 10 grey levels off: MSE = (10/255)², PSNR = 20 log10(25.5) = 28.13 dB.
        let (a, b) = (vec![100u8; 300], vec![110u8; 300]);
        let p = psnr(&a, &b).unwrap_or(0.0);
        assert!((p - 20.0 * 25.5f64.log10()).abs() < 1e-9, "{p}");
        assert_eq!(psnr(&a, &b[..299]), None);
    }

    #[test]
    fn ssim_of_flat_images_is_the_luminance_term() {
        // No variance anywhere: SSIM = (2 μa μb + C1) / (μa² + μb² + C1).
        let (a, b) = (vec![51u8; 20 * 20], vec![204u8; 20 * 20]);
        let (ua, ub) = (0.2, 0.8);
        let want = (2.0 * ua * ub + C1) / (ua * ua + ub * ub + C1);
        let s = ssim(&a, &b, 20, 20, 1).unwrap_or(0.0);
        assert!((s - want).abs() < 1e-9, "{s} vs {want}");
    }

    #[test]
    fn noise_lowers_both_and_inverting_structure_lowers_ssim_most() {
        let img = textured(40, 30);
        let noisy: Vec<u8> = img
            .iter()
            .enumerate()
            .map(|(i, v)| v.saturating_add((i % 5) as u8 * 3))
            .collect();
        let inverted: Vec<u8> = img.iter().map(|v| 255 - v).collect();
        let s_noisy = ssim(&img, &noisy, 40, 30, 3).unwrap_or(1.0);
        let s_inv = ssim(&img, &inverted, 40, 30, 3).unwrap_or(1.0);
        assert!(s_noisy < 1.0 && s_inv < s_noisy, "{s_noisy} {s_inv}");
        assert!(psnr(&img, &noisy).unwrap_or(f64::INFINITY) > 20.0);
        assert_eq!(ssim(&img, &img, 4, 4, 3), None, "too small for the window");
    }
}
