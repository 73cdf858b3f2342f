//! Camera images → 8-bit RGB: raw encodings (rgb8, bgr8, rgba8, bgra8, mono8, mono16) and
//! compressed JPEG / PNG.

use image::RgbImage;

use super::error::{DecodeError, DecodeResult};
use super::types::{CompressedImage, RawImage};

/// Decode a raw image, honouring `step` (row padding) and the byte order of mono16.
pub fn decode_raw(img: &RawImage<'_>) -> DecodeResult<RgbImage> {
    let enc = img.encoding.to_ascii_lowercase();
    let bpp = match enc.as_str() {
        "rgb8" | "bgr8" => 3,
        "rgba8" | "bgra8" => 4,
        "mono8" | "8uc1" => 1,
        "mono16" | "16uc1" => 2,
        other => {
            return Err(DecodeError::new(format!(
                "unsupported image encoding '{other}'"
            )));
        }
    };
    let (w, h) = (img.width as usize, img.height as usize);
    // An image of no pixel is of no use to a run (and its four billion empty rows would
    // still be walked one by one).
    if w == 0 || h == 0 {
        return Err(DecodeError::new(format!(
            "image of {w}×{h} pixels has none"
        )));
    }
    let row_bytes = w * bpp; // ≤ 4 × u32::MAX: no overflow on 64-bit
    let step = if img.step == 0 {
        row_bytes
    } else {
        img.step as usize
    };
    if step < row_bytes {
        return Err(DecodeError::new(format!(
            "step {step} is smaller than width {w} × {bpp} bytes"
        )));
    }
    // A corrupt header can claim more bytes than a usize holds; such an image is as short of
    // data as any other.
    let needed = (h - 1)
        .checked_mul(step)
        .and_then(|n| n.checked_add(row_bytes))
        .unwrap_or(usize::MAX);
    if img.data.len() < needed {
        return Err(DecodeError::new(format!(
            "image data has {} bytes, {w}×{h} {enc} needs {needed}",
            img.data.len()
        )));
    }
    let mut out = RgbImage::new(img.width, img.height);
    for y in 0..h {
        let row = &img.data[y * step..y * step + row_bytes];
        for x in 0..w {
            let p = &row[x * bpp..x * bpp + bpp];
            let rgb = match enc.as_str() {
                "rgb8" | "rgba8" => [p[0], p[1], p[2]],
                "bgr8" | "bgra8" => [p[2], p[1], p[0]],
                "mono8" | "8uc1" => [p[0]; 3],
                _ => {
                    let v = if img.big_endian {
                        u16::from_be_bytes([p[0], p[1]])
                    } else {
                        u16::from_le_bytes([p[0], p[1]])
                    };
                    [(v >> 8) as u8; 3]
                }
            };
            out.put_pixel(x as u32, y as u32, image::Rgb(rgb));
        }
    }
    Ok(out)
}

/// Decode a JPEG or PNG (the format string is a hint; the bytes decide).
pub fn decode_compressed(img: &CompressedImage<'_>) -> DecodeResult<RgbImage> {
    let format = image::guess_format(&img.data).map_err(|_| {
        DecodeError::new(format!(
            "compressed image ('{}') is neither JPEG nor PNG",
            img.format
        ))
    })?;
    if format == image::ImageFormat::Jpeg && !has_end_of_image_after_scan(&img.data) {
        // The decoder would fill what is missing with grey and say nothing.
        return Err(DecodeError::new(
            "JPEG data ends without its end-of-image marker (truncated?)".to_string(),
        ));
    }
    image::load_from_memory_with_format(&img.data, format)
        .map(|d| d.into_rgb8())
        .map_err(|e| DecodeError::new(format!("cannot decode {:?} image: {e}", format)))
}

/// Whether JPEG data has its end-of-image marker (FF D9) after the first start of scan (FF DA):
/// entropy-coded data cannot hold FF D9 (an FF there is followed by 00), so a scan cut short has
/// none, while bytes an encoder appends after the marker (fill, metadata) do not matter, and an
/// EXIF thumbnail's marker comes before the scan.
fn has_end_of_image_after_scan(data: &[u8]) -> bool {
    let Some(scan) = data.windows(2).position(|w| w == [0xFF, 0xDA]) else {
        return false;
    };
    // From the end: the marker is almost always the last two bytes.
    data[scan..].windows(2).rev().any(|w| w == [0xFF, 0xD9])
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn a_truncated_jpeg_is_an_error_not_a_grey_image() {
        let pixels =
            image::RgbImage::from_fn(32, 16, |x, y| image::Rgb([x as u8 * 8, y as u8 * 16, 90]));
        let mut jpeg = Vec::new();
        image::DynamicImage::ImageRgb8(pixels)
            .write_to(
                &mut std::io::Cursor::new(&mut jpeg),
                image::ImageFormat::Jpeg,
            )
            .unwrap();
        let message = |data: Vec<u8>| CompressedImage {
            stamp_nanos: 0,
            frame_id: "camera".into(),
            format: "jpeg".into(),
            data: data.into(),
        };
        assert_eq!(
            decode_compressed(&message(jpeg.clone()))
                .unwrap()
                .dimensions(),
            (32, 16)
        );
        // Bytes an encoder appends after the marker are fine.
        let mut padded = jpeg.clone();
        padded.extend([0, 0, 0xFF, 0xFF, b'x']);
        assert!(decode_compressed(&message(padded)).is_ok());
        let cut = jpeg[..jpeg.len() - 40].to_vec();
        let err = decode_compressed(&message(cut)).unwrap_err().to_string();
        assert!(err.contains("end-of-image marker"), "{err}");
    }

    #[test]
    fn a_header_claiming_more_bytes_than_memory_is_an_error() {
        // Found by the ros2 fuzz target: (height − 1) × step + width × 4 overflowed a u64.
        let image = RawImage {
            stamp_nanos: 0,
            frame_id: "camera".into(),
            width: u32::MAX,
            height: u32::MAX,
            encoding: "rgba8".into(),
            big_endian: false,
            step: 0, // the packed step, 4 × width
            data: vec![0u8; 64].into(),
        };
        let err = decode_raw(&image).unwrap_err().to_string();
        assert!(err.contains("needs"), "{err}");
    }
}
