//! Point clouds of any field layout → [`LidarSweep`].
//!
//! x/y/z may be float32 or float64; intensity is read from `intensity` or `reflectivity` (any
//! numeric type, kept in its native scale); per-point time from `t`, `time`, `timestamp` or
//! `offset_time`. Integer times are nanoseconds, float times seconds; a float time larger than
//! 10⁸ s is taken as absolute (since the epoch) and made relative to the header stamp. Rows may be
//! padded (`row_step > width · point_step`), data may be big-endian, and non-finite points (a
//! non-dense cloud's holes) are dropped.

use super::error::{DecodeError, DecodeResult};
use super::types::{Numeric, PointField, RawPointCloud};

/// One LiDAR sweep in its sensor's frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LidarSweep {
    pub stamp_nanos: i64,
    pub frame_id: String,
    pub points_in_sensor: Vec<[f32; 3]>,
    /// Native scale of the sensor (e.g. 0–255); zeros when the cloud has no intensity field.
    pub intensity: Vec<f32>,
    /// Firing time of each point relative to `stamp_nanos`, when the cloud has a time field.
    pub time_offset_secs: Option<Vec<f32>>,
}

impl LidarSweep {
    pub fn len(&self) -> usize {
        self.points_in_sensor.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points_in_sensor.is_empty()
    }

    /// Keep the points whose flag in `keep` (one per point) is true, with their intensity and
    /// firing time; points beyond `keep`'s length are kept.
    pub fn retain(&mut self, keep: &[bool]) {
        retain_flagged(&mut self.points_in_sensor, keep);
        if self.intensity.len() == keep.len() {
            retain_flagged(&mut self.intensity, keep);
        }
        if let Some(t) = self
            .time_offset_secs
            .as_mut()
            .filter(|t| t.len() == keep.len())
        {
            retain_flagged(t, keep);
        }
    }

    /// What projections need of this sweep.
    pub fn view(&self) -> crate::geometry::projection::SweepView<'_> {
        crate::geometry::projection::SweepView {
            points_in_lidar: &self.points_in_sensor,
            intensity: &self.intensity,
            time_offset_secs: self.time_offset_secs.as_deref(),
            stamp_nanos: self.stamp_nanos,
        }
    }
}

/// Keep `items[i]` where `keep[i]` (or `i` is beyond `keep`).
fn retain_flagged<T>(items: &mut Vec<T>, keep: &[bool]) {
    let mut i = 0;
    items.retain(|_| {
        let k = keep.get(i).copied().unwrap_or(true);
        i += 1;
        k
    });
}

const INTENSITY_NAMES: [&str; 3] = ["intensity", "reflectivity", "i"];
const TIME_NAMES: [&str; 5] = ["t", "time", "timestamp", "offset_time", "time_offset"];

fn find<'f>(fields: &'f [PointField], names: &[&str]) -> Option<&'f PointField> {
    names
        .iter()
        .find_map(|n| fields.iter().find(|f| f.name.eq_ignore_ascii_case(n)))
}

fn read(bytes: &[u8], at: usize, numeric: Numeric, big_endian: bool) -> f64 {
    macro_rules! get {
        ($t:ty, $n:expr) => {{
            let mut b = [0u8; $n];
            b.copy_from_slice(&bytes[at..at + $n]);
            if big_endian {
                <$t>::from_be_bytes(b) as f64
            } else {
                <$t>::from_le_bytes(b) as f64
            }
        }};
    }
    match numeric {
        Numeric::I8 => bytes[at] as i8 as f64,
        Numeric::U8 => bytes[at] as f64,
        Numeric::I16 => get!(i16, 2),
        Numeric::U16 => get!(u16, 2),
        Numeric::I32 => get!(i32, 4),
        Numeric::U32 => get!(u32, 4),
        Numeric::F32 => get!(f32, 4),
        Numeric::F64 => get!(f64, 8),
    }
}

