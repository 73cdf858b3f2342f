//! Decoders for Foxglove's schemas, in both protobuf and JSON encodings: PointCloud,
//! CompressedImage, RawImage, CameraCalibration, FrameTransform, FrameTransforms, PoseInFrame,
//! PosesInFrame.
//!
//! Protobuf field numbers are those of the published `foxglove/*.proto` files; JSON field names
//! those of the published JSON schemas (`data` is base64).

use serde_json::Value as Json;

use super::error::{DecodeError, DecodeResult};
use super::protobuf::{self as pb, Value};
use super::types::*;
use crate::geometry::Rigid;
use crate::geometry::camera::CameraIntrinsics;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FoxgloveType {
    PointCloud,
    CompressedImage,
    RawImage,
    CameraCalibration,
    FrameTransform,
    FrameTransforms,
    PoseInFrame,
    PosesInFrame,
}

impl FoxgloveType {
    pub fn from_schema(name: &str) -> Option<Self> {
        Some(
            match name
                .trim_start_matches("foxglove.")
                .trim_start_matches("foxglove_msgs/msg/")
            {
                "PointCloud" => Self::PointCloud,
                "CompressedImage" => Self::CompressedImage,
                "RawImage" => Self::RawImage,
                "CameraCalibration" => Self::CameraCalibration,
                "FrameTransform" => Self::FrameTransform,
                "FrameTransforms" => Self::FrameTransforms,
                "PoseInFrame" => Self::PoseInFrame,
                "PosesInFrame" => Self::PosesInFrame,
                _ => return None,
            },
        )
    }
}

// ---------- protobuf ----------

fn pb_msg(v: Option<Value<'_>>) -> DecodeResult<Vec<(u32, Value<'_>)>> {
    match v {
        Some(v) => pb::fields(v.as_bytes()),
        None => Ok(Vec::new()),
    }
}

