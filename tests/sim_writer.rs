#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The simulator's ROS 2 MCAP writer, read back with rigcal's own reader: everything written must
//! come back exactly (poses, extrinsics, points bit for bit, intrinsics, stamps), through the
//! summary and chunk indexes, with the schemas rosbag2 would write.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{DQuat, DVec3, EulerRot};
use image::{ExtendedColorType, ImageEncoder, RgbImage};
use rigcal::calib::SensorKind;
use rigcal::geometry::Rigid;
use rigcal::geometry::camera::{CameraIntrinsics, CameraModel};
use rigcal::log::container::McapContainer;
use rigcal::log::{Drive, StampSource};
use rigcal::sim::writer::{Ros2McapWriter, WriterError};

const T0: i64 = 1_700_000_000_000_000_000;
const MS: i64 = 1_000_000;

/// A fresh, empty directory for one test.
fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rigcal-sim-writer-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn rigid(roll: f64, pitch: f64, yaw: f64, t: [f64; 3]) -> Rigid {
    Rigid::new(
        DQuat::from_euler(EulerRot::ZYX, yaw, pitch, roll),
        DVec3::from_array(t),
    )
}

fn base_from_lidar() -> Rigid {
    rigid(0.01, -0.02, 1.62, [1.2, 0.03, 1.85])
}
fn base_from_mount() -> Rigid {
    rigid(0.0, 0.05, -0.1, [1.6, -0.2, 1.4])
}
fn mount_from_front() -> Rigid {
    // Optical frame: x right, y down, z forward.
    Rigid::new(
        DQuat::from_xyzw(-0.5, 0.5, -0.5, 0.5),
        DVec3::new(0.1, 0.0, 0.02),
    )
}
fn base_from_side() -> Rigid {
    rigid(-1.57, 0.0, 1.5, [0.5, 0.9, 1.3])
}

fn odom_from_base(i: usize) -> Rigid {
    let t = i as f64 * 0.01;
    rigid(
        0.002 * t.sin(),
        0.001 * t,
        0.3 * t,
        [8.0 * t, 0.5 * t * t, 0.01 * t],
    )
}

fn plumb_bob_front() -> CameraIntrinsics {
    CameraIntrinsics {
        model: CameraModel::PlumbBob,
        distortion: vec![-0.27, 0.075, 6e-4, -4e-4, -0.009],
        ..CameraIntrinsics::pinhole(32, 24, 30.5, 30.25, 15.7, 11.3)
    }
}

fn pinhole_side() -> CameraIntrinsics {
    CameraIntrinsics::pinhole(20, 16, 18.0, 18.5, 9.5, 7.5)
}

/// Deterministic awkward f32s: varied signs and magnitudes (including -0.0 and subnormals).
struct Lcg(u64);
impl Lcg {
    fn next_u32(&mut self) -> u32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 33) as u32
    }
    fn f32_in(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * (self.next_u32() as f32 / (1u64 << 31) as f32)
    }
}

struct Cloud {
    stamp: i64,
    points: Vec<[f32; 3]>,
    intensity: Vec<f32>,
    times: Vec<f32>,
}

fn cloud(m: usize) -> Cloud {
    let mut rng = Lcg(17 + m as u64);
    let n = 20_000 + 37 * m; // 3 clouds of ~400 KB: more than one 1 MiB chunk
    let mut points: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            [
                rng.f32_in(-80.0, 80.0),
                rng.f32_in(-80.0, 80.0),
                rng.f32_in(-3.0, 12.0),
            ]
        })
        .collect();
    points[0] = [-0.0, f32::MIN_POSITIVE / 8.0, 1e-30];
    points[1] = [f32::MAX, -f32::MAX, 0.1];
    let intensity = (0..n).map(|k| (k % 256) as f32 + 0.25 * m as f32).collect();
    let times = (0..n).map(|k| k as f32 * (0.1 / n as f32)).collect();
    Cloud {
        stamp: T0 + 50 * MS + m as i64 * 100 * MS,
        points,
        intensity,
        times,
    }
}

