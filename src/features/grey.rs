//! The one grey-level conversion: Rec. 601 luma, Y = 0.299 R + 0.587 G + 0.114 B, in the
//! three forms rigcal's image code uses (0–255 as f32, 0–1 as f32, and 8-bit, where the
//! integer weights 299 / 587 / 114 over 1000 give the same value, truncated).

use image::RgbImage;

/// Rec. 601 luma of one pixel, 0–255.
#[inline]
pub fn luma(r: u8, g: u8, b: u8) -> f32 {
    0.299 * r as f32 + 0.587 * g as f32 + 0.114 * b as f32
}

/// Grey levels of an image, 0–255, row-major.
pub fn grey_levels(img: &RgbImage) -> Vec<f32> {
    img.pixels().map(|p| luma(p[0], p[1], p[2])).collect()
}

/// Grey levels of an image, 0–1, row-major.
pub fn grey_unit(img: &RgbImage) -> Vec<f32> {
    img.pixels()
        .map(|p| luma(p[0], p[1], p[2]) / 255.0)
        .collect()
}

/// Grey levels of an image, 8-bit, row-major (integer arithmetic, truncated).
pub fn grey_u8(img: &RgbImage) -> Vec<u8> {
    img.pixels()
        .map(|p| ((299 * p[0] as u32 + 587 * p[1] as u32 + 114 * p[2] as u32) / 1000) as u8)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_three_forms_agree_on_known_pixels() {
        let img = RgbImage::from_raw(3, 1, vec![255, 0, 0, 0, 255, 0, 10, 20, 30]).unwrap();
        let levels = grey_levels(&img);
        assert!((levels[0] - 76.245).abs() < 1e-3 && (levels[1] - 149.685).abs() < 1e-3);
        assert!((levels[2] - 18.15).abs() < 1e-3);
        let unit = grey_unit(&img);
        assert!((unit[1] - 149.685 / 255.0).abs() < 1e-6);
        assert_eq!(grey_u8(&img), vec![76, 149, 18]);
        let white = RgbImage::from_pixel(1, 1, image::Rgb([255, 255, 255]));
        assert_eq!(grey_u8(&white), vec![255]);
        assert!((grey_levels(&white)[0] - 255.0).abs() < 1e-3);
    }
}