fn pb_stamp(f: &[(u32, Value<'_>)], n: u32) -> DecodeResult<i64> {
    // google.protobuf.Timestamp { int64 seconds = 1; int32 nanos = 2; }
    let t = pb_msg(pb::get(f, n))?;
    let sec = pb::get(&t, 1).map_or(0, |v| v.as_u64() as i64);
    let nsec = pb::get(&t, 2).map_or(0, |v| v.as_u64() as u32);
    stamp_nanos(sec, nsec)
}

fn pb_vec3(f: &[(u32, Value<'_>)], n: u32) -> DecodeResult<[f64; 3]> {
    let v = pb_msg(pb::get(f, n))?;
    let c = |i| pb::get(&v, i).map_or(0.0, |x: Value<'_>| x.as_f64());
    Ok([c(1), c(2), c(3)])
}

fn pb_quat(f: &[(u32, Value<'_>)], n: u32) -> DecodeResult<[f64; 4]> {
    let v = pb_msg(pb::get(f, n))?;
    if v.is_empty() {
        return Ok([0.0, 0.0, 0.0, 1.0]);
    }
    let c = |i| pb::get(&v, i).map_or(0.0, |x: Value<'_>| x.as_f64());
    Ok([c(1), c(2), c(3), c(4)])
}

fn pb_pose(f: &[(u32, Value<'_>)], n: u32) -> DecodeResult<Rigid> {
    let p = pb_msg(pb::get(f, n))?;
    if p.is_empty() {
        return Ok(Rigid::IDENTITY);
    }
    super::ros2::rigid_from(pb_vec3(&p, 1)?, pb_quat(&p, 2)?, "pose")
}

fn pb_str(f: &[(u32, Value<'_>)], n: u32) -> String {
    pb::get(f, n).map(|v| v.as_string()).unwrap_or_default()
}

fn pb_u32(f: &[(u32, Value<'_>)], n: u32) -> u32 {
    pb::get(f, n).map_or(0, |v| v.as_u64() as u32)
}

fn pb_transform(f: &[(u32, Value<'_>)]) -> DecodeResult<TransformMsg> {
    Ok(TransformMsg {
        stamp_nanos: pb_stamp(f, 1)?,
        parent: pb_str(f, 2),
        child: pb_str(f, 3),
        parent_from_child: super::ros2::rigid_from(pb_vec3(f, 4)?, pb_quat(f, 5)?, "transform")?,
    })
}

fn calibration(
    stamp: i64,
    frame_id: String,
    width: u32,
    height: u32,
    model: &str,
    d: Vec<f64>,
    k: &[f64],
) -> DecodeResult<Decoded<'static>> {
    let intrinsics = CameraIntrinsics::from_camera_info(width, height, model, d, k)
        .map_err(|e| DecodeError::new(e.to_string()))?;
    Ok(Decoded::CameraInfo(CameraInfoMsg {
        stamp_nanos: stamp,
        frame_id,
        intrinsics,
    }))
}

pub fn decode_protobuf(kind: FoxgloveType, payload: &[u8]) -> DecodeResult<Decoded<'_>> {
    let f = pb::fields(payload)?;
    Ok(match kind {
        FoxgloveType::PointCloud => {
            let mut fields = Vec::new();
            for v in pb::all(&f, 5) {
                let e = pb::fields(v.as_bytes())?;
                if let Some(numeric) = Numeric::from_foxglove(pb_u32(&e, 3)) {
                    fields.push(PointField {
                        name: pb_str(&e, 1),
                        offset: pb_u32(&e, 2),
                        numeric,
                    });
                }
            }
            let data = pb::get(&f, 6).map(|v| v.as_bytes()).unwrap_or_default();
            let stride = pb_u32(&f, 4);
            let width = if stride == 0 {
                0
            } else {
                (data.len() / stride as usize) as u32
            };
            Decoded::PointCloud(RawPointCloud {
                stamp_nanos: pb_stamp(&f, 1)?,
                frame_id: pb_str(&f, 2),
                fields,
                width,
                height: 1,
                point_step: stride,
                row_step: 0,
                big_endian: false,
                data: data.into(),
                frame_from_cloud: pb_pose(&f, 3)?,
            })
        }
        FoxgloveType::CompressedImage => Decoded::CompressedImage(CompressedImage {
            stamp_nanos: pb_stamp(&f, 1)?,
            frame_id: pb_str(&f, 4),
            format: pb_str(&f, 3),
            data: pb::get(&f, 2)
                .map(|v| v.as_bytes())
                .unwrap_or_default()
                .into(),
        }),
        FoxgloveType::RawImage => Decoded::Image(RawImage {
            stamp_nanos: pb_stamp(&f, 1)?,
            frame_id: pb_str(&f, 7),
            width: pb_u32(&f, 2),
            height: pb_u32(&f, 3),
            encoding: pb_str(&f, 4),
            big_endian: false,
            step: pb_u32(&f, 5),
            data: pb::get(&f, 6)
                .map(|v| v.as_bytes())
                .unwrap_or_default()
                .into(),
        }),
        FoxgloveType::CameraCalibration => {
            let d: Vec<f64> = pb::all(&f, 5).flat_map(|v| v.as_f64s()).collect();
            let k: Vec<f64> = pb::all(&f, 6).flat_map(|v| v.as_f64s()).collect();
            calibration(
                pb_stamp(&f, 1)?,
                pb_str(&f, 9),
                pb_u32(&f, 2),
                pb_u32(&f, 3),
                &pb_str(&f, 4),
                d,
                &k,
            )?
        }
        FoxgloveType::FrameTransform => Decoded::Transforms(vec![pb_transform(&f)?]),
        FoxgloveType::FrameTransforms => {
            let mut out = Vec::new();
            for v in pb::all(&f, 1) {
                out.push(pb_transform(&pb::fields(v.as_bytes())?)?);
            }
            Decoded::Transforms(out)
        }
        FoxgloveType::PoseInFrame => Decoded::Pose(PoseMsg {
            stamp_nanos: pb_stamp(&f, 1)?,
            frame_id: pb_str(&f, 2),
            child_frame_id: None,
            frame_from_body: pb_pose(&f, 3)?,
        }),
        FoxgloveType::PosesInFrame => {
            let stamp = pb_stamp(&f, 1)?;
            let frame_id = pb_str(&f, 2);
            let mut out = Vec::new();
            for v in pb::all(&f, 3) {
                let p = pb::fields(v.as_bytes())?;
                let pose = super::ros2::rigid_from(pb_vec3(&p, 1)?, pb_quat(&p, 2)?, "poses")?;
                out.push(PoseMsg {
                    stamp_nanos: stamp,
                    frame_id: frame_id.clone(),
                    child_frame_id: None,
                    frame_from_body: pose,
                });
            }
            Decoded::Poses(out)
        }
    })
}

// ---------- JSON ----------

fn j_stamp(v: &Json) -> DecodeResult<i64> {
    let t = &v["timestamp"];
    stamp_nanos(
        t["sec"].as_i64().unwrap_or(0),
        t["nsec"].as_u64().unwrap_or(0) as u32,
    )
}

fn j_f64(v: &Json) -> f64 {
    v.as_f64().unwrap_or(0.0)
}

fn j_pose(v: &Json) -> DecodeResult<Rigid> {
    if v.is_null() {
        return Ok(Rigid::IDENTITY);
    }
    let p = &v["position"];
    let q = &v["orientation"];
    let quat = if q.is_null() {
        [0.0, 0.0, 0.0, 1.0]
    } else {
        [
            j_f64(&q["x"]),
            j_f64(&q["y"]),
            j_f64(&q["z"]),
            j_f64(&q["w"]),
        ]
    };
    super::ros2::rigid_from(
        [j_f64(&p["x"]), j_f64(&p["y"]), j_f64(&p["z"])],
        quat,
        "pose",
    )
}

fn j_str(v: &Json) -> String {
    v.as_str().unwrap_or_default().to_string()
}

fn j_u32(v: &Json) -> u32 {
    v.as_u64().unwrap_or(0) as u32
}

fn j_f64s(v: &Json) -> Vec<f64> {
    v.as_array()
        .map(|a| a.iter().map(j_f64).collect())
        .unwrap_or_default()
}

fn j_data(v: &Json) -> DecodeResult<Vec<u8>> {
    match v {
        Json::String(s) => base64_decode(s),
        Json::Array(a) => Ok(a.iter().map(|x| x.as_u64().unwrap_or(0) as u8).collect()),
        Json::Null => Ok(Vec::new()),
        _ => Err(DecodeError::new("data is neither base64 nor a byte array")),
    }
}

fn j_transform(v: &Json) -> DecodeResult<TransformMsg> {
    let t = &v["translation"];
    let q = &v["rotation"];
    Ok(TransformMsg {
        stamp_nanos: j_stamp(v)?,
        parent: j_str(&v["parent_frame_id"]),
        child: j_str(&v["child_frame_id"]),
        parent_from_child: super::ros2::rigid_from(
            [j_f64(&t["x"]), j_f64(&t["y"]), j_f64(&t["z"])],
            [
                j_f64(&q["x"]),
                j_f64(&q["y"]),
                j_f64(&q["z"]),
                j_f64(&q["w"]),
            ],
            "transform",
        )?,
    })
}

pub fn decode_json(kind: FoxgloveType, payload: &[u8]) -> DecodeResult<Decoded<'static>> {
    let v: Json = serde_json::from_slice(payload)
        .map_err(|e| DecodeError::new(format!("invalid JSON: {e}")))?;
    Ok(match kind {
        FoxgloveType::PointCloud => {
            let mut fields = Vec::new();
            for e in v["fields"].as_array().into_iter().flatten() {
                if let Some(numeric) = Numeric::from_foxglove(j_u32(&e["type"])) {
                    fields.push(PointField {
                        name: j_str(&e["name"]),
                        offset: j_u32(&e["offset"]),
                        numeric,
                    });
                }
            }
            let data = j_data(&v["data"])?;
            let stride = j_u32(&v["point_stride"]);
            let width = if stride == 0 {
                0
            } else {
                (data.len() / stride as usize) as u32
            };
            Decoded::PointCloud(RawPointCloud {
                stamp_nanos: j_stamp(&v)?,
                frame_id: j_str(&v["frame_id"]),
                fields,
                width,
                height: 1,
                point_step: stride,
                row_step: 0,
                big_endian: false,
                data: data.into(),
                frame_from_cloud: j_pose(&v["pose"])?,
            })
        }
        FoxgloveType::CompressedImage => Decoded::CompressedImage(CompressedImage {
            stamp_nanos: j_stamp(&v)?,
            frame_id: j_str(&v["frame_id"]),
            format: j_str(&v["format"]),
            data: j_data(&v["data"])?.into(),
        }),
        FoxgloveType::RawImage => Decoded::Image(RawImage {
            stamp_nanos: j_stamp(&v)?,
            frame_id: j_str(&v["frame_id"]),
            width: j_u32(&v["width"]),
            height: j_u32(&v["height"]),
            encoding: j_str(&v["encoding"]),
            big_endian: false,
            step: j_u32(&v["step"]),
            data: j_data(&v["data"])?.into(),
        }),
        FoxgloveType::CameraCalibration => calibration(
            j_stamp(&v)?,
            j_str(&v["frame_id"]),
            j_u32(&v["width"]),
            j_u32(&v["height"]),
            &j_str(&v["distortion_model"]),
            j_f64s(&v["D"]),
            &j_f64s(&v["K"]),
        )?,
        FoxgloveType::FrameTransform => Decoded::Transforms(vec![j_transform(&v)?]),
        FoxgloveType::FrameTransforms => Decoded::Transforms(
            v["transforms"]
                .as_array()
                .into_iter()
                .flatten()
                .map(j_transform)
                .collect::<DecodeResult<_>>()?,
        ),
        FoxgloveType::PoseInFrame => Decoded::Pose(PoseMsg {
            stamp_nanos: j_stamp(&v)?,
            frame_id: j_str(&v["frame_id"]),
            child_frame_id: None,
            frame_from_body: j_pose(&v["pose"])?,
        }),
        FoxgloveType::PosesInFrame => {
            let stamp = j_stamp(&v)?;
            let frame_id = j_str(&v["frame_id"]);
            Decoded::Poses(
                v["poses"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .map(|p| {
                        Ok(PoseMsg {
                            stamp_nanos: stamp,
                            frame_id: frame_id.clone(),
                            child_frame_id: None,
                            frame_from_body: j_pose(p)?,
                        })
                    })
                    .collect::<DecodeResult<_>>()?,
            )
        }
    })
}

/// Standard base64 (with or without padding).
pub fn base64_decode(s: &str) -> DecodeResult<Vec<u8>> {
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let mut acc = 0u32;
    let mut bits = 0u32;
    for c in s.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' | b'\n' | b'\r' | b' ' => continue,
            _ => {
                return Err(DecodeError::new(format!(
                    "invalid base64 character '{}'",
                    c as char
                )));
            }
        } as u32;
        acc = (acc << 6) | v;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_known_values() {
        assert_eq!(base64_decode("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64_decode("aGVsbG8").unwrap(), b"hello");
        assert!(base64_decode("a$").is_err());
    }
}