fn test_image(w: u32, h: u32, seed: u8) -> RgbImage {
    RgbImage::from_fn(w, h, |x, y| {
        image::Rgb([
            (x * 7) as u8 ^ seed,
            (y * 9) as u8,
            (x + y) as u8 * 3 + seed,
        ])
    })
}

fn jpeg(img: &RgbImage) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
        .encode(
            img.as_raw(),
            img.width(),
            img.height(),
            ExtendedColorType::Rgb8,
        )
        .unwrap();
    out
}

fn png(img: &RgbImage) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            ExtendedColorType::Rgb8,
        )
        .unwrap();
    out
}

fn front_stamp(j: usize) -> i64 {
    T0 + 80 * MS + j as i64 * 100 * MS
}
const SIDE_STAMP: i64 = T0 + 140 * MS;
const STATIC_STAMP: i64 = T0;

/// The small drive every read-back test uses.
fn write_drive(path: &Path) {
    let mut w = Ros2McapWriter::create(path).unwrap();
    w.write_tf_static(
        STATIC_STAMP,
        &[
            ("base_link".into(), "lidar".into(), base_from_lidar()),
            ("base_link".into(), "cam_mount".into(), base_from_mount()),
            ("cam_mount".into(), "cam_front".into(), mount_from_front()),
            ("base_link".into(), "cam_side".into(), base_from_side()),
        ],
    )
    .unwrap();
    for i in 0..50 {
        w.write_tf(
            T0 + i as i64 * 10 * MS,
            "odom",
            "base_link",
            odom_from_base(i),
        )
        .unwrap();
        if i % 10 == 5 && i < 30 {
            let c = cloud(i / 10);
            w.write_pointcloud(
                "/lidar/points",
                c.stamp,
                "lidar",
                &c.points,
                &c.intensity,
                &c.times,
            )
            .unwrap();
        }
        if i % 10 == 8 && i < 30 {
            let j = i / 10;
            let stamp = front_stamp(j);
            w.write_camera_info(
                "/cam_front/camera_info",
                stamp,
                "cam_front",
                &plumb_bob_front(),
            )
            .unwrap();
            w.write_compressed_image(
                "/cam_front/image_raw/compressed",
                stamp,
                "cam_front",
                "jpeg",
                &jpeg(&test_image(32, 24, j as u8)),
            )
            .unwrap();
        }
    }
    w.write_camera_info(
        "/cam_side/camera_info",
        SIDE_STAMP,
        "cam_side",
        &pinhole_side(),
    )
    .unwrap();
    w.write_compressed_image(
        "/cam_side/image_raw/compressed",
        SIDE_STAMP,
        "cam_side",
        "png",
        &png(&test_image(20, 16, 3)),
    )
    .unwrap();
    w.finish().unwrap();
}

fn assert_close(a: Rigid, b: Rigid, tol: f64, what: &str) {
    let (r, t) = a.difference(b);
    assert!(r <= tol && t <= tol, "{what}: {a:?} vs {b:?} ({r}, {t})");
}

