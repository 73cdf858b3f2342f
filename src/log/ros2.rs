//! Decoders for the ROS 2 messages rigcal reads, from CDR payloads.
//!
//! Schema names are matched with or without the `/msg/` part (`sensor_msgs/msg/Image` and
//! `sensor_msgs/Image`). Field order follows the `.msg` definitions exactly; a payload that is
//! shorter than its definition is a [`DecodeError`] naming the field.

use glam::{DQuat, DVec3};

use super::cdr::CdrReader;
use super::error::{DecodeError, DecodeResult};
use super::types::*;
use crate::geometry::Rigid;
use crate::geometry::camera::CameraIntrinsics;

/// The message types this module decodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ros2Type {
    PointCloud2,
    Image,
    CompressedImage,
    CameraInfo,
    TfMessage,
    Odometry,
    PoseStamped,
}

impl Ros2Type {
    /// Every type rigcal reads.
    pub const ALL: [Ros2Type; 7] = [
        Ros2Type::PointCloud2,
        Ros2Type::Image,
        Ros2Type::CompressedImage,
        Ros2Type::CameraInfo,
        Ros2Type::TfMessage,
        Ros2Type::Odometry,
        Ros2Type::PoseStamped,
    ];

    pub fn from_schema(name: &str) -> Option<Self> {
        Some(match name.replace("/msg/", "/").as_str() {
            "sensor_msgs/PointCloud2" => Self::PointCloud2,
            "sensor_msgs/Image" => Self::Image,
            "sensor_msgs/CompressedImage" => Self::CompressedImage,
            "sensor_msgs/CameraInfo" => Self::CameraInfo,
            "tf2_msgs/TFMessage" => Self::TfMessage,
            "nav_msgs/Odometry" => Self::Odometry,
            "geometry_msgs/PoseStamped" => Self::PoseStamped,
            _ => return None,
        })
    }
}

struct Header {
    stamp_nanos: i64,
    frame_id: String,
}

fn header(r: &mut CdrReader<'_>) -> DecodeResult<Header> {
    let sec = r.i32("header.stamp.sec")?;
    let nsec = r.u32("header.stamp.nanosec")?;
    let frame_id = r.string("header.frame_id")?;
    Ok(Header {
        stamp_nanos: stamp_nanos(sec as i64, nsec)?,
        frame_id,
    })
}

fn pose(r: &mut CdrReader<'_>, what: &str) -> DecodeResult<Rigid> {
    let p = r.f64_array::<3>(what)?;
    let q = r.f64_array::<4>(what)?;
    rigid_from(p, q, what)
}

/// The longest translation a pose in a message may have (m): Earth-centred and UTM coordinates
/// are below 1e7 m, so anything longer is a corrupt value, not a place.
pub const MAX_TRANSLATION_M: f64 = 1e8;

/// A rigid transform from a translation and an (x, y, z, w) quaternion read from a message.
pub fn rigid_from(p: [f64; 3], q: [f64; 4], what: &str) -> DecodeResult<Rigid> {
    let quat = DQuat::from_xyzw(q[0], q[1], q[2], q[3]);
    let norm = quat.length();
    if !p.iter().all(|v| v.is_finite()) {
        return Err(DecodeError::new(format!(
            "{what}: invalid pose (translation {p:?} is not finite)"
        )));
    }
    let length_m = DVec3::from_array(p).length();
    if length_m > MAX_TRANSLATION_M {
        return Err(DecodeError::new(format!(
            "{what}: invalid pose (translation of {length_m:.3e} m, beyond any map frame's {MAX_TRANSLATION_M:.0e} m)"
        )));
    }
    if !norm.is_finite() || !(0.5..2.0).contains(&norm) {
        return Err(DecodeError::new(format!(
            "{what}: invalid pose (quaternion norm {norm})"
        )));
    }
    Ok(Rigid::new(quat / norm, DVec3::from_array(p)))
}

