//! Tests of [`super`] (writer).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::*;
use crate::log::cdr::CdrReader;

#[test]
fn in_memory_and_file_writers_end_their_own_way_and_leave_nothing_behind() {
    let mut w = Ros2McapWriter::in_memory().unwrap();
    w.write_tf_static(0, &[("base_link".into(), "lidar".into(), Rigid::IDENTITY)])
        .unwrap();
    let bytes = w.finish_bytes().unwrap();
    assert!(bytes.starts_with(b"\x89MCAP0\r\n") && bytes.ends_with(b"\x89MCAP0\r\n"));
    let err = Ros2McapWriter::in_memory().unwrap().finish().unwrap_err();
    assert!(err.to_string().contains("finish_bytes"), "{err}");
    let dir = std::env::temp_dir().join(format!("rigcal-writer-ends-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("x.mcap");
    let err = Ros2McapWriter::create(&path)
        .unwrap()
        .finish_bytes()
        .unwrap_err();
    assert!(err.to_string().contains("ends with finish"), "{err}");
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        0,
        "temporary file left"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn every_definition_resolves_with_dependencies_once_in_rosbag2_order() {
    let tf = message_definition("tf2_msgs/msg/TFMessage").unwrap();
    let headers: Vec<&str> = tf.lines().filter(|l| l.starts_with("MSG: ")).collect();
    assert_eq!(
        headers,
        [
            "MSG: geometry_msgs/TransformStamped",
            "MSG: geometry_msgs/Transform",
            "MSG: geometry_msgs/Quaternion",
            "MSG: geometry_msgs/Vector3",
            "MSG: std_msgs/Header",
            "MSG: builtin_interfaces/Time",
        ]
    );
    assert!(tf.starts_with("geometry_msgs/TransformStamped[] transforms\n\n====="));
    let info = message_definition("sensor_msgs/msg/CameraInfo").unwrap();
    let headers: Vec<&str> = info.lines().filter(|l| l.starts_with("MSG: ")).collect();
    assert_eq!(
        headers,
        [
            "MSG: sensor_msgs/RegionOfInterest",
            "MSG: std_msgs/Header",
            "MSG: builtin_interfaces/Time"
        ]
    );
    for kind in [
        MsgType::TfMessage,
        MsgType::PointCloud2,
        MsgType::CompressedImage,
        MsgType::CameraInfo,
    ] {
        assert!(message_definition(kind.schema_name()).is_some());
    }
}

#[test]
fn cdr_aligns_from_after_the_encapsulation_header() {
    let mut buf = Vec::new();
    let mut w = CdrWriter::new(&mut buf, 0);
    w.u8(9);
    w.u32(7);
    w.f64(1.5);
    w.string("ab").unwrap();
    w.header(-1, "f").unwrap();
    let mut expected = vec![0, 1, 0, 0, 9, 0, 0, 0, 7, 0, 0, 0];
    expected.extend_from_slice(&1.5f64.to_le_bytes());
    expected.extend_from_slice(&[3, 0, 0, 0, b'a', b'b', 0, 0]);
    expected.extend_from_slice(&(-1i32).to_le_bytes());
    expected.extend_from_slice(&999_999_999u32.to_le_bytes());
    expected.extend_from_slice(&[2, 0, 0, 0, b'f', 0]);
    assert_eq!(buf, expected);
    let mut r = CdrReader::new(&buf).unwrap();
    assert_eq!(r.u8("a").unwrap(), 9);
    assert_eq!(r.u32("b").unwrap(), 7);
    assert_eq!(r.f64("c").unwrap(), 1.5);
    assert_eq!(r.string("d").unwrap(), "ab");
    assert_eq!(r.i32("e").unwrap(), -1);
}

#[test]
fn ros_time_is_floored_and_range_checked() {
    assert_eq!(ros_time(1_500_000_001).unwrap(), (1, 500_000_001));
    assert_eq!(ros_time(-1).unwrap(), (-1, 999_999_999));
    assert!(ros_time(i64::MAX).is_err());
}
