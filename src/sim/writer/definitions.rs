//! The ROS 2 message definitions the writer records in each schema: the `.msg` texts of the
//! types it writes, with every type they depend on appended in the `ros2msg` layout.

use std::collections::BTreeSet;

// ------------------------------------------------------------------------------------------------
// Message definitions
// ------------------------------------------------------------------------------------------------

/// `pkg/Type` → the `.msg` text.
const MSG_FILES: &[(&str, &str)] = &[
    (
        "builtin_interfaces/Time",
        include_str!("../../../assets/ros2_msg/builtin_interfaces/msg/Time.msg"),
    ),
    (
        "std_msgs/Header",
        include_str!("../../../assets/ros2_msg/std_msgs/msg/Header.msg"),
    ),
    (
        "geometry_msgs/Quaternion",
        include_str!("../../../assets/ros2_msg/geometry_msgs/msg/Quaternion.msg"),
    ),
    (
        "geometry_msgs/Vector3",
        include_str!("../../../assets/ros2_msg/geometry_msgs/msg/Vector3.msg"),
    ),
    (
        "geometry_msgs/Transform",
        include_str!("../../../assets/ros2_msg/geometry_msgs/msg/Transform.msg"),
    ),
    (
        "geometry_msgs/TransformStamped",
        include_str!("../../../assets/ros2_msg/geometry_msgs/msg/TransformStamped.msg"),
    ),
    (
        "tf2_msgs/TFMessage",
        include_str!("../../../assets/ros2_msg/tf2_msgs/msg/TFMessage.msg"),
    ),
    (
        "sensor_msgs/PointField",
        include_str!("../../../assets/ros2_msg/sensor_msgs/msg/PointField.msg"),
    ),
    (
        "sensor_msgs/PointCloud2",
        include_str!("../../../assets/ros2_msg/sensor_msgs/msg/PointCloud2.msg"),
    ),
    (
        "sensor_msgs/CompressedImage",
        include_str!("../../../assets/ros2_msg/sensor_msgs/msg/CompressedImage.msg"),
    ),
    (
        "sensor_msgs/RegionOfInterest",
        include_str!("../../../assets/ros2_msg/sensor_msgs/msg/RegionOfInterest.msg"),
    ),
    (
        "sensor_msgs/CameraInfo",
        include_str!("../../../assets/ros2_msg/sensor_msgs/msg/CameraInfo.msg"),
    ),
];

const PRIMITIVE_TYPES: [&str; 14] = [
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
    "uint32", "int64", "uint64", "string",
];

/// The `.msg` text of `pkg/Type` or `pkg/msg/Type`.
fn msg_text(type_name: &str) -> Option<&'static str> {
    let key = type_name.replace("/msg/", "/");
    MSG_FILES
        .iter()
        .find(|(name, _)| *name == key)
        .map(|(_, text)| *text)
}

/// The non-primitive field types a `.msg` text uses, as `pkg/Type`, sorted. Like rosbag2's
/// `LocalMessageDefinitionSource`: the first word of each line (array suffix removed), when it
/// is followed by whitespace; comment lines start with `#` and so never match.
fn msg_dependencies(text: &str, pkg: &str) -> BTreeSet<String> {
    let mut deps = BTreeSet::new();
    for line in text.lines() {
        let line = line.trim_start();
        let end = line
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '/'))
            .unwrap_or(line.len());
        let (word, mut rest) = line.split_at(end);
        if word.is_empty() {
            continue;
        }
        if let Some(after) = rest.strip_prefix('[') {
            match after.find(']') {
                Some(close) => rest = &after[close + 1..],
                None => continue,
            }
        }
        if !rest.starts_with(char::is_whitespace) || PRIMITIVE_TYPES.contains(&word) {
            continue;
        }
        deps.insert(if word.contains('/') {
            word.to_string()
        } else {
            format!("{pkg}/{word}")
        });
    }
    deps
}

/// The rosbag2-style full definition of `root` (e.g. `sensor_msgs/msg/PointCloud2`); `None` if
/// a definition is missing from [`MSG_FILES`].
pub(super) fn message_definition(root: &str) -> Option<String> {
    fn append(type_name: &str, seen: &mut BTreeSet<String>, out: &mut String) -> Option<()> {
        let text = msg_text(type_name)?;
        out.push_str(text);
        let pkg = type_name.split('/').next().unwrap_or_default();
        for dep in msg_dependencies(text, pkg) {
            if seen.insert(dep.clone()) {
                out.push('\n');
                out.push_str(&"=".repeat(80));
                out.push_str("\nMSG: ");
                out.push_str(&dep);
                out.push('\n');
                append(&dep, seen, out)?;
            }
        }
        Some(())
    }
    let mut out = String::new();
    append(root, &mut BTreeSet::new(), &mut out)?;
    Some(out)
}
