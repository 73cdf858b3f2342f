//! Camera pixels no ray is drawn from: where moving traffic was (the transient returns of
//! [`super::transient`] projected into a frame, each grown into a disc where enough of them
//! fall together) and where the vehicle itself fills the view (pixels still over a camera's
//! frames, joined to the image's bottom row). A mask is row-major, one `bool` per pixel, and
//! empty when nothing is masked.

use glam::DVec2;

use super::depth_calib::CameraFrame;

/// Each transient return masks a disc of this fraction of the image width around it: a car's
/// returns are a few pixels apart at training resolution, the camera's starting extrinsic may
/// be off by a degree, and the car moves between the sweep and the exposure.
pub const MASK_RADIUS_FRACTION: f64 = 0.025;

/// Transient returns that must fall near one another, in an image, for them to mask it.
pub const MASK_MIN_SUPPORT: usize = 4;

/// A pixel whose brightness changes by less than this (standard deviation over a camera's
/// frames, of 255) while the vehicle drives sees the vehicle itself.
pub const EGO_STD_MAX: f64 = 4.0;

/// The part of a camera's view the vehicle itself fills (its bonnet or boot): pixels whose
/// brightness hardly changes over `frames` while the scene moves past, joined to the image's
/// bottom row (so a plain sky is not taken for it). Empty when none is, or with fewer than
/// four frames to tell.
pub fn ego_mask(frames: &[CameraFrame], width: usize, height: usize) -> Vec<bool> {
    let n = width * height;
    if frames.len() < 4 || n == 0 || frames.iter().any(|f| f.rgb.len() != 3 * n) {
        return Vec::new();
    }
    let (mut sum, mut sum_sq) = (vec![0.0f64; n], vec![0.0f64; n]);
    for f in frames {
        for (i, px) in f.rgb.chunks_exact(3).enumerate() {
            let y = crate::features::grey::luma(px[0], px[1], px[2]) as f64;
            sum[i] += y;
            sum_sq[i] += y * y;
        }
    }
    let m = frames.len() as f64;
    let still: Vec<bool> = (0..n)
        .map(|i| {
            let mean = sum[i] / m;
            (sum_sq[i] / m - mean * mean).max(0.0).sqrt() < EGO_STD_MAX
        })
        .collect();
    // Flood fill from the still pixels of the bottom row.
    let mut mask = vec![false; n];
    let mut stack: Vec<usize> = ((height - 1) * width..n).filter(|&i| still[i]).collect();
    for &i in &stack {
        mask[i] = true;
    }
    while let Some(i) = stack.pop() {
        let (x, y) = (i % width, i / width);
        let neighbours = [
            (x > 0).then(|| i - 1),
            (x + 1 < width).then(|| i + 1),
            (y > 0).then(|| i - width),
            (y + 1 < height).then(|| i + width),
        ];
        for j in neighbours.into_iter().flatten() {
            if still[j] && !mask[j] {
                mask[j] = true;
                stack.push(j);
            }
        }
    }
    if mask.iter().any(|m| *m) {
        mask
    } else {
        Vec::new()
    }
}

/// Whether pixel `(x, y)` of a `width`-wide frame is in `masked` (empty: nothing is).
pub fn is_masked(masked: &[bool], width: u32, x: f32, y: f32) -> bool {
    if masked.is_empty() || !(x >= 0.0 && y >= 0.0) {
        return false;
    }
    let (x, y) = (x as usize, y as usize);
    (x < width as usize) && masked.get(y * width as usize + x).copied().unwrap_or(false)
}