/// Decode a CDR payload of a known type.
pub fn decode(kind: Ros2Type, payload: &[u8]) -> DecodeResult<Decoded<'_>> {
    let mut r = CdrReader::new(payload)?;
    Ok(match kind {
        Ros2Type::TfMessage => {
            // A TransformStamped holds at least a header (a stamp of 8 bytes and a frame id of
            // 5), a child frame id (5) and seven f64 (56).
            let n = r.seq_len_of("transforms", 74)?;
            let mut out = Vec::with_capacity(n);
            for _ in 0..n {
                let h = header(&mut r)?;
                let child = r.string("child_frame_id")?;
                let t = pose(&mut r, "transform")?;
                out.push(TransformMsg {
                    stamp_nanos: h.stamp_nanos,
                    parent: h.frame_id,
                    child,
                    parent_from_child: t,
                });
            }
            Decoded::Transforms(out)
        }
        Ros2Type::Odometry => {
            let h = header(&mut r)?;
            let child = r.string("child_frame_id")?;
            let p = pose(&mut r, "pose.pose")?;
            Decoded::Pose(PoseMsg {
                stamp_nanos: h.stamp_nanos,
                frame_id: h.frame_id,
                child_frame_id: Some(child),
                frame_from_body: p,
            })
        }
        Ros2Type::PoseStamped => {
            let h = header(&mut r)?;
            let p = pose(&mut r, "pose")?;
            Decoded::Pose(PoseMsg {
                stamp_nanos: h.stamp_nanos,
                frame_id: h.frame_id,
                child_frame_id: None,
                frame_from_body: p,
            })
        }
        Ros2Type::CameraInfo => {
            let h = header(&mut r)?;
            let height = r.u32("height")?;
            let width = r.u32("width")?;
            let model_name = r.string("distortion_model")?;
            let d = r.f64_seq("d")?;
            let k = r.f64_array::<9>("k")?;
            let intrinsics = CameraIntrinsics::from_camera_info(width, height, &model_name, d, &k)
                .map_err(|e| DecodeError::new(e.to_string()))?;
            Decoded::CameraInfo(CameraInfoMsg {
                stamp_nanos: h.stamp_nanos,
                frame_id: h.frame_id,
                intrinsics,
            })
        }
        Ros2Type::PointCloud2 => {
            let h = header(&mut r)?;
            let height = r.u32("height")?;
            let width = r.u32("width")?;
            // A PointField holds at least a name (5 bytes), an offset, a type and a count (9).
            let n = r.seq_len_of("fields", 14)?;
            let mut fields = Vec::with_capacity(n);
            for _ in 0..n {
                let name = r.string("fields.name")?;
                let offset = r.u32("fields.offset")?;
                let datatype = r.u8("fields.datatype")?;
                let _count = r.u32("fields.count")?;
                if let Some(numeric) = Numeric::from_ros(datatype) {
                    fields.push(PointField {
                        name,
                        offset,
                        numeric,
                    });
                }
            }
            let big_endian = r.bool("is_bigendian")?;
            let point_step = r.u32("point_step")?;
            let row_step = r.u32("row_step")?;
            let data = r.bytes("data")?;
            Decoded::PointCloud(RawPointCloud {
                stamp_nanos: h.stamp_nanos,
                frame_id: h.frame_id,
                fields,
                width,
                height,
                point_step,
                row_step,
                big_endian,
                data: data.into(),
                frame_from_cloud: Rigid::IDENTITY,
            })
        }
        Ros2Type::Image => {
            let h = header(&mut r)?;
            let height = r.u32("height")?;
            let width = r.u32("width")?;
            let encoding = r.string("encoding")?;
            let big_endian = r.u8("is_bigendian")? != 0;
            let step = r.u32("step")?;
            let data = r.bytes("data")?;
            Decoded::Image(RawImage {
                stamp_nanos: h.stamp_nanos,
                frame_id: h.frame_id,
                width,
                height,
                encoding,
                big_endian,
                step,
                data: data.into(),
            })
        }
        Ros2Type::CompressedImage => {
            let h = header(&mut r)?;
            let format = r.string("format")?;
            let data = r.bytes("data")?;
            Decoded::CompressedImage(CompressedImage {
                stamp_nanos: h.stamp_nanos,
                frame_id: h.frame_id,
                format,
                data: data.into(),
            })
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_pose_is_refused_naming_what_is_wrong() {
        let unit = [0.0, 0.0, 0.0, 1.0];
        assert!(rigid_from([1.0, 2.0, 3.0], unit, "pose").is_ok());
        let e = rigid_from([f64::NAN, 0.0, 0.0], unit, "pose")
            .unwrap_err()
            .to_string();
        assert!(e.contains("not finite"), "{e}");
        let e = rigid_from([1e300, 0.0, 0.0], unit, "pose")
            .unwrap_err()
            .to_string();
        assert!(e.contains("beyond any map frame"), "{e}");
        // Earth-centred coordinates are places, not corruption.
        assert!(rigid_from([-2.7e6, -4.3e6, 3.9e6], unit, "pose").is_ok());
        let e = rigid_from([0.0; 3], [0.0; 4], "pose")
            .unwrap_err()
            .to_string();
        assert!(e.contains("quaternion norm"), "{e}");
    }
}
