//! A ROS 2 MCAP writer for the simulator: files shaped like a real `ros2 bag record -s mcap`.
//!
//! How it works:
//!
//! - **Container.** [`mcap::Writer`] with its defaults (zstd-compressed chunks of about 1 MiB,
//!   message indexes, and a summary section with schemas, channels, statistics and chunk
//!   indexes), profile `ros2`. Output goes to a temporary file beside the target
//!   (`.<name>.tmp<pid>-<n>`); [`Ros2McapWriter::finish`] writes the summary, fsyncs and renames it
//!   into place, so the target is either absent or complete. Dropping the writer without
//!   `finish` deletes the temporary file.
//! - **Schemas.** Encoding `ros2msg`, named `pkg/msg/Type`, with the full definition as rosbag2
//!   stores it: the type's `.msg` text, then every dependency once (sorted, depth first), each
//!   after a line of 80 `=` and a `MSG: pkg/Type` line. The `.msg` files are the real ROS 2
//!   ones, embedded from `assets/ros2_msg/` so the library needs nothing at run time.
//! - **Channels.** Created lazily, one per topic (message encoding `cdr`), one schema per type.
//!   Each carries the `offered_qos_profiles` metadata the `ros2` profile asks for (reliable,
//!   volatile; transient-local for `/tf_static`, as `ros2 bag play` needs to latch it).
//! - **Messages.** Serialised by hand as little-endian CDR (XCDR1): the 4-byte encapsulation
//!   header `00 01 00 00`, then the fields in `.msg` order, each primitive aligned to its size
//!   counted from the end of that header; strings are a u32 length including the NUL, then the
//!   bytes and the NUL; sequences a u32 count then the elements. This mirrors the reader in
//!   `src/log/cdr.rs`. One scratch buffer is reused for every message and pre-sized, and point
//!   data is packed straight into it.
//! - **Times.** `log_time = publish_time = ` the header stamp (negative stamps clamp to 0 in the
//!   MCAP record; the header keeps them, as `sec = floor(t / 1 s)`, `nanosec = t mod 1 s`).

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Cursor, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use thiserror::Error;

use crate::geometry::Rigid;
use crate::geometry::camera::CameraIntrinsics;

/// An error of [`Ros2McapWriter`]; every message names the output file.
#[derive(Debug, Error)]
pub enum WriterError {
    #[error("{path}: {what}: {source}")]
    Io {
        path: PathBuf,
        what: String,
        source: std::io::Error,
    },
    #[error("{path}: MCAP writer failed: {source}")]
    Mcap {
        path: PathBuf,
        source: mcap::McapError,
    },
    #[error("{path}: {what}")]
    Invalid { path: PathBuf, what: String },
}

mod definitions;
use definitions::message_definition;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum MsgType {
    TfMessage,
    PointCloud2,
    CompressedImage,
    CameraInfo,
}

impl MsgType {
    fn schema_name(self) -> &'static str {
        match self {
            MsgType::TfMessage => "tf2_msgs/msg/TFMessage",
            MsgType::PointCloud2 => "sensor_msgs/msg/PointCloud2",
            MsgType::CompressedImage => "sensor_msgs/msg/CompressedImage",
            MsgType::CameraInfo => "sensor_msgs/msg/CameraInfo",
        }
    }
}

/// rosbag2's `offered_qos_profiles`, in the integer form rosbag2 writes on ROS 2 Humble: history 3
/// (unknown, what rosbag2 records for an offered profile), depth 0, reliability 1 (reliable),
/// durability 1 (transient local) or 2 (volatile), infinite deadline, lifespan and lease,
/// liveliness 1 (automatic).
fn offered_qos_profiles(transient_local: bool) -> String {
    const INFINITE: &str = "\n    sec: 9223372036\n    nsec: 854775807";
    format!(
        "- history: 3\n  depth: 0\n  reliability: 1\n  durability: {}\n  deadline:{INFINITE}\n  \
         lifespan:{INFINITE}\n  liveliness: 1\n  liveliness_lease_duration:{INFINITE}\n  \
         avoid_ros_namespace_conventions: false",
        if transient_local { 1 } else { 2 }
    )
}