/// Decode a cloud into a sweep.
pub fn to_sweep(cloud: &RawPointCloud<'_>) -> DecodeResult<LidarSweep> {
    let axis = |name: &str| {
        cloud
            .fields
            .iter()
            .find(|f| f.name == name)
            .ok_or_else(|| DecodeError::new(format!("point cloud has no '{name}' field")))
    };
    let (fx, fy, fz) = (axis("x")?, axis("y")?, axis("z")?);
    let intensity = find(&cloud.fields, &INTENSITY_NAMES);
    let time = find(&cloud.fields, &TIME_NAMES);
    let step = cloud.point_step as usize;
    let width = cloud.width as usize;
    let height = cloud.height.max(1) as usize;
    let row_step = if cloud.row_step == 0 {
        width * step
    } else {
        cloud.row_step as usize
    };
    for f in [Some(fx), Some(fy), Some(fz), intensity, time]
        .into_iter()
        .flatten()
    {
        if f.offset as usize + f.numeric.size() > step {
            return Err(DecodeError::new(format!(
                "field '{}' (offset {}, {} bytes) does not fit in point_step {step}",
                f.name,
                f.offset,
                f.numeric.size()
            )));
        }
    }
    if row_step < width * step {
        return Err(DecodeError::new(format!(
            "row_step {row_step} is smaller than width {width} × point_step {step}"
        )));
    }
    let n = width * height;
    let mut sweep = LidarSweep {
        stamp_nanos: cloud.stamp_nanos,
        frame_id: cloud.frame_id.clone(),
        points_in_sensor: Vec::new(),
        intensity: Vec::new(),
        time_offset_secs: time.map(|_| Vec::new()),
    };
    // No point: nothing to walk (rows of zero width would still be walked one by one, four
    // billion of them at most).
    if n == 0 {
        return Ok(sweep);
    }
    // Checked: a layout from the file may claim more bytes than a usize holds.
    let needed = (height - 1)
        .checked_mul(row_step)
        .and_then(|rows| rows.checked_add(width * step));
    if needed.is_none_or(|needed| cloud.data.len() < needed) {
        return Err(DecodeError::new(format!(
            "point data has {} bytes, the layout ({height}×{width}, point_step {step}, row_step {row_step}) needs {}",
            cloud.data.len(),
            needed.map_or("more than can be addressed".to_string(), |n| n.to_string())
        )));
    }
    sweep = LidarSweep {
        stamp_nanos: cloud.stamp_nanos,
        frame_id: cloud.frame_id.clone(),
        points_in_sensor: Vec::with_capacity(n),
        intensity: Vec::with_capacity(n),
        time_offset_secs: time.map(|_| Vec::with_capacity(n)),
    };
    let stamp_secs = cloud.stamp_nanos as f64 * 1e-9;
    let be = cloud.big_endian;
    let identity_origin = cloud.frame_from_cloud == crate::geometry::Rigid::IDENTITY;
    let data: &[u8] = &cloud.data;
    // Fast path for the common layout (little-endian float32 x/y/z and intensity, no time).
    let f32_le = |f: &PointField| f.numeric == Numeric::F32 && !be;
    if identity_origin
        && time.is_none()
        && [fx, fy, fz].into_iter().all(f32_le)
        && intensity.is_none_or(f32_le)
    {
        let at = |base: usize, off: u32| {
            let o = base + off as usize;
            f32::from_le_bytes([data[o], data[o + 1], data[o + 2], data[o + 3]])
        };
        for row in 0..height {
            for col in 0..width {
                let base = row * row_step + col * step;
                let p = [
                    at(base, fx.offset),
                    at(base, fy.offset),
                    at(base, fz.offset),
                ];
                if p.iter().all(|v| v.is_finite()) {
                    sweep.points_in_sensor.push(p);
                    sweep
                        .intensity
                        .push(intensity.map_or(0.0, |f| at(base, f.offset)));
                }
            }
        }
        return Ok(sweep);
    }
    for row in 0..height {
        for col in 0..width {
            let base = row * row_step + col * step;
            let p = [
                read(data, base + fx.offset as usize, fx.numeric, be),
                read(data, base + fy.offset as usize, fy.numeric, be),
                read(data, base + fz.offset as usize, fz.numeric, be),
            ];
            if !p.iter().all(|v| v.is_finite()) {
                continue;
            }
            let p = if identity_origin {
                p
            } else {
                cloud
                    .frame_from_cloud
                    .transform_point(glam::DVec3::from_array(p))
                    .to_array()
            };
            sweep
                .points_in_sensor
                .push([p[0] as f32, p[1] as f32, p[2] as f32]);
            sweep.intensity.push(intensity.map_or(0.0, |f| {
                read(data, base + f.offset as usize, f.numeric, be) as f32
            }));
            if let (Some(f), Some(times)) = (time, sweep.time_offset_secs.as_mut()) {
                let raw = read(data, base + f.offset as usize, f.numeric, be);
                let secs = if f.numeric.is_integer() {
                    raw * 1e-9
                } else if raw > 1e8 {
                    raw - stamp_secs
                } else {
                    raw
                };
                times.push(secs as f32);
            }
        }
    }
    Ok(sweep)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(name: &str, offset: u32, numeric: Numeric) -> PointField {
        PointField {
            name: name.into(),
            offset,
            numeric,
        }
    }

    #[test]
    fn decodes_padded_big_endian_rows_with_absolute_time() {
        // 2×2 organized cloud, x/y/z f32, reflectivity u16, timestamp f64 absolute; big-endian;
        // point_step 24, row_step 56 (8 bytes of row padding).
        let stamp = 1_700_000_000_000_000_000i64;
        let mut data = Vec::new();
        for row in 0..2 {
            for col in 0..2 {
                let i = (row * 2 + col) as f32;
                for v in [i, -i, 0.5 * i] {
                    data.extend_from_slice(&v.to_be_bytes());
                }
                data.extend_from_slice(&(100u16 + i as u16).to_be_bytes());
                data.extend_from_slice(&[0, 0]);
                data.extend_from_slice(&(1_700_000_000.0f64 + 0.01 * i as f64).to_be_bytes());
            }
            data.extend_from_slice(&[0xAA; 8]);
        }
        let cloud = RawPointCloud {
            stamp_nanos: stamp,
            frame_id: "lidar".into(),
            fields: vec![
                field("x", 0, Numeric::F32),
                field("y", 4, Numeric::F32),
                field("z", 8, Numeric::F32),
                field("reflectivity", 12, Numeric::U16),
                field("timestamp", 16, Numeric::F64),
            ],
            width: 2,
            height: 2,
            point_step: 24,
            row_step: 56,
            big_endian: true,
            data: data.as_slice().into(),
            frame_from_cloud: crate::geometry::Rigid::IDENTITY,
        };
        let s = to_sweep(&cloud).unwrap();
        assert_eq!(s.len(), 4);
        assert_eq!(s.points_in_sensor[3], [3.0, -3.0, 1.5]);
        assert_eq!(s.intensity[2], 102.0);
        let t = s.time_offset_secs.unwrap();
        assert!((t[3] - 0.03).abs() < 1e-6, "{t:?}");
    }

    #[test]
    fn short_data_is_an_error_not_a_panic() {
        let cloud = RawPointCloud {
            stamp_nanos: 0,
            frame_id: String::new(),
            fields: vec![
                field("x", 0, Numeric::F32),
                field("y", 4, Numeric::F32),
                field("z", 8, Numeric::F32),
            ],
            width: 10,
            height: 1,
            point_step: 12,
            row_step: 120,
            big_endian: false,
            data: vec![0u8; 50].into(),
            frame_from_cloud: crate::geometry::Rigid::IDENTITY,
        };
        assert!(to_sweep(&cloud).unwrap_err().0.contains("needs 120"));
        let bad = RawPointCloud {
            point_step: 4,
            ..cloud.clone()
        };
        assert!(to_sweep(&bad).is_err());
    }
}