/// Mark on `mask` (created `width × height` on the first mark) a disc of
/// [`MASK_RADIUS_FRACTION`] of the width around every pixel of `pixels` that has at least
/// [`MASK_MIN_SUPPORT`] of them within about a disc's radius: a lone return (a leaf, a wire, a
/// grazing ray) masks nothing. Pixels outside the image are ignored.
pub fn mark_traffic(mask: &mut Vec<bool>, pixels: &[DVec2], width: usize, height: usize) {
    let (w, h) = (width, height);
    if w == 0 || h == 0 {
        return;
    }
    let radius = (MASK_RADIUS_FRACTION * w as f64).max(1.0);
    let (cw, ch) = (
        (w as f64 / radius).ceil() as usize,
        (h as f64 / radius).ceil() as usize,
    );
    let cell = |px: &DVec2| {
        (
            ((px.x / radius) as usize).min(cw - 1),
            ((px.y / radius) as usize).min(ch - 1),
        )
    };
    let inside: Vec<&DVec2> = pixels
        .iter()
        .filter(|px| px.x >= 0.0 && px.y >= 0.0 && px.x < w as f64 && px.y < h as f64)
        .collect();
    let mut counts = vec![0usize; cw * ch];
    for px in &inside {
        let (x, y) = cell(px);
        counts[x + cw * y] += 1;
    }
    let support = |px: &DVec2| {
        let (cx, cy) = cell(px);
        let mut n = 0;
        for y in cy.saturating_sub(1)..=(cy + 1).min(ch - 1) {
            for x in cx.saturating_sub(1)..=(cx + 1).min(cw - 1) {
                n += counts[x + cw * y];
            }
        }
        n
    };
    let r = radius.ceil() as i64;
    for px in inside
        .into_iter()
        .filter(|px| support(px) >= MASK_MIN_SUPPORT)
    {
        if mask.is_empty() {
            *mask = vec![false; w * h];
        }
        let (cx, cy) = (px.x.floor() as i64, px.y.floor() as i64);
        for y in (cy - r).max(0)..=(cy + r).min(h as i64 - 1) {
            for x in (cx - r).max(0)..=(cx + r).min(w as i64 - 1) {
                let (dx, dy) = ((x - cx) as f64, (y - cy) as f64);
                if dx * dx + dy * dy <= radius * radius {
                    mask[y as usize * w + x as usize] = true;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 16 × 12 frame: a scene that shifts one pixel per frame above the bottom third, and
    /// the vehicle's grey boot, fixed, below it; the sky (top row) is plain.
    fn frame(t: usize) -> CameraFrame {
        let (w, h) = (16, 12);
        let mut rgb = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                let v = if y == 0 {
                    200
                } else if y >= 8 {
                    90 + (x % 2) as u8
                } else {
                    (((x + t) * 37 + y * 11) % 256) as u8
                };
                rgb.extend([v, v, v]);
            }
        }
        CameraFrame {
            stamp_nanos: t as i64,
            rgb,
            keypoints: Vec::new(),
            masked: Vec::new(),
        }
    }

    #[test]
    fn the_vehicles_own_body_is_masked_and_a_plain_sky_is_not() {
        let frames: Vec<CameraFrame> = (0..6).map(frame).collect();
        let mask = ego_mask(&frames, 16, 12);
        assert_eq!(mask.len(), 16 * 12);
        for y in 0..12 {
            for x in 0..16 {
                assert_eq!(mask[y * 16 + x], y >= 8, "pixel ({x}, {y})");
            }
        }
        assert!(is_masked(&mask, 16, 3.5, 9.2));
        assert!(
            !is_masked(&mask, 16, 3.5, 0.2),
            "the sky is still too, but not the vehicle"
        );
        assert!(!is_masked(&mask, 16, 17.0, 9.0), "outside the image");
        assert!(!is_masked(&[], 16, 3.5, 9.2), "no mask");
    }

    #[test]
    fn too_few_frames_or_a_moving_bottom_row_mask_nothing() {
        let frames: Vec<CameraFrame> = (0..3).map(frame).collect();
        assert!(ego_mask(&frames, 16, 12).is_empty());
        let mut frames: Vec<CameraFrame> = (0..6).map(frame).collect();
        for (t, f) in frames.iter_mut().enumerate() {
            for px in f.rgb[3 * 16 * 8..].iter_mut() {
                *px = (t * 40) as u8;
            }
        }
        assert!(ego_mask(&frames, 16, 12).is_empty());
    }
}
