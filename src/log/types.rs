//! Decoded message content shared by the ROS 2 and Foxglove decoders.

use crate::geometry::Rigid;
use crate::geometry::camera::CameraIntrinsics;

/// Nanoseconds since the epoch from a (sec, nsec) stamp.
pub fn stamp_nanos(sec: i64, nsec: u32) -> super::error::DecodeResult<i64> {
    sec.checked_mul(1_000_000_000)
        .and_then(|ns| ns.checked_add(i64::from(nsec)))
        .ok_or_else(|| {
            super::error::DecodeError::new(format!(
                "stamp {sec} s {nsec} ns is outside the range of nanosecond stamps"
            ))
        })
}

/// One edge of the TF tree: `parent_from_child` at `stamp_nanos`.
#[derive(Clone, Debug, PartialEq)]
pub struct TransformMsg {
    pub stamp_nanos: i64,
    pub parent: String,
    pub child: String,
    pub parent_from_child: Rigid,
}

/// A pose of `frame_id` in... the pose of a body in `frame_id` (odometry, PoseStamped, PoseInFrame).
#[derive(Clone, Debug, PartialEq)]
pub struct PoseMsg {
    pub stamp_nanos: i64,
    pub frame_id: String,
    pub child_frame_id: Option<String>,
    pub frame_from_body: Rigid,
}

#[derive(Clone, Debug, PartialEq)]
pub struct CameraInfoMsg {
    pub stamp_nanos: i64,
    pub frame_id: String,
    pub intrinsics: CameraIntrinsics,
}

/// Numeric type of a point field, in the ROS PointField numbering.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Numeric {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Numeric {
    /// ROS `sensor_msgs/PointField` datatype constant.
    pub fn from_ros(datatype: u8) -> Option<Self> {
        Some(match datatype {
            1 => Self::I8,
            2 => Self::U8,
            3 => Self::I16,
            4 => Self::U16,
            5 => Self::I32,
            6 => Self::U32,
            7 => Self::F32,
            8 => Self::F64,
            _ => return None,
        })
    }

    /// Foxglove `NumericType` enum value.
    pub fn from_foxglove(t: u32) -> Option<Self> {
        Some(match t {
            1 => Self::U8,
            2 => Self::I8,
            3 => Self::U16,
            4 => Self::I16,
            5 => Self::U32,
            6 => Self::I32,
            7 => Self::F32,
            8 => Self::F64,
            _ => return None,
        })
    }

    pub fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    pub fn is_integer(self) -> bool {
        !matches!(self, Self::F32 | Self::F64)
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct PointField {
    pub name: String,
    pub offset: u32,
    pub numeric: Numeric,
}

/// A point cloud as it arrives: layout plus a borrowed byte buffer.
#[derive(Clone, Debug)]
pub struct RawPointCloud<'a> {
    pub stamp_nanos: i64,
    pub frame_id: String,
    pub fields: Vec<PointField>,
    pub width: u32,
    pub height: u32,
    pub point_step: u32,
    pub row_step: u32,
    pub big_endian: bool,
    pub data: std::borrow::Cow<'a, [u8]>,
    /// Foxglove clouds carry an origin pose in `frame_id`; identity for ROS clouds.
    pub frame_from_cloud: Rigid,
}

/// An uncompressed image as it arrives.
#[derive(Clone, Debug)]
pub struct RawImage<'a> {
    pub stamp_nanos: i64,
    pub frame_id: String,
    pub width: u32,
    pub height: u32,
    pub encoding: String,
    pub big_endian: bool,
    pub step: u32,
    pub data: std::borrow::Cow<'a, [u8]>,
}

#[derive(Clone, Debug)]
pub struct CompressedImage<'a> {
    pub stamp_nanos: i64,
    pub frame_id: String,
    pub format: String,
    pub data: std::borrow::Cow<'a, [u8]>,
}

/// Any message this crate understands, decoded (large payloads borrowed).
#[derive(Clone, Debug)]
pub enum Decoded<'a> {
    Transforms(Vec<TransformMsg>),
    Pose(PoseMsg),
    Poses(Vec<PoseMsg>),
    CameraInfo(CameraInfoMsg),
    PointCloud(RawPointCloud<'a>),
    Image(RawImage<'a>),
    CompressedImage(CompressedImage<'a>),
}

impl Decoded<'_> {
    /// The header stamp and frame of sensor data, for indexing without keeping the payload.
    pub fn stamp_and_frame(&self) -> Option<(i64, &str)> {
        match self {
            Decoded::PointCloud(c) => Some((c.stamp_nanos, &c.frame_id)),
            Decoded::Image(i) => Some((i.stamp_nanos, &i.frame_id)),
            Decoded::CompressedImage(i) => Some((i.stamp_nanos, &i.frame_id)),
            Decoded::CameraInfo(c) => Some((c.stamp_nanos, &c.frame_id)),
            Decoded::Pose(p) => Some((p.stamp_nanos, &p.frame_id)),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_stamp_beyond_nanosecond_range_is_an_error_not_a_wrap() {
        assert_eq!(super::stamp_nanos(1, 5).unwrap(), 1_000_000_005);
        let e = super::stamp_nanos(i64::MAX / 10, 0).unwrap_err();
        assert!(e.0.contains("outside the range"), "{e:?}");
        assert!(super::stamp_nanos(i64::MIN, 0).is_err());
    }
}
