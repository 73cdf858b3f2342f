//! [`Drive`]: an opened recording — topics, TF tree, trajectory, the initial rig, and per-sensor
//! indexes of sweeps and images that decode on demand.
//!
//! Opening scans every message once (chunks in parallel) but keeps only small things: decoded
//! transforms, poses and camera infos, plus a header stamp and a [`MessageRef`] per sweep or
//! image. Header stamps are the sensor time; a topic whose stamps are all zero falls back to log
//! time, and [`SensorStream::stamp_source`] says which was used.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::{Arc, Mutex};

use image::RgbImage;

use super::byte_lru::ByteLru;
use super::container::{McapContainer, MessageRef};
use super::decode::Codec;
use super::error::{LogError, Problem, Problems};
use super::pointcloud::{self, LidarSweep};
use super::tf::{TfTree, normalize_frame};
use super::types::{CameraInfoMsg, Decoded, PoseMsg, TransformMsg};
use crate::calib::file::exportable_name;
use crate::calib::{Rig, Sensor, SensorKind};
use crate::geometry::camera::CameraIntrinsics;
use crate::geometry::{Rigid, RowTimes, StampConflict, Trajectory, conflicting_stamps};

/// Faster than any vehicle: a trajectory pose that implies it towards most of its nearest poses
/// is dropped ([`Trajectory::remove_jumps`]).
const MAX_VEHICLE_SPEED_MPS: f64 = 100.0;

/// One problem for the stamps of `source` that carry poses which disagree: how many, and the
/// worst.
fn stamp_conflicts(source: &str, conflicts: &[StampConflict]) -> Problem {
    let worst = conflicts
        .iter()
        .max_by(|a, b| a.translation_m.total_cmp(&b.translation_m))
        .copied();
    let worst = worst.map_or(String::new(), |w| {
        format!(
            " (the worst at {:.3} s: {:.3} m and {:.3}° apart)",
            w.stamp_nanos as f64 * 1e-9,
            w.translation_m,
            w.rotation_rad.to_degrees()
        )
    });
    Problem::file(format!(
        "{source}: {} stamp(s) carry poses that disagree{worst}; the last one in the log is used",
        conflicts.len()
    ))
}

/// Decoded images a [`Drive`] keeps by default: about ten full-HD images (the eight frames a
/// camera's checks read twice fit), forty-five of KITTI's.
pub const DEFAULT_IMAGE_CACHE_BYTES: usize = 64 << 20;

#[derive(Clone, Debug)]
pub struct DriveOptions {
    /// Fixed frame of the trajectory (e.g. world, odom, map); default: parent of the densest
    /// dynamic TF edge.
    pub fixed_frame: Option<String>,
    /// The vehicle frame every extrinsic maps into; default: child of that edge.
    pub vehicle_frame: Option<String>,
    /// How far (s) a query may extrapolate past either end of the trajectory.
    pub max_extrapolation_secs: f64,
    /// Bytes of decoded images kept in memory (the last image decoded is kept whatever its
    /// size): a bound in bytes, not images, so that a log of full-HD cameras does not hold
    /// six times what one of KITTI's does.
    pub image_cache_bytes: usize,
    /// Added to every camera image's stamp: a known delay between the cameras' clock (or
    /// trigger) and the trajectory's (negative: the images were taken before their stamps).
    pub camera_time_offset_nanos: i64,
    /// When the cameras' first and last image rows were exposed relative to each image's
    /// (offset) stamp: a rolling shutter's readout ([`Drive::camera_readout`]).
    pub camera_readout: RowTimes,
}