#[test]
fn a_written_drive_reads_back_exactly() {
    let dir = temp_dir("roundtrip");
    let path = dir.join("drive.mcap");
    write_drive(&path);
    // Only the finished file is left: no temporary beside it.
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, [std::ffi::OsString::from("drive.mcap")]);

    let drive = Drive::open(&path).unwrap();
    assert!(drive.problems.is_empty(), "{:?}", drive.problems);
    let container = drive.container();
    assert!(container.used_summary);
    assert_eq!(container.profile.as_deref(), Some("ros2"));
    assert!(
        container.chunks.len() >= 2,
        "{} chunks",
        container.chunks.len()
    );

    // Topics, schemas, encodings, counts, log times.
    let topics: BTreeMap<&str, _> = drive.topics.iter().map(|t| (t.topic.as_str(), t)).collect();
    let expect = [
        ("/tf_static", "tf2_msgs/msg/TFMessage", 1, STATIC_STAMP),
        ("/tf", "tf2_msgs/msg/TFMessage", 50, T0),
        (
            "/lidar/points",
            "sensor_msgs/msg/PointCloud2",
            3,
            T0 + 50 * MS,
        ),
        (
            "/cam_front/camera_info",
            "sensor_msgs/msg/CameraInfo",
            3,
            front_stamp(0),
        ),
        (
            "/cam_front/image_raw/compressed",
            "sensor_msgs/msg/CompressedImage",
            3,
            front_stamp(0),
        ),
        (
            "/cam_side/camera_info",
            "sensor_msgs/msg/CameraInfo",
            1,
            SIDE_STAMP,
        ),
        (
            "/cam_side/image_raw/compressed",
            "sensor_msgs/msg/CompressedImage",
            1,
            SIDE_STAMP,
        ),
    ];
    assert_eq!(topics.len(), expect.len());
    for (topic, schema, count, first) in expect {
        let t = topics[topic];
        assert_eq!(t.schema_name, schema, "{topic}");
        assert_eq!(t.message_encoding, "cdr", "{topic}");
        assert_eq!(t.count, count, "{topic}");
        assert_eq!(t.first_log_time_nanos, first as u64, "{topic}");
        assert!(t.understood && t.failed == 0, "{topic}");
    }
    for ch in container.channels.values() {
        assert_eq!(ch.schema_encoding, "ros2msg", "{}", ch.topic);
    }

    // Trajectory: odom → base_link, 50 poses at 100 Hz.
    assert_eq!(drive.fixed_frame.as_deref(), Some("odom"));
    assert_eq!(drive.trajectory.len(), 50);
    for (i, (stamp, pose)) in drive.trajectory.poses().enumerate() {
        assert_eq!(stamp, T0 + i as i64 * 10 * MS);
        assert_close(pose, odom_from_base(i), 1e-12, &format!("pose {i}"));
    }

    // Static TF edges as written, and the composed extrinsics of the rig.
    let edges = &drive.tf.static_edges;
    assert_eq!(edges.len(), 4);
    for (parent, child, t) in [
        ("base_link", "lidar", base_from_lidar()),
        ("base_link", "cam_mount", base_from_mount()),
        ("cam_mount", "cam_front", mount_from_front()),
        ("base_link", "cam_side", base_from_side()),
    ] {
        let (p, got) = &edges[child];
        assert_eq!(p, parent);
        assert_eq!(got.translation, t.translation, "{child}");
        assert_close(*got, t, 1e-15, child);
    }
    assert_eq!(drive.rig.vehicle_frame, "base_link");
    let rig: BTreeMap<&str, _> = drive
        .rig
        .sensors
        .iter()
        .map(|s| (s.name.as_str(), s))
        .collect();
    assert_eq!(
        rig.keys().copied().collect::<Vec<_>>(),
        ["cam_front", "cam_side", "lidar"]
    );
    assert_eq!(rig["lidar"].kind, SensorKind::Lidar);
    assert_close(
        rig["lidar"].vehicle_from_sensor,
        base_from_lidar(),
        1e-15,
        "lidar",
    );
    assert_close(
        rig["cam_front"].vehicle_from_sensor,
        base_from_mount() * mount_from_front(),
        1e-15,
        "cam_front",
    );
    assert_close(
        rig["cam_side"].vehicle_from_sensor,
        base_from_side(),
        1e-15,
        "cam_side",
    );

    // Intrinsics: plumb_bob exactly; pinhole (written as plumb_bob with zeros) back as pinhole.
    assert_eq!(rig["cam_front"].camera.as_ref(), Some(&plumb_bob_front()));
    assert_eq!(rig["cam_side"].camera.as_ref(), Some(&pinhole_side()));
    assert_eq!(
        rig["cam_side"].camera.as_ref().map(|c| c.model),
        Some(CameraModel::Pinhole)
    );

    // Point clouds: header stamps, frame, and every value bit for bit.
    let lidar = drive.stream("lidar").unwrap();
    assert_eq!(lidar.stamp_source, StampSource::Header);
    assert_eq!(lidar.frames.len(), 3);
    for m in 0..3 {
        let want = cloud(m);
        assert_eq!(lidar.frames[m].stamp_nanos, want.stamp);
        assert_eq!(lidar.frames[m].msg.log_time_nanos, want.stamp as u64);
        let sweep = drive.load_sweep("lidar", m).unwrap();
        assert_eq!(sweep.stamp_nanos, want.stamp);
        assert_eq!(sweep.frame_id, "lidar");
        assert_eq!(sweep.len(), want.points.len());
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let flat = |p: &[[f32; 3]]| p.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(
            flat(&sweep.points_in_sensor),
            flat(&want.points),
            "cloud {m}"
        );
        assert_eq!(bits(&sweep.intensity), bits(&want.intensity), "cloud {m}");
        let times = sweep.time_offset_secs.as_deref().unwrap();
        assert_eq!(bits(times), bits(&want.times), "cloud {m}");
    }

    // Images: stamps and decoded dimensions.
    let front = drive.stream("cam_front").unwrap();
    assert_eq!(front.kind, SensorKind::Camera);
    assert_eq!(
        front
            .frames
            .iter()
            .map(|f| f.stamp_nanos)
            .collect::<Vec<_>>(),
        (0..3).map(front_stamp).collect::<Vec<_>>()
    );
    for j in 0..3 {
        let img = drive.load_image("cam_front", j).unwrap();
        assert_eq!(img.dimensions(), (32, 24));
    }
    let side = drive.stream("cam_side").unwrap();
    assert_eq!(side.frames.len(), 1);
    assert_eq!(side.frames[0].stamp_nanos, SIDE_STAMP);
    let img = drive.load_image("cam_side", 0).unwrap();
    // PNG is lossless: the pixels come back too.
    assert_eq!(*img, test_image(20, 16, 3));

    std::fs::remove_dir_all(&dir).unwrap();
}

