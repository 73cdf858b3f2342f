//! Writes the seed corpora in `fuzz/corpus/` from the test fixtures (`scripts/fuzz.sh seeds`):
//! every fixture MCAP whole for `mcap`, one message of each type and encoding for `ros2` and
//! `foxglove` (the selector byte, then the payload), and small text files for `text`.

use std::collections::BTreeSet;
use std::path::Path;

use rigcal::log::container::McapContainer;
use rigcal::log::foxglove::FoxgloveType;
use rigcal::log::ros2::Ros2Type;

const ROS2: [&str; 7] = [
    "PointCloud2",
    "Image",
    "CompressedImage",
    "CameraInfo",
    "TfMessage",
    "Odometry",
    "PoseStamped",
];
const FOXGLOVE: [&str; 8] = [
    "PointCloud",
    "CompressedImage",
    "RawImage",
    "CameraCalibration",
    "FrameTransform",
    "FrameTransforms",
    "PoseInFrame",
    "PosesInFrame",
];

const NATIVE: &str = "rigcal_calibration: 1
vehicle_frame: base_link
sensors:
  - name: front_camera
    kind: camera
    frame_id: front_camera
    topics: [/front_camera/image/compressed]
    vehicle_from_sensor:
      translation_m: [1.0, 2.0, 3.0]
      rotation_xyzw: [0.0, 0.0, 0.0, 1.0]
    camera: {width: 64, height: 48, model: plumb_bob, fx: 50.0, fy: 50.0, cx: 32.0, cy: 24.0, distortion: [0.1, -0.01, 0.0, 0.0, 0.0]}
  - name: lidar
    kind: lidar
    vehicle_from_sensor: {translation_m: [0, 0, 1.8], rotation_xyzw: [0, 0, 0, 1]}
";
const CAMERA_INFO: &str = "image_width: 64
image_height: 48
camera_name: front_camera
camera_matrix: {rows: 3, cols: 3, data: [50, 0, 32, 0, 50, 24, 0, 0, 1]}
distortion_model: plumb_bob
distortion_coefficients: {rows: 1, cols: 5, data: [0.1, -0.01, 0, 0, 0]}
";

fn write(dir: &Path, name: &str, bytes: &[u8]) {
    std::fs::create_dir_all(dir).expect("corpus directory");
    std::fs::write(dir.join(name), bytes).expect("seed file");
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let fixtures = root.join("../tests/fixtures/mcap");
    let corpus = root.join("corpus");
    let mut seen = BTreeSet::new();
    for name in ["ros2.mcap", "foxglove_protobuf.mcap", "foxglove_json.mcap"] {
        let path = fixtures.join(name);
        let bytes = std::fs::read(&path).expect("fixture");
        write(&corpus.join("mcap"), name, &bytes);
        let container = McapContainer::open(&path).expect("fixture opens");
        let (messages, _) = container.scan(|_, channel, _| Some(channel.clone()));
        for (r, channel) in messages {
            let selector = match channel.message_encoding.as_str() {
                "cdr" => Ros2Type::from_schema(&channel.schema_name)
                    .and_then(|t| ROS2.iter().position(|n| format!("{t:?}") == *n))
                    .map(|k| ("ros2", k as u8)),
                "protobuf" | "json" => FoxgloveType::from_schema(&channel.schema_name)
                    .and_then(|t| FOXGLOVE.iter().position(|n| format!("{t:?}") == *n))
                    .map(|k| {
                        let json = (channel.message_encoding == "json") as u8;
                        ("foxglove", k as u8 * 2 + json)
                    }),
                _ => None,
            };
            let Some((target, selector)) = selector else {
                continue;
            };
            if !seen.insert((target, selector)) {
                continue;
            }
            let Ok(payload) = container.message_bytes(&r) else {
                continue;
            };
            let mut seed = vec![selector];
            seed.extend_from_slice(&payload);
            write(&corpus.join(target), &format!("{selector:03}"), &seed);
        }
    }
    let inline: [(u8, &str, &str); 6] = [
        (0, "native.yaml", NATIVE),
        (2, "camera_info.yaml", CAMERA_INFO),
        (
            1,
            "config.yaml",
            "quality: fast\nbudget_secs: 60\ncameras:\n  image_scale: 0.25\n",
        ),
        (
            3,
            "joints.urdf",
            "<robot name=\"r\"><link name=\"base_link\"/><link name=\"cam\"/><joint name=\"j\" type=\"fixed\"><parent link=\"base_link\"/><child link=\"cam\"/><origin xyz=\"1 0 1.5\" rpy=\"0 0.1 0\"/></joint></robot>",
        ),
        (
            4,
            "reference.json",
            "{\"vehicle_frame\": \"base\", \"sensors\": {\"cam\": {\"kind\": \"camera\", \"vehicle_from_sensor\": [[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 2], [0, 0, 0, 1]], \"width\": 64, \"height\": 48, \"fx\": 50, \"fy\": 50, \"cx\": 32, \"cy\": 24}}}",
        ),
        (
            5,
            "transform.txt",
            "translation_m: [1, 2, 3]\nrotation_xyzw: [0, 0, 0, 1]\n",
        ),
    ];
    for (selector, name, body) in inline {
        let mut seed = vec![selector];
        seed.extend_from_slice(body.as_bytes());
        write(&corpus.join("text"), name, &seed);
    }
    println!("seeds written to {}", corpus.display());
}