// ------------------------------------------------------------------------------------------------
// CDR serialisation
// ------------------------------------------------------------------------------------------------

/// Little-endian CDR into a borrowed buffer; alignment counts from the end of the 4-byte
/// encapsulation header.
struct CdrWriter<'a> {
    buf: &'a mut Vec<u8>,
}

const CDR_HEADER: [u8; 4] = [0, 1, 0, 0];

impl<'a> CdrWriter<'a> {
    /// Clear `buf`, reserve `capacity` bytes of payload and write the encapsulation header.
    fn new(buf: &'a mut Vec<u8>, capacity: usize) -> Self {
        buf.clear();
        buf.reserve(capacity + CDR_HEADER.len() + 8);
        buf.extend_from_slice(&CDR_HEADER);
        Self { buf }
    }

    fn align(&mut self, n: usize) {
        let pos = self.buf.len() - CDR_HEADER.len();
        let pad = (n - pos % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    fn bool(&mut self, v: bool) {
        self.buf.push(v as u8);
    }
    fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn f64s(&mut self, v: &[f64]) {
        for x in v {
            self.f64(*x);
        }
    }
    /// A string: u32 length including the NUL, the bytes, the NUL.
    fn string(&mut self, s: &str) -> Result<(), String> {
        self.u32(len_u32(s.len() + 1, "string")?);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
        Ok(())
    }
    /// A `uint8[]`: u32 count, the bytes.
    fn bytes(&mut self, b: &[u8]) -> Result<(), String> {
        self.u32(len_u32(b.len(), "byte sequence")?);
        self.buf.extend_from_slice(b);
        Ok(())
    }
    /// `std_msgs/Header`: stamp (int32 sec, uint32 nanosec), frame_id.
    fn header(&mut self, stamp_nanos: i64, frame_id: &str) -> Result<(), String> {
        let (sec, nanosec) = ros_time(stamp_nanos)?;
        self.i32(sec);
        self.u32(nanosec);
        self.string(frame_id)
    }
}

fn len_u32(n: usize, what: &str) -> Result<u32, String> {
    u32::try_from(n).map_err(|_| format!("{what} of {n} bytes is too long for CDR"))
}

/// `builtin_interfaces/Time` of a stamp in nanoseconds.
fn ros_time(stamp_nanos: i64) -> Result<(i32, u32), String> {
    let sec = stamp_nanos.div_euclid(1_000_000_000);
    let nanosec = stamp_nanos.rem_euclid(1_000_000_000) as u32;
    let sec = i32::try_from(sec)
        .map_err(|_| format!("stamp {stamp_nanos} ns is outside the int32 seconds of ROS time"))?;
    Ok((sec, nanosec))
}

fn check_pose(t: &Rigid, what: &str) -> Result<(), String> {
    let norm = t.rotation.length();
    if !t.translation.is_finite() || !norm.is_finite() || !(0.5..2.0).contains(&norm) {
        return Err(format!(
            "{what}: invalid transform (translation {}, quaternion norm {norm})",
            t.translation
        ));
    }
    Ok(())
}

/// `geometry_msgs/TransformStamped`.
fn transform_stamped(
    w: &mut CdrWriter<'_>,
    stamp_nanos: i64,
    parent: &str,
    child: &str,
    t: &Rigid,
) -> Result<(), String> {
    check_pose(t, &format!("transform {parent} -> {child}"))?;
    w.header(stamp_nanos, parent)?;
    w.string(child)?;
    w.f64s(&t.translation.to_array());
    let q = t.rotation;
    w.f64s(&[q.x, q.y, q.z, q.w]);
    Ok(())
}

/// `sensor_msgs/PointField` datatype FLOAT32.
const FLOAT32: u8 = 7;
/// Fields of the clouds this writer produces: name and byte offset, all float32, count 1.
const CLOUD_FIELDS: [(&str, u32); 5] = [("x", 0), ("y", 4), ("z", 8), ("intensity", 12), ("t", 16)];
const POINT_STEP: usize = 20;

// ------------------------------------------------------------------------------------------------
// The writer
// ------------------------------------------------------------------------------------------------

struct ChannelState {
    id: u16,
    kind: MsgType,
    sequence: u32,
}

/// Where the MCAP's bytes go: a temporary file renamed into place, or memory.
enum Sink {
    File(BufWriter<File>),
    Memory(Cursor<Vec<u8>>),
}

impl Write for Sink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self {
            Sink::File(f) => f.write(buf),
            Sink::Memory(m) => m.write(buf),
        }
    }
    fn flush(&mut self) -> std::io::Result<()> {
        match self {
            Sink::File(f) => f.flush(),
            Sink::Memory(m) => m.flush(),
        }
    }
}

