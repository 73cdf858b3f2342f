#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Every input the fuzzers found (`fuzz/regressions/TARGET/`, RELIABILITY.md) goes through the
//! same calls as its target and ends in a value or a clean error.

use std::path::Path;

use rigcal::log::ros2::{self, Ros2Type};
use rigcal::log::types::Decoded;
use rigcal::log::{image, pointcloud};

const ROS2: [Ros2Type; 7] = Ros2Type::ALL;

fn inputs(target: &str) -> Vec<(String, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/regressions")
        .join(target);
    let mut out: Vec<(String, Vec<u8>)> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| {
            let path = e.unwrap().path();
            (path.display().to_string(), std::fs::read(&path).unwrap())
        })
        .collect();
    out.sort();
    out
}

/// The ros2 target's body: the first byte picks the type, a cloud becomes a sweep.
fn ros2_target(data: &[u8]) -> Result<usize, String> {
    let (&selector, payload) = data.split_first().ok_or("empty")?;
    let decoded =
        ros2::decode(ROS2[selector as usize % ROS2.len()], payload).map_err(|e| e.to_string())?;
    Ok(match decoded {
        Decoded::PointCloud(cloud) => pointcloud::to_sweep(&cloud)
            .map_err(|e| e.to_string())?
            .points_in_sensor
            .len(),
        Decoded::Image(raw) => image::decode_raw(&raw).map_err(|e| e.to_string())?.len(),
        Decoded::CompressedImage(c) => image::decode_compressed(&c)
            .map_err(|e| e.to_string())?
            .len(),
        _ => 0,
    })
}

#[test]
fn every_ros2_finding_decodes_or_fails_cleanly() {
    let found = inputs("ros2");
    assert!(!found.is_empty());
    for (name, data) in found {
        // A cloud and an image of zero-width rows, hundreds of millions of them, were walked
        // row by row (10 s timeouts): the cloud now has no point, the image is refused.
        let got = ros2_target(&data);
        eprintln!("{name}: {got:?}");
        assert!(matches!(got, Ok(0) | Err(_)), "{name}: {got:?}");
    }
}
