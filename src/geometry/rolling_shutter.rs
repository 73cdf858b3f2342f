//! When each row of a rolling-shutter image was exposed.
//!
//! A rolling shutter reads an image out row by row, top to bottom, so on a moving vehicle each
//! row sees the scene from a slightly different place: at 5 m/s a 40 ms readout spreads one
//! image over 20 cm of the drive. [`RowTimes`] holds when the first and the last row were
//! exposed relative to the image's stamp; rows in between are spaced evenly. The pose of a
//! pixel's ray is the vehicle's pose at its row's time composed with the camera's extrinsic.
//! The zero value is a global shutter exposed at the stamp.
//!
//! Where a pose per row would be costly, an image keeps the vehicle's pose at [`SAMPLED_ROWS`]
//! rows spread from its top edge to its bottom edge ([`RowTimes::sampled_offsets_nanos`]), and a
//! pixel takes the sample nearest its row ([`RowTimes::nearest_sample`]).

/// Rows of a rolling-shutter image whose pose is sampled: with a 40 ms readout a row is then at
/// most 0.6 ms from a sample (7 mm at 40 km/h).
pub const SAMPLED_ROWS: usize = 33;

/// The exposure times of an image's first and last rows, relative to its stamp.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RowTimes {
    /// When the readout began, at the image's top edge (y = −0.5), relative to the stamp (ns;
    /// negative: before it). Row 0's centre is half a row later; as NeuRAD counts it.
    pub first_row_nanos: i64,
    /// When the readout ended, at the bottom edge (ns).
    pub last_row_nanos: i64,
}

impl RowTimes {
    /// A global shutter exposed at the stamp.
    pub const GLOBAL: Self = Self {
        first_row_nanos: 0,
        last_row_nanos: 0,
    };

    /// From milliseconds (first row, last row).
    pub fn from_millis(first_ms: f64, last_ms: f64) -> Self {
        Self {
            first_row_nanos: (first_ms * 1e6).round() as i64,
            last_row_nanos: (last_ms * 1e6).round() as i64,
        }
    }