/// Decoded images are kept within their bound in bytes (the least recently used go first), and
/// released ones decode again to the same pixels.
#[test]
fn decoded_images_are_kept_within_their_bytes_and_decode_the_same_after_a_release() {
    use std::sync::Arc;
    let dir = temp_dir("image-cache");
    let path = dir.join("drive.mcap");
    write_drive(&path);
    let drive = Drive::open(&path).unwrap();
    let before = drive.load_image("cam_front", 1).unwrap();
    assert!(Arc::ptr_eq(
        &before,
        &drive.load_image("cam_front", 1).unwrap()
    ));
    drive.release_caches();
    let after = drive.load_image("cam_front", 1).unwrap();
    assert!(!Arc::ptr_eq(&before, &after), "released, so decoded anew");
    assert_eq!(before.as_raw(), after.as_raw());

    // Room for one 32×24 image and a half: each image decoded pushes out the one before.
    let one_image = after.as_raw().len();
    let small = Drive::open_with(
        &path,
        &rigcal::log::DriveOptions {
            image_cache_bytes: one_image + one_image / 2,
            ..rigcal::log::DriveOptions::default()
        },
    )
    .unwrap();
    let first = small.load_image("cam_front", 0).unwrap();
    let second = small.load_image("cam_front", 1).unwrap();
    let first_again = small.load_image("cam_front", 0).unwrap();
    assert!(!Arc::ptr_eq(&first, &first_again), "evicted by the second");
    assert_eq!(first.as_raw(), first_again.as_raw());
    assert!(!Arc::ptr_eq(
        &second,
        &small.load_image("cam_front", 1).unwrap()
    ));
    // A bound of two images holds the two used last.
    let two = Drive::open_with(
        &path,
        &rigcal::log::DriveOptions {
            image_cache_bytes: 2 * one_image,
            ..rigcal::log::DriveOptions::default()
        },
    )
    .unwrap();
    let a = two.load_image("cam_front", 0).unwrap();
    let b = two.load_image("cam_front", 1).unwrap();
    assert!(Arc::ptr_eq(&a, &two.load_image("cam_front", 0).unwrap()));
    two.load_image("cam_front", 2).unwrap();
    assert!(
        Arc::ptr_eq(&a, &two.load_image("cam_front", 0).unwrap()),
        "used last but one"
    );
    assert!(
        !Arc::ptr_eq(&b, &two.load_image("cam_front", 1).unwrap()),
        "least recently used"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_file_is_shaped_like_a_rosbag2_recording() {
    let dir = temp_dir("shape");
    let path = dir.join("drive.mcap");
    write_drive(&path);
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(!summary.chunk_indexes.is_empty());
    for ci in &summary.chunk_indexes {
        assert_eq!(ci.compression, "zstd");
        assert!(!ci.message_index_offsets.is_empty());
    }
    let stats = summary.stats.as_ref().unwrap();
    assert_eq!(stats.message_count, 1 + 50 + 3 + 3 + 3 + 1 + 1);
    assert_eq!(stats.schema_count, 4);
    assert_eq!(stats.channel_count, 7);
    for ch in summary.channels.values() {
        let qos = &ch.metadata["offered_qos_profiles"];
        let durability = if ch.topic == "/tf_static" { 1 } else { 2 };
        assert!(
            qos.contains(&format!("durability: {durability}\n")),
            "{}: {qos}",
            ch.topic
        );
    }

    // Every schema is byte-identical to the one the official mcap_ros2 writer stored in the
    // fixture (the same rosbag2-style concatenation of the same .msg files).
    let fixture = McapContainer::open(Path::new("tests/fixtures/mcap/ros2.mcap")).unwrap();
    let ours = McapContainer::open(&path).unwrap();
    let mut compared = 0;
    for ch in ours.channels.values() {
        let theirs = fixture
            .channels
            .values()
            .find(|c| c.schema_name == ch.schema_name)
            .unwrap_or_else(|| panic!("fixture has no {}", ch.schema_name));
        assert_eq!(theirs.schema_encoding, ch.schema_encoding);
        assert!(
            *theirs.schema_data == *ch.schema_data,
            "{}: schema text differs from rosbag2's",
            ch.schema_name
        );
        compared += 1;
    }
    assert_eq!(compared, 7);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_unfinished_writer_leaves_nothing_behind() {
    let dir = temp_dir("unfinished");
    let path = dir.join("drive.mcap");
    {
        let mut w = Ros2McapWriter::create(&path).unwrap();
        for i in 0..10 {
            w.write_tf(T0 + i * 10 * MS, "odom", "base_link", odom_from_base(0))
                .unwrap();
        }
        // Dropped without finish(), as on an error or a panic.
    }
    assert!(!path.exists());
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);

    // A previous complete file stays as it was until a new one is finished.
    write_drive(&path);
    let before = std::fs::read(&path).unwrap();
    {
        let mut w = Ros2McapWriter::create(&path).unwrap();
        w.write_tf(T0, "odom", "base_link", Rigid::IDENTITY)
            .unwrap();
    }
    assert_eq!(std::fs::read(&path).unwrap(), before);
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn errors_name_the_output_path() {
    let dir = temp_dir("errors");
    // A path under a regular file cannot be created, whoever runs the test.
    let blocker = dir.join("not-a-directory");
    std::fs::write(&blocker, b"x").unwrap();
    let path = blocker.join("drive.mcap");
    let err = Ros2McapWriter::create(&path).unwrap_err();
    assert!(matches!(err, WriterError::Io { .. }), "{err:?}");
    assert!(err.to_string().contains(&*path.to_string_lossy()), "{err}");

    // Bad input is refused with the path too, and the file is still finished cleanly.
    let path = dir.join("drive.mcap");
    let mut w = Ros2McapWriter::create(&path).unwrap();
    let e = w
        .write_pointcloud("/p", T0, "lidar", &[[0.0; 3]; 2], &[1.0], &[0.0, 0.0])
        .unwrap_err();
    assert!(e.to_string().contains(&*path.to_string_lossy()), "{e}");
    let bad = Rigid {
        rotation: DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0),
        translation: DVec3::ZERO,
    };
    assert!(w.write_tf(T0, "odom", "base_link", bad).is_err());
    assert!(
        w.write_tf(i64::MAX, "odom", "base_link", Rigid::IDENTITY)
            .is_err()
    );
    w.write_tf(T0, "odom", "base_link", Rigid::IDENTITY)
        .unwrap();
    let e = w
        .write_compressed_image("/tf", T0, "cam", "jpeg", &[])
        .unwrap_err();
    assert!(
        e.to_string().contains("/tf carries tf2_msgs/msg/TFMessage"),
        "{e}"
    );
    w.finish().unwrap();
    assert!(Drive::open(&path).is_ok());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// One corrupt trajectory pose (1000 km off) does not sink the drive: it is dropped and named,
/// and the rest of the trajectory is kept.
#[test]
fn a_trajectory_pose_far_from_its_neighbours_is_dropped_with_a_problem() {
    let dir = temp_dir("jump");
    let path = dir.join("jump.mcap");
    let mut w = Ros2McapWriter::create(&path).unwrap();
    w.write_tf_static(
        T0,
        &[("base_link".into(), "lidar".into(), base_from_lidar())],
    )
    .unwrap();
    for i in 0..20 {
        let mut pose = Rigid::new(DQuat::IDENTITY, DVec3::new(0.5 * i as f64, 0.0, 0.0));
        if i == 7 {
            pose.translation.y += 1e6;
        }
        w.write_tf(T0 + i * 100 * MS, "odom", "base_link", pose)
            .unwrap();
    }
    w.finish().unwrap();
    let drive = Drive::open(&path).unwrap();
    assert_eq!(drive.trajectory.len(), 19);
    let said: Vec<String> = drive.problems.iter().map(|p| p.to_string()).collect();
    assert!(
        said.iter()
            .any(|p| p.contains("trajectory pose at") && p.contains("dropped")),
        "{said:?}"
    );
    let at_seven = drive.trajectory.world_from_vehicle(T0 + 700 * MS).unwrap();
    assert!((at_seven.translation - DVec3::new(3.5, 0.0, 0.0)).length() < 1e-9);
}

/// Two /tf poses of one edge at one stamp that disagree are named as a problem; the last one
/// in the log is the trajectory's, and the same pose sent twice is no problem.
#[test]
fn two_poses_at_one_stamp_that_disagree_are_named() {
    let dir = temp_dir("conflict");
    let path = dir.join("conflict.mcap");
    let mut w = Ros2McapWriter::create(&path).unwrap();
    w.write_tf_static(
        T0,
        &[("base_link".into(), "lidar".into(), base_from_lidar())],
    )
    .unwrap();
    for i in 0..10 {
        let pose = Rigid::new(DQuat::IDENTITY, DVec3::new(0.5 * i as f64, 0.0, 0.0));
        w.write_tf(T0 + i * 100 * MS, "odom", "base_link", pose)
            .unwrap();
        if i == 2 {
            // The same pose again: no conflict.
            w.write_tf(T0 + i * 100 * MS, "odom", "base_link", pose)
                .unwrap();
        }
        if i == 4 {
            let other = Rigid::new(DQuat::IDENTITY, DVec3::new(0.5 * i as f64, 0.25, 0.0));
            w.write_tf(T0 + i * 100 * MS, "odom", "base_link", other)
                .unwrap();
        }
    }
    w.finish().unwrap();
    let drive = Drive::open(&path).unwrap();
    let said: Vec<String> = drive.problems.iter().map(|p| p.to_string()).collect();
    let conflicts: Vec<&String> = said.iter().filter(|p| p.contains("disagree")).collect();
    assert_eq!(conflicts.len(), 1, "{said:?}");
    assert!(
        conflicts[0].contains("/tf odom -> base_link: 1 stamp(s)")
            && conflicts[0].contains("0.250 m"),
        "{said:?}"
    );
    let at_four = drive.trajectory.world_from_vehicle(T0 + 400 * MS).unwrap();
    assert!(
        (at_four.translation.y - 0.25).abs() < 1e-9,
        "the last pose given"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Frame ids a calibration file cannot carry (a line break, white space around, none at all)
/// and a blank vehicle frame never reach the rig: what `calibrate --out` writes loads again.
#[test]
fn odd_frame_ids_and_a_blank_vehicle_frame_give_a_rig_that_saves_and_loads() {
    let dir = temp_dir("odd-frames");
    let path = dir.join("odd.mcap");
    let mut w = Ros2McapWriter::create(&path).unwrap();
    for i in 0..5 {
        let pose = Rigid::new(DQuat::IDENTITY, DVec3::new(0.5 * i as f64, 0.0, 0.0));
        w.write_tf(T0 + i * 100 * MS, "odom", "base_link", pose)
            .unwrap();
        let points = [[1.0f32, 2.0, 3.0]; 4];
        w.write_pointcloud(
            "/a/points",
            T0 + i * 100 * MS,
            "lidar\na ",
            &points,
            &[1.0; 4],
            &[0.0; 4],
        )
        .unwrap();
        w.write_pointcloud(
            "/b/points",
            T0 + i * 100 * MS,
            "",
            &points,
            &[1.0; 4],
            &[0.0; 4],
        )
        .unwrap();
        w.write_pointcloud(
            "/c/points",
            T0 + i * 100 * MS,
            "  ",
            &points,
            &[1.0; 4],
            &[0.0; 4],
        )
        .unwrap();
    }
    w.finish().unwrap();
    let options = rigcal::log::DriveOptions {
        vehicle_frame: Some(" ".into()),
        ..Default::default()
    };
    let drive = Drive::open_with(&path, &options).unwrap();
    assert!(!drive.rig.vehicle_frame.trim().is_empty());
    let mut names: Vec<(&str, &str)> = drive
        .rig
        .sensors
        .iter()
        .map(|s| (s.name.as_str(), s.frame_id.as_str()))
        .collect();
    names.sort();
    assert_eq!(
        names,
        [("b_points", ""), ("c_points", ""), ("lidar_a", "lidar_a")]
    );
    let file = rigcal::calib::file::CalibrationFile::from_rig(&drive.rig);
    let saved = dir.join("calib.yaml");
    file.save(&saved).unwrap();
    rigcal::calib::file::CalibrationFile::load_rig(&saved).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A trajectory pose stamped near 0 in an epoch-stamped log is dropped with a problem, so the
/// drive does not span fifty years.
#[test]
fn a_trajectory_pose_stamped_in_another_epoch_is_dropped_with_a_problem() {
    let dir = temp_dir("epoch");
    let path = dir.join("epoch.mcap");
    let mut w = Ros2McapWriter::create(&path).unwrap();
    w.write_tf(1_000, "odom", "base_link", Rigid::IDENTITY)
        .unwrap();
    for i in 0..20 {
        let pose = Rigid::new(DQuat::IDENTITY, DVec3::new(0.5 * i as f64, 0.0, 0.0));
        w.write_tf(T0 + i * 100 * MS, "odom", "base_link", pose)
            .unwrap();
    }
    w.finish().unwrap();
    let drive = Drive::open(&path).unwrap();
    assert_eq!(
        drive.trajectory.time_range_nanos(),
        Some((T0, T0 + 1900 * MS))
    );
    let said: Vec<String> = drive.problems.iter().map(|p| p.to_string()).collect();
    assert!(
        said.iter()
            .any(|p| p.contains("more than an hour apart") && p.contains("dropped")),
        "{said:?}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