impl Seek for Sink {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        match self {
            Sink::File(f) => f.seek(pos),
            Sink::Memory(m) => m.seek(pos),
        }
    }
}

/// Writes a ROS 2 MCAP (see the module documentation).
pub struct Ros2McapWriter {
    /// The target file (a placeholder in error messages when writing to memory).
    path: PathBuf,
    /// The temporary file beside it (`None`: in memory).
    tmp_path: Option<PathBuf>,
    mcap: Option<mcap::Writer<Sink>>,
    schemas: HashMap<MsgType, u16>,
    channels: HashMap<String, ChannelState>,
    scratch: Vec<u8>,
}

impl std::fmt::Debug for Ros2McapWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros2McapWriter")
            .field("path", &self.path)
            .field("tmp_path", &self.tmp_path)
            .field("channels", &self.channels.len())
            .finish_non_exhaustive()
    }
}

/// Distinguishes temporary files of writers in one process.
static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

impl Ros2McapWriter {
    /// Writes to a temporary file beside `path`; `finish` renames it into place (atomic).
    pub fn create(path: &Path) -> Result<Self, WriterError> {
        let invalid = |what: &str| WriterError::Invalid {
            path: path.to_path_buf(),
            what: what.to_string(),
        };
        // Follow a link so it stays a link; a device or pipe cannot take a rename.
        let resolved = match crate::util::output_target(path) {
            Ok(crate::util::OutputTarget::Replace(p)) => p,
            Ok(crate::util::OutputTarget::Direct(_)) => {
                return Err(invalid(
                    "is not a regular file (a device or pipe); an MCAP is written beside its target and renamed into place",
                ));
            }
            Err(e) => return Err(invalid(&e.to_string())),
        };
        let path = resolved.as_path();
        let file_name = path
            .file_name()
            .ok_or_else(|| invalid("the output path has no file name"))?;
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(file_name);
        tmp_name.push(format!(
            ".tmp{}-{}",
            std::process::id(),
            TMP_COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let tmp_path = dir.join(tmp_name);
        let file = File::create(&tmp_path).map_err(|source| WriterError::Io {
            path: path.to_path_buf(),
            what: format!("cannot create the temporary file {}", tmp_path.display()),
            source,
        })?;
        let sink = Sink::File(BufWriter::with_capacity(1 << 20, file));
        let made = Self::over(sink, path.to_path_buf(), Some(tmp_path.clone()));
        if made.is_err() {
            let _ = std::fs::remove_file(&tmp_path);
        }
        made
    }

    /// Writes to memory; [`Ros2McapWriter::finish_bytes`] returns the file's bytes.
    pub fn in_memory() -> Result<Self, WriterError> {
        Self::over(
            Sink::Memory(Cursor::new(Vec::new())),
            PathBuf::from("<in memory>"),
            None,
        )
    }

    fn over(sink: Sink, path: PathBuf, tmp_path: Option<PathBuf>) -> Result<Self, WriterError> {
        let options = mcap::WriteOptions::new().profile("ros2").library(format!(
            "rigcal {} simulator ({})",
            env!("CARGO_PKG_VERSION"),
            mcap::LIBRARY_IDENTIFIER
        ));
        let mcap = options.create(sink).map_err(|source| WriterError::Mcap {
            path: path.clone(),
            source,
        })?;
        Ok(Self {
            path,
            tmp_path,
            mcap: Some(mcap),
            schemas: HashMap::new(),
            channels: HashMap::new(),
            scratch: Vec::new(),
        })
    }

    fn invalid(&self, what: impl Into<String>) -> WriterError {
        WriterError::Invalid {
            path: self.path.clone(),
            what: what.into(),
        }
    }

    fn mcap_error(&self, source: mcap::McapError) -> WriterError {
        WriterError::Mcap {
            path: self.path.clone(),
            source,
        }
    }

    /// The channel of `topic`, created (with its schema) on first use.
    fn channel(&mut self, topic: &str, kind: MsgType) -> Result<u16, WriterError> {
        if let Some(ch) = self.channels.get(topic) {
            return if ch.kind == kind {
                Ok(ch.id)
            } else {
                Err(self.invalid(format!(
                    "topic {topic} carries {}, cannot also write {}",
                    ch.kind.schema_name(),
                    kind.schema_name()
                )))
            };
        }
        let Some(mcap) = self.mcap.as_mut() else {
            return Err(self.invalid("the writer is already finished"));
        };
        let schema_id = match self.schemas.get(&kind) {
            Some(id) => *id,
            None => {
                let name = kind.schema_name();
                let Some(definition) = message_definition(name) else {
                    return Err(self.invalid(format!("no embedded definition for {name}")));
                };
                let id = mcap
                    .add_schema(name, "ros2msg", definition.as_bytes())
                    .map_err(|e| WriterError::Mcap {
                        path: self.path.clone(),
                        source: e,
                    })?;
                self.schemas.insert(kind, id);
                id
            }
        };
        let metadata = BTreeMap::from([(
            "offered_qos_profiles".to_string(),
            offered_qos_profiles(topic.trim_start_matches('/') == "tf_static"),
        )]);
        let id = mcap
            .add_channel(schema_id, topic, "cdr", &metadata)
            .map_err(|e| WriterError::Mcap {
                path: self.path.clone(),
                source: e,
            })?;
        self.channels.insert(
            topic.to_string(),
            ChannelState {
                id,
                kind,
                sequence: 0,
            },
        );
        Ok(id)
    }

    /// Serialise with `encode` into the scratch buffer and write it on `topic`.
    fn write_message(
        &mut self,
        topic: &str,
        kind: MsgType,
        stamp_nanos: i64,
        capacity: usize,
        encode: impl FnOnce(&mut CdrWriter<'_>) -> Result<(), String>,
    ) -> Result<(), WriterError> {
        let channel_id = self.channel(topic, kind)?;
        let mut scratch = std::mem::take(&mut self.scratch);
        let encoded = encode(&mut CdrWriter::new(&mut scratch, capacity));
        let result = match encoded {
            Err(what) => Err(self.invalid(format!("topic {topic}: {what}"))),
            Ok(()) => self.put(topic, channel_id, stamp_nanos, &scratch),
        };
        self.scratch = scratch;
        result
    }

    fn put(
        &mut self,
        topic: &str,
        channel_id: u16,
        stamp_nanos: i64,
        payload: &[u8],
    ) -> Result<(), WriterError> {
        let sequence = match self.channels.get_mut(topic) {
            Some(ch) => {
                ch.sequence = ch.sequence.wrapping_add(1);
                ch.sequence
            }
            None => 0,
        };
        let log_time = stamp_nanos.max(0) as u64;
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence,
            log_time,
            publish_time: log_time,
        };
        let Some(mcap) = self.mcap.as_mut() else {
            return Err(self.invalid("the writer is already finished"));
        };
        mcap.write_to_known_channel(&header, payload)
            .map_err(|e| self.mcap_error(e))
    }

    /// /tf_static, one TFMessage with all transforms (parent, child, parent_from_child), stamped `stamp_nanos`.
    pub fn write_tf_static(
        &mut self,
        stamp_nanos: i64,
        transforms: &[(String, String, Rigid)],
    ) -> Result<(), WriterError> {
        let capacity = 8 + transforms
            .iter()
            .map(|(p, c, _)| 96 + p.len() + c.len())
            .sum::<usize>();
        self.write_message(
            "/tf_static",
            MsgType::TfMessage,
            stamp_nanos,
            capacity,
            |w| {
                w.u32(len_u32(transforms.len(), "transform list")?);
                for (parent, child, t) in transforms {
                    transform_stamped(w, stamp_nanos, parent, child, t)?;
                }
                Ok(())
            },
        )
    }

    /// /tf, one TFMessage with one transform.
    pub fn write_tf(
        &mut self,
        stamp_nanos: i64,
        parent: &str,
        child: &str,
        parent_from_child: Rigid,
    ) -> Result<(), WriterError> {
        let capacity = 104 + parent.len() + child.len();
        self.write_message("/tf", MsgType::TfMessage, stamp_nanos, capacity, |w| {
            w.u32(1);
            transform_stamped(w, stamp_nanos, parent, child, &parent_from_child)
        })
    }

    /// sensor_msgs/PointCloud2 with fields x,y,z,intensity (float32) and t (float32 seconds relative to the header stamp); point_step 20, little-endian, height 1, is_dense true.
    ///
    /// `is_dense` is true unless a point has a non-finite coordinate. The three slices must have
    /// the same length.
    pub fn write_pointcloud(
        &mut self,
        topic: &str,
        stamp_nanos: i64,
        frame_id: &str,
        points: &[[f32; 3]],
        intensity: &[f32],
        time_offset_secs: &[f32],
    ) -> Result<(), WriterError> {
        let n = points.len();
        if intensity.len() != n || time_offset_secs.len() != n {
            return Err(self.invalid(format!(
                "topic {topic}: {n} points but {} intensities and {} time offsets",
                intensity.len(),
                time_offset_secs.len()
            )));
        }
        let data_len = n
            .checked_mul(POINT_STEP)
            .filter(|&l| u32::try_from(l).is_ok())
            .ok_or_else(|| self.invalid(format!("topic {topic}: {n} points are too many")))?;
        let capacity = 160 + frame_id.len() + data_len;
        self.write_message(topic, MsgType::PointCloud2, stamp_nanos, capacity, |w| {
            w.header(stamp_nanos, frame_id)?;
            w.u32(1); // height
            w.u32(len_u32(n, "point count")?); // width
            w.u32(CLOUD_FIELDS.len() as u32);
            for (name, offset) in CLOUD_FIELDS {
                w.string(name)?;
                w.u32(offset);
                w.u8(FLOAT32);
                w.u32(1); // count
            }
            w.bool(false); // is_bigendian
            w.u32(POINT_STEP as u32);
            w.u32(len_u32(data_len, "point data")?); // row_step
            w.u32(len_u32(data_len, "point data")?);
            let start = w.buf.len();
            w.buf.resize(start + data_len, 0);
            let mut dense = true;
            let records = w.buf[start..].chunks_exact_mut(POINT_STEP);
            for (((rec, p), i), t) in records.zip(points).zip(intensity).zip(time_offset_secs) {
                dense &= p[0].is_finite() & p[1].is_finite() & p[2].is_finite();
                rec[0..4].copy_from_slice(&p[0].to_le_bytes());
                rec[4..8].copy_from_slice(&p[1].to_le_bytes());
                rec[8..12].copy_from_slice(&p[2].to_le_bytes());
                rec[12..16].copy_from_slice(&i.to_le_bytes());
                rec[16..20].copy_from_slice(&t.to_le_bytes());
            }
            w.bool(dense);
            Ok(())
        })
    }

    /// sensor_msgs/CompressedImage, format "jpeg" (or "png"), data as given.
    pub fn write_compressed_image(
        &mut self,
        topic: &str,
        stamp_nanos: i64,
        frame_id: &str,
        format: &str,
        data: &[u8],
    ) -> Result<(), WriterError> {
        let capacity = 32 + frame_id.len() + format.len() + data.len();
        self.write_message(
            topic,
            MsgType::CompressedImage,
            stamp_nanos,
            capacity,
            |w| {
                w.header(stamp_nanos, frame_id)?;
                w.string(format)?;
                w.bytes(data)
            },
        )
    }

    /// sensor_msgs/CameraInfo from intrinsics: distortion_model = model.as_str() ("pinhole" written as "plumb_bob" with 5 zeros, as ROS drivers do), d, k, r = identity, p = [fx 0 cx 0; 0 fy cy 0; 0 0 1 0].
    ///
    /// `d` is padded with zeros to the model's length (5 plumb_bob, 8 rational_polynomial,
    /// 4 equidistant), never truncated; binning and ROI are zero (full resolution).
    pub fn write_camera_info(
        &mut self,
        topic: &str,
        stamp_nanos: i64,
        frame_id: &str,
        intrinsics: &CameraIntrinsics,
    ) -> Result<(), WriterError> {
        let c = intrinsics;
        let (model_name, d) = c.ros_distortion();
        let k = [c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0];
        let r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let p = [
            c.fx, 0.0, c.cx, 0.0, 0.0, c.fy, c.cy, 0.0, 0.0, 0.0, 1.0, 0.0,
        ];
        let capacity = 400 + frame_id.len() + 8 * d.len();
        self.write_message(topic, MsgType::CameraInfo, stamp_nanos, capacity, |w| {
            w.header(stamp_nanos, frame_id)?;
            w.u32(c.height);
            w.u32(c.width);
            w.string(model_name)?;
            w.u32(len_u32(d.len(), "distortion")?);
            w.f64s(&d);
            w.f64s(&k);
            w.f64s(&r);
            w.f64s(&p);
            w.u32(0); // binning_x
            w.u32(0); // binning_y
            for _ in 0..4 {
                w.u32(0); // roi x_offset, y_offset, height, width
            }
            w.bool(false); // roi.do_rectify
            Ok(())
        })
    }

    /// Finish the MCAP (summary, indexes): its sink.
    fn finish_sink(&mut self) -> Result<Sink, WriterError> {
        let Some(mut mcap) = self.mcap.take() else {
            return Err(self.invalid("the writer is already finished"));
        };
        mcap.finish().map_err(|e| self.mcap_error(e))?;
        Ok(mcap.into_inner())
    }

    /// Finish the MCAP (summary, indexes) and atomically move it into place.
    pub fn finish(mut self) -> Result<(), WriterError> {
        let Some(tmp_path) = self.tmp_path.clone() else {
            return Err(self.invalid("an in-memory writer ends with finish_bytes"));
        };
        let result = (|| {
            let Sink::File(file) = self.finish_sink()? else {
                return Err(self.invalid("a file writer without its file"));
            };
            let io = |what: &str, source| WriterError::Io {
                path: self.path.clone(),
                what: what.to_string(),
                source,
            };
            let file = file
                .into_inner()
                .map_err(|e| io("cannot flush", e.into_error()))?;
            file.sync_all().map_err(|e| io("cannot sync", e))?;
            drop(file);
            std::fs::rename(&tmp_path, &self.path).map_err(|e| {
                io(
                    &format!("cannot rename {} into place", tmp_path.display()),
                    e,
                )
            })?;
            // Make the rename itself durable where the platform allows it.
            if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty())
                && let Ok(d) = File::open(dir)
            {
                let _ = d.sync_all();
            }
            Ok(())
        })();
        if result.is_err() {
            let _ = std::fs::remove_file(&tmp_path);
        }
        self.tmp_path = None;
        result
    }

    /// Finish an in-memory MCAP and return its bytes.
    pub fn finish_bytes(mut self) -> Result<Vec<u8>, WriterError> {
        match self.finish_sink()? {
            Sink::Memory(bytes) => Ok(bytes.into_inner()),
            Sink::File(_) => Err(self.invalid("a file writer ends with finish")),
        }
    }
}

impl Drop for Ros2McapWriter {
    /// An unfinished writer leaves nothing behind: the temporary file is deleted and the target
    /// path is never created.
    fn drop(&mut self) {
        if let Some(mcap) = self.mcap.take() {
            // `into_inner` skips writing the summary that dropping an mcap::Writer would.
            let mut sink = mcap.into_inner();
            let _ = sink.flush();
            drop(sink);
        }
        if let Some(tmp) = &self.tmp_path {
            let _ = std::fs::remove_file(tmp);
        }
    }
}

#[cfg(test)]
mod tests;