    /// Parse `FIRST..LAST` in milliseconds, each within ±1000 (LAST below FIRST is a readout
    /// from the bottom up); the error says what is wrong with `text`.
    pub fn parse_millis(text: &str) -> Result<Self, crate::error::ParseError> {
        let (a, b) = text.split_once("..").ok_or_else(|| {
            format!("'{text}': expected FIRST..LAST in milliseconds, e.g. -30..10")
        })?;
        let parse = |s: &str| {
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && v.abs() <= 1000.0)
                .ok_or_else(|| {
                    format!("'{text}': '{s}' is not a number of milliseconds within ±1000")
                })
        };
        Ok(Self::from_millis(parse(a)?, parse(b)?))
    }

    /// Whether every row is exposed at the stamp.
    pub fn is_global(&self) -> bool {
        *self == Self::GLOBAL
    }

    /// When the row at pixel coordinate `y` (pixel centres at integers, as in
    /// [`super::camera::CameraIntrinsics`]) of an image `height` rows tall was exposed,
    /// relative to the stamp. The row's fraction of the image is the same at any scale, so
    /// downscaled images use their own `y` and `height`.
    pub fn offset_nanos(&self, y: f64, height: u32) -> i64 {
        if self.first_row_nanos == self.last_row_nanos || height == 0 {
            return self.first_row_nanos;
        }
        let span = (self.last_row_nanos - self.first_row_nanos) as f64;
        self.first_row_nanos + (span * Self::row_fraction(y, height)).round() as i64
    }

    /// How far down the image pixel coordinate `y` lies: 0 at the top edge (y = −0.5), 1 at
    /// the bottom edge (y = height − 0.5), clamped to those.
    pub fn row_fraction(y: f64, height: u32) -> f64 {
        ((y + 0.5) / f64::from(height.max(1))).clamp(0.0, 1.0)
    }

    /// When the middle of the image was exposed, relative to the stamp.
    pub fn middle_nanos(&self) -> i64 {
        self.first_row_nanos + (self.last_row_nanos - self.first_row_nanos) / 2
    }

    /// When `rows` samples spread evenly from the top edge to the bottom edge were exposed,
    /// relative to the stamp (sample k at k / (rows − 1) of the way); one sample is the middle
    /// row's.
    pub fn sampled_offsets_nanos(&self, rows: usize) -> Vec<i64> {
        if rows <= 1 {
            return vec![self.middle_nanos()];
        }
        let span = (self.last_row_nanos - self.first_row_nanos) as f64;
        (0..rows)
            .map(|k| self.first_row_nanos + (span * k as f64 / (rows - 1) as f64).round() as i64)
            .collect()
    }

    /// Which of `rows` samples ([`Self::sampled_offsets_nanos`]) pixel coordinate `y` of an
    /// image `height` rows tall is nearest.
    pub fn nearest_sample(y: f64, height: u32, rows: usize) -> usize {
        (Self::row_fraction(y, height) * rows.saturating_sub(1) as f64).round() as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_run_from_the_top_edge_to_the_bottom_edge() {
        let t = RowTimes::from_millis(-30.0, 10.0);
        let samples = t.sampled_offsets_nanos(SAMPLED_ROWS);
        assert_eq!(samples.len(), SAMPLED_ROWS);
        assert_eq!(samples[0], t.offset_nanos(-0.5, 1080));
        assert_eq!(samples[16], t.middle_nanos());
        assert_eq!(samples[32], t.offset_nanos(1079.5, 1080));
        assert_eq!(t.sampled_offsets_nanos(1), vec![-10_000_000]);
        // A pixel takes the sample nearest its row: the top, the middle and the bottom rows.
        assert_eq!(RowTimes::nearest_sample(0.0, 1080, SAMPLED_ROWS), 0);
        assert_eq!(RowTimes::nearest_sample(539.5, 1080, SAMPLED_ROWS), 16);
        assert_eq!(RowTimes::nearest_sample(1079.0, 1080, SAMPLED_ROWS), 32);
        assert_eq!(RowTimes::nearest_sample(700.0, 1080, 1), 0);
    }

    #[test]
    fn rows_are_spaced_evenly_from_the_first_to_the_last() {
        let t = RowTimes::from_millis(-30.0, 10.0);
        let h = 1080;
        // The top edge of the image is the first row's time, the bottom edge the last's.
        assert_eq!(t.offset_nanos(-0.5, h), -30_000_000);
        assert_eq!(t.offset_nanos(h as f64 - 0.5, h), 10_000_000);
        assert_eq!(t.offset_nanos(539.5, h), -10_000_000);
        assert_eq!(t.middle_nanos(), -10_000_000);
        // The same row at a quarter of the size is exposed at the same time.
        assert_eq!(t.offset_nanos(134.5, h / 4), t.offset_nanos(539.5, h));
        // Rows outside the image are clamped to the readout.
        assert_eq!(t.offset_nanos(5000.0, h), 10_000_000);
        assert_eq!(t.offset_nanos(-40.0, h), -30_000_000);
        let mut previous = i64::MIN;
        for y in 0..h {
            let o = t.offset_nanos(y as f64, h);
            assert!(o > previous, "row {y}");
            previous = o;
        }
    }

    #[test]
    fn a_global_shutter_exposes_every_row_at_one_time() {
        assert!(RowTimes::default().is_global());
        assert_eq!(RowTimes::GLOBAL.offset_nanos(700.0, 1080), 0);
        let late = RowTimes::from_millis(5.0, 5.0);
        assert!(!late.is_global());
        assert_eq!(late.offset_nanos(0.0, 1080), 5_000_000);
        assert_eq!(late.offset_nanos(1079.0, 0), 5_000_000);
    }
}