impl Default for DriveOptions {
    fn default() -> Self {
        Self {
            fixed_frame: None,
            vehicle_frame: None,
            max_extrapolation_secs: 0.1,
            image_cache_bytes: DEFAULT_IMAGE_CACHE_BYTES,
            camera_time_offset_nanos: 0,
            camera_readout: RowTimes::GLOBAL,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StampSource {
    /// The message header's stamp (sensor time).
    Header,
    /// The MCAP log time: the header stamps were missing (zero).
    LogTime,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameRef {
    pub stamp_nanos: i64,
    pub msg: MessageRef,
}

/// The sweeps or images of one sensor, sorted by stamp.
#[derive(Clone, Debug)]
pub struct SensorStream {
    pub sensor: String,
    pub kind: SensorKind,
    pub topic: String,
    pub codec: Codec,
    pub stamp_source: StampSource,
    pub frames: Vec<FrameRef>,
}

/// Per-topic counts for `inspect`.
#[derive(Clone, Debug, PartialEq)]
pub struct TopicStats {
    pub topic: String,
    pub schema_name: String,
    pub message_encoding: String,
    pub count: u64,
    pub first_log_time_nanos: u64,
    pub last_log_time_nanos: u64,
    /// Whether rigcal decodes this schema.
    pub understood: bool,
    pub failed: u64,
}

impl TopicStats {
    pub fn rate_hz(&self) -> f64 {
        let span = (self
            .last_log_time_nanos
            .saturating_sub(self.first_log_time_nanos)) as f64
            * 1e-9;
        if self.count > 1 && span > 0.0 {
            (self.count - 1) as f64 / span
        } else {
            0.0
        }
    }
}

/// What the scan keeps of one message.
enum Kept {
    Transforms {
        msgs: Vec<TransformMsg>,
        is_static: bool,
    },
    Poses(Vec<PoseMsg>),
    CameraInfo(CameraInfoMsg),
    Sensor {
        stamp_nanos: i64,
        frame_id: String,
    },
    Ignored,
    Failed(String),
}

pub struct Drive {
    container: Arc<McapContainer>,
    pub topics: Vec<TopicStats>,
    pub tf: TfTree,
    pub fixed_frame: Option<String>,
    pub trajectory: Trajectory,
    /// Where the trajectory came from, e.g. "/tf: world → pandar64".
    pub trajectory_source: String,
    /// The initial rig: extrinsics from the static TF tree, intrinsics from camera info.
    pub rig: Rig,
    /// Intrinsics of every camera info in the log by (normalised) frame id, whether or not
    /// images of that frame are in it.
    pub camera_infos: BTreeMap<String, CameraIntrinsics>,
    pub streams: Vec<SensorStream>,
    pub problems: Problems,
    /// Decoded images by (stream, frame index), bounded by [`DriveOptions::image_cache_bytes`].
    image_cache: Arc<Mutex<ByteLru<(usize, usize), RgbImage>>>,
    /// The frames runs skipped because they did not decode ([`super::frames`]).
    pub(super) skipped_frames: Arc<super::frames::SkippedFrames>,
    /// When each image row of the cameras was exposed relative to the image's stamp (a
    /// rolling shutter; [`RowTimes::GLOBAL`] unless the user gave a readout).
    pub camera_readout: RowTimes,
}

impl std::fmt::Debug for Drive {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Drive")
            .field("path", &self.container.path())
            .field("streams", &self.streams.len())
            .finish_non_exhaustive()
    }
}

impl Drive {
    pub fn open(path: &Path) -> Result<Self, LogError> {
        Self::open_with(path, &DriveOptions::default())
    }

    pub fn open_with(path: &Path, options: &DriveOptions) -> Result<Self, LogError> {
        let container = McapContainer::open(path)?;
        let codecs: BTreeMap<u16, Option<Codec>> = container
            .channels
            .iter()
            .map(|(id, ch)| (*id, Codec::for_channel(ch)))
            .collect();
        let (kept, scan_problems) = container.scan(|r, ch, payload| {
            let Some(codec) = codecs.get(&r.channel_id).copied().flatten() else {
                return Some(Kept::Ignored);
            };
            Some(match codec.decode(payload) {
                Err(e) => Kept::Failed(e.0),
                Ok(Decoded::Transforms(msgs)) => Kept::Transforms {
                    msgs,
                    is_static: ch.topic.ends_with("tf_static"),
                },
                Ok(Decoded::Pose(p)) => Kept::Poses(vec![p]),
                Ok(Decoded::Poses(p)) => Kept::Poses(p),
                Ok(Decoded::CameraInfo(c)) => Kept::CameraInfo(c),
                Ok(d) => match d.stamp_and_frame() {
                    Some((stamp_nanos, frame)) => Kept::Sensor {
                        stamp_nanos,
                        frame_id: normalize_frame(frame),
                    },
                    None => Kept::Ignored,
                },
            })
        });
        let mut problems = container.problems.clone();
        problems.append(scan_problems);

        // Topic statistics.
        let mut topics: BTreeMap<u16, TopicStats> = container
            .channels
            .iter()
            .map(|(id, ch)| {
                (
                    *id,
                    TopicStats {
                        topic: ch.topic.clone(),
                        schema_name: ch.schema_name.clone(),
                        message_encoding: ch.message_encoding.clone(),
                        count: 0,
                        first_log_time_nanos: u64::MAX,
                        last_log_time_nanos: 0,
                        understood: codecs.get(id).copied().flatten().is_some(),
                        failed: 0,
                    },
                )
            })
            .collect();

        let mut tf = TfTree::default();
        let mut poses_by_topic: BTreeMap<String, Vec<PoseMsg>> = BTreeMap::new();
        let mut camera_infos: BTreeMap<String, (String, CameraInfoMsg)> = BTreeMap::new();
        // topic → (frame_id, frames)
        let mut sensor_frames: BTreeMap<u16, (String, Vec<FrameRef>, Vec<u64>)> = BTreeMap::new();
        for (r, k) in kept {
            let Some(stats) = topics.get_mut(&r.channel_id) else {
                continue;
            };
            stats.count += 1;
            stats.first_log_time_nanos = stats.first_log_time_nanos.min(r.log_time_nanos);
            stats.last_log_time_nanos = stats.last_log_time_nanos.max(r.log_time_nanos);
            match k {
                Kept::Transforms { msgs, is_static } => {
                    for m in &msgs {
                        if is_static {
                            tf.add_static(m)
                        } else {
                            tf.add_dynamic(m)
                        }
                    }
                }
                Kept::Poses(p) => poses_by_topic
                    .entry(stats.topic.clone())
                    .or_default()
                    .extend(p),
                Kept::CameraInfo(c) => {
                    camera_infos
                        .entry(normalize_frame(&c.frame_id))
                        .or_insert((stats.topic.clone(), c));
                }
                Kept::Sensor {
                    stamp_nanos,
                    frame_id,
                } => {
                    let e = sensor_frames
                        .entry(r.channel_id)
                        .or_insert_with(|| (frame_id, Vec::new(), Vec::new()));
                    e.1.push(FrameRef {
                        stamp_nanos,
                        msg: r,
                    });
                    e.2.push(r.log_time_nanos);
                }
                Kept::Ignored => {}
                Kept::Failed(what) => {
                    stats.failed += 1;
                    problems.push(Problem::message(&stats.topic, r.log_time_nanos, what));
                }
            }
        }
        let topics: Vec<TopicStats> = topics
            .into_values()
            .map(|mut t| {
                if t.count == 0 {
                    t.first_log_time_nanos = 0;
                }
                t
            })
            .collect();
        tf.promote_constant_dynamic_edges();
        for ((parent, child), conflicts) in tf.conflicting_stamps() {
            problems.push(stamp_conflicts(
                &format!("/tf {parent} -> {child}"),
                &conflicts,
            ));
        }

        // Trajectory: TF first, then odometry / pose topics.
        let max_extrapolation_nanos = (options.max_extrapolation_secs.max(0.0) * 1e9) as i64;
        let mut fixed_frame = options.fixed_frame.as_deref().map(normalize_frame);
        let mut vehicle_frame = options.vehicle_frame.as_deref().map(normalize_frame);
        let mut trajectory = Trajectory::default();
        let mut trajectory_source = String::from("none");
        if let Some((f, v)) = tf.default_trajectory_frames() {
            let f = fixed_frame.clone().unwrap_or(f);
            let v = vehicle_frame.clone().unwrap_or(v);
            if let Some(t) = tf.trajectory(&f, &v) {
                trajectory_source = format!("/tf: {f} -> {v} ({} poses)", t.len());
                trajectory = t;
                fixed_frame = Some(f);
                vehicle_frame = Some(v);
            } else {
                problems.push(Problem::file(format!(
                    "no TF chain from '{f}' to '{v}' for the trajectory"
                )));
            }
        }
        if trajectory.is_empty()
            && let Some((topic, poses)) = poses_by_topic.iter().max_by_key(|(_, p)| p.len())
            && let Some(first) = poses.first()
        {
            let v = first.child_frame_id.clone().map(|c| normalize_frame(&c));
            let v = vehicle_frame
                .clone()
                .or(v)
                .unwrap_or_else(|| "base_link".into());
            trajectory_source =
                format!("{topic}: {} -> {v} ({} poses)", first.frame_id, poses.len());
            fixed_frame = Some(normalize_frame(&first.frame_id));
            vehicle_frame = Some(v);
            let poses: Vec<(i64, Rigid)> = poses
                .iter()
                .map(|p| (p.stamp_nanos, p.frame_from_body))
                .collect();
            let conflicts = conflicting_stamps(&poses);
            if !conflicts.is_empty() {
                problems.push(stamp_conflicts(topic, &conflicts));
            }
            trajectory = Trajectory::new(poses);
        }
        // A pose stamped far apart from the rest (0, another epoch) would stretch the drive
        // over years: drop it and say so.
        for stamp in trajectory.remove_time_outliers() {
            problems.push(Problem::file(format!(
                "trajectory pose stamped {:.3} s lies more than an hour apart from the rest of the trajectory, at an end: dropped",
                stamp as f64 * 1e-9
            )));
        }
        // A pose far from most of its neighbours is a corrupt message, not a drive: drop it and
        // say so.
        for (stamp, jump_m) in trajectory.remove_jumps(MAX_VEHICLE_SPEED_MPS) {
            problems.push(Problem::file(format!(
                "trajectory pose at {:.3} s lies {jump_m:.3e} m from the nearest good pose, farther from most of its neighbours than {MAX_VEHICLE_SPEED_MPS} m/s allows: dropped",
                stamp as f64 * 1e-9
            )));
        }
        let trajectory = trajectory.with_max_extrapolation_nanos(max_extrapolation_nanos);

        // Sensors: every topic carrying sweeps or images.
        let vehicle_frame = vehicle_frame
            .filter(|v| !v.trim().is_empty())
            .unwrap_or_else(|| static_root_of_sensors(&tf, &sensor_frames));
        let mut rig = Rig {
            vehicle_frame: exportable_name(&vehicle_frame),
            sensors: Vec::new(),
        };
        let mut streams = Vec::new();
        for (channel_id, (frame_id, mut frames, log_times)) in sensor_frames {
            let (Some(ch), Some(Some(codec))) =
                (container.channels.get(&channel_id), codecs.get(&channel_id))
            else {
                continue;
            };
            let kind = if codec.is_lidar() {
                SensorKind::Lidar
            } else {
                SensorKind::Camera
            };
            let stamp_source = if frames.iter().all(|f| f.stamp_nanos == 0) {
                for (f, lt) in frames.iter_mut().zip(&log_times) {
                    f.stamp_nanos = *lt as i64;
                }
                problems.push(Problem::file(format!(
                    "{}: header stamps are zero; using log time",
                    ch.topic
                )));
                StampSource::LogTime
            } else {
                StampSource::Header
            };
            if kind == SensorKind::Camera {
                for f in frames.iter_mut() {
                    f.stamp_nanos += options.camera_time_offset_nanos;
                }
            }
            frames.sort_by_key(|f| f.stamp_nanos);
            // What the calibration file and the exports can carry: no line breaks, no white
            // space around (the lookups below use the log's own frame id).
            let clean_frame_id = exportable_name(&frame_id);
            let mut name = if clean_frame_id.is_empty() {
                exportable_name(&ch.topic.trim_matches('/').replace('/', "_"))
            } else {
                clean_frame_id.clone()
            };
            if rig.sensor(&name).is_some() {
                name = exportable_name(&format!("{name}{}", ch.topic.replace('/', "_")));
            }
            let vehicle_from_sensor = match tf.static_transform(&vehicle_frame, &frame_id) {
                Some(t) => t,
                None => {
                    problems.push(Problem::file(format!(
                        "no static TF from vehicle frame '{vehicle_frame}' to '{frame_id}' (sensor {name}); using identity"
                    )));
                    Rigid::IDENTITY
                }
            };
            let mut topics_of_sensor = vec![ch.topic.clone()];
            let camera = if kind == SensorKind::Camera {
                match camera_infos.get(&frame_id) {
                    Some((info_topic, info)) => {
                        topics_of_sensor.push(info_topic.clone());
                        Some(info.intrinsics.clone())
                    }
                    None => {
                        problems.push(Problem::file(format!(
                            "camera {name} ({}) has no camera info for frame '{frame_id}'",
                            ch.topic
                        )));
                        None
                    }
                }
            } else {
                None
            };
            let frame_id = clean_frame_id;
            let frame_taken =
                !frame_id.is_empty() && rig.sensors.iter().any(|s| s.frame_id == frame_id);
            if rig.sensor(&name).is_some() || name.is_empty() || frame_taken {
                problems.push(Problem::file(format!(
                    "{}: its frame id or name is blank or repeats another's once cleaned of white space and control characters; skipped",
                    ch.topic
                )));
                continue;
            }
            rig.sensors.push(Sensor {
                name: name.clone(),
                kind,
                frame_id,
                topics: topics_of_sensor,
                vehicle_from_sensor,
                camera,
            });
            streams.push(SensorStream {
                sensor: name,
                kind,
                topic: ch.topic.clone(),
                codec: *codec,
                stamp_source,
                frames,
            });
        }
        if trajectory.is_empty() {
            problems.push(Problem::file(
                "no trajectory: no dynamic /tf, odometry or pose topic",
            ));
        }
        let camera_infos = camera_infos
            .into_iter()
            .map(|(frame, (_, info))| (frame, info.intrinsics))
            .collect();
        Ok(Self {
            container: Arc::new(container),
            topics,
            tf,
            fixed_frame,
            trajectory,
            trajectory_source,
            rig,
            camera_infos,
            streams,
            problems,
            image_cache: Arc::new(Mutex::new(ByteLru::new(options.image_cache_bytes))),
            skipped_frames: Default::default(),
            camera_readout: options.camera_readout,
        })
    }

    pub fn path(&self) -> &Path {
        self.container.path()
    }

    /// The same log with cameras exposed row by row over `readout`, without reading it again:
    /// the file, its index, the decoded-image cache and the skipped-frame record are shared, and
    /// only which frames lie inside the trajectory ([`Drive::frames_within`]) and the runs'
    /// image times change. The studio gives its runs the user's readout this way.
    pub fn with_camera_readout(&self, readout: RowTimes) -> Self {
        Self {
            container: Arc::clone(&self.container),
            topics: self.topics.clone(),
            tf: self.tf.clone(),
            fixed_frame: self.fixed_frame.clone(),
            trajectory: self.trajectory.clone(),
            trajectory_source: self.trajectory_source.clone(),
            rig: self.rig.clone(),
            camera_infos: self.camera_infos.clone(),
            streams: self.streams.clone(),
            problems: self.problems.clone(),
            image_cache: Arc::clone(&self.image_cache),
            skipped_frames: Arc::clone(&self.skipped_frames),
            camera_readout: readout,
        }
    }

    pub fn container(&self) -> &McapContainer {
        &self.container
    }

    pub fn stream(&self, sensor: &str) -> Option<&SensorStream> {
        self.streams.iter().find(|s| s.sensor == sensor)
    }

    /// Frame indices of `sensor` stamped inside the trajectory (a camera with a rolling shutter:
    /// every row's time inside it) and, unless `segments_nanos` is empty, inside one of the
    /// segments.
    pub fn frames_within(&self, sensor: &str, segments_nanos: &[(i64, i64)]) -> Vec<usize> {
        let Some(stream) = self.stream(sensor) else {
            return Vec::new();
        };
        let inside = |t: i64| self.trajectory.world_from_vehicle(t).is_ok();
        // A rolling shutter's every row, from the first's time to the last's, must be inside.
        let readout = (stream.kind == SensorKind::Camera && !self.camera_readout.is_global())
            .then_some(self.camera_readout);
        (0..stream.frames.len())
            .filter(|&i| {
                let t = stream.frames[i].stamp_nanos;
                in_segments(segments_nanos, t)
                    && inside(t)
                    && readout.is_none_or(|r| {
                        inside(t + r.first_row_nanos) && inside(t + r.last_row_nanos)
                    })
            })
            .collect()
    }

    fn stream_index(&self, sensor: &str) -> Result<usize, LogError> {
        self.streams
            .iter()
            .position(|s| s.sensor == sensor)
            .ok_or_else(|| LogError::Unusable {
                path: self.path().to_path_buf(),
                what: format!("no sensor named '{sensor}'"),
            })
    }

    fn payload_error(&self, stream: &SensorStream, r: &MessageRef, what: String) -> LogError {
        LogError::Message {
            path: self.path().to_path_buf(),
            topic: stream.topic.clone(),
            log_time_nanos: r.log_time_nanos,
            what,
        }
    }

    /// Decode sweep `index` of a LiDAR.
    pub fn load_sweep(&self, sensor: &str, index: usize) -> Result<LidarSweep, LogError> {
        let stream = &self.streams[self.stream_index(sensor)?];
        let frame = self.frame(stream, index)?;
        let bytes = self
            .container
            .message_bytes(&frame.msg)
            .map_err(|e| self.payload_error(stream, &frame.msg, e.to_string()))?;
        let decoded = stream
            .codec
            .decode(&bytes)
            .map_err(|e| self.payload_error(stream, &frame.msg, e.0))?;
        let Decoded::PointCloud(cloud) = decoded else {
            return Err(self.payload_error(stream, &frame.msg, "not a point cloud".into()));
        };
        let mut sweep = pointcloud::to_sweep(&cloud)
            .map_err(|e| self.payload_error(stream, &frame.msg, e.0))?;
        sweep.stamp_nanos = frame.stamp_nanos;
        Ok(sweep)
    }

    /// Empty the caches of decoded images ([`DriveOptions::image_cache_bytes`]) and of the
    /// file's decompressed chunks: a long stage that has its own copies of what it reads, such
    /// as UniCal's training images and sweeps, need not keep them alive. What is asked for
    /// later is read and decoded again.
    pub fn release_caches(&self) {
        if let Ok(mut cache) = self.image_cache.lock() {
            cache.clear();
        }
        self.container.release_cache();
    }

    /// Decode image `index` of a camera (cached).
    pub fn load_image(&self, sensor: &str, index: usize) -> Result<Arc<RgbImage>, LogError> {
        let s = self.stream_index(sensor)?;
        if let Ok(mut cache) = self.image_cache.lock()
            && let Some(img) = cache.get(&(s, index))
        {
            return Ok(img);
        }
        let stream = &self.streams[s];
        let frame = self.frame(stream, index)?;
        let bytes = self
            .container
            .message_bytes(&frame.msg)
            .map_err(|e| self.payload_error(stream, &frame.msg, e.to_string()))?;
        let decoded = stream
            .codec
            .decode(&bytes)
            .map_err(|e| self.payload_error(stream, &frame.msg, e.0))?;
        let image = match decoded {
            Decoded::Image(raw) => super::image::decode_raw(&raw),
            Decoded::CompressedImage(c) => super::image::decode_compressed(&c),
            _ => return Err(self.payload_error(stream, &frame.msg, "not an image".into())),
        }
        .map_err(|e| self.payload_error(stream, &frame.msg, e.0))?;
        let image = Arc::new(image);
        if let Ok(mut cache) = self.image_cache.lock() {
            cache.put((s, index), image.clone(), image.as_raw().len());
        }
        Ok(image)
    }

    fn frame(&self, stream: &SensorStream, index: usize) -> Result<FrameRef, LogError> {
        stream
            .frames
            .get(index)
            .copied()
            .ok_or_else(|| LogError::Unusable {
                path: self.path().to_path_buf(),
                what: format!(
                    "{} has {} frames, asked for index {index}",
                    stream.sensor,
                    stream.frames.len()
                ),
            })
    }

    /// Time range covered by sensor data (header stamps), in nanoseconds.
    pub fn time_range_nanos(&self) -> Option<(i64, i64)> {
        let stamps = self
            .streams
            .iter()
            .flat_map(|s| s.frames.iter().map(|f| f.stamp_nanos));
        let (lo, hi) = stamps.fold((i64::MAX, i64::MIN), |(lo, hi), t| (lo.min(t), hi.max(t)));
        (lo <= hi).then_some((lo, hi))
    }
}

/// When there is no trajectory: the static-tree root that most sensor frames hang from.
fn static_root_of_sensors(
    tf: &TfTree,
    sensors: &BTreeMap<u16, (String, Vec<FrameRef>, Vec<u64>)>,
) -> String {
    let mut votes: BTreeMap<String, usize> = BTreeMap::new();
    for (frame, _, _) in sensors.values() {
        let mut current = frame.clone();
        for _ in 0..=tf.static_edges.len() {
            match tf.static_edges.get(&current) {
                Some((parent, _)) => current = parent.clone(),
                None => break,
            }
        }
        *votes.entry(current).or_default() += 1;
    }
    votes
        .into_iter()
        .filter(|(f, _)| !exportable_name(f).is_empty())
        .max_by_key(|(_, n)| *n)
        .map(|(f, _)| f)
        .unwrap_or_else(|| "base_link".into())
}

/// Whether `t` lies in one of `segments_nanos` (inclusive); every time does when there are none.
pub fn in_segments(segments_nanos: &[(i64, i64)], t: i64) -> bool {
    segments_nanos.is_empty() || segments_nanos.iter().any(|&(a, b)| t >= a && t <= b)
}

/// `n` (at least 1, at most all) of `items`, spread evenly: each from the middle of its share.
pub fn spread_evenly<T: Copy>(items: &[T], n: usize) -> Vec<T> {
    let n = n.clamp(1, items.len().max(1));
    (0..n)
        .filter_map(|k| {
            items
                .get((k * items.len()) / n + items.len() / (2 * n))
                .copied()
        })
        .collect()
}

#[cfg(test)]
mod spread_tests {
    use super::*;

    #[test]
    fn spread_takes_the_middle_of_each_share() {
        assert_eq!(spread_evenly(&[0, 1, 2, 3, 4, 5, 6, 7], 2), vec![2, 6]);
        assert_eq!(spread_evenly(&[5, 6, 7], 10), vec![5, 6, 7]);
        assert!(spread_evenly::<u8>(&[], 3).is_empty());
        assert!(in_segments(&[], 7) && in_segments(&[(0, 5), (6, 9)], 7));
        assert!(!in_segments(&[(0, 5)], 7));
    }
}
