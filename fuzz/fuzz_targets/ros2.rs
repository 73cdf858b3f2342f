//! ROS 2 CDR messages: the first byte picks the type (PointCloud2, Image, CompressedImage,
//! CameraInfo, TFMessage, Odometry, PoseStamped), the rest is its payload; a decoded cloud
//! becomes a sweep and an image pixels, as a run would use them.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rigcal::log::ros2::{self, Ros2Type};
use rigcal::log::types::Decoded;
use rigcal::log::{image, pointcloud};

const TYPES: [Ros2Type; 7] = Ros2Type::ALL;

fuzz_target!(|data: &[u8]| {
    let Some((&selector, payload)) = data.split_first() else {
        return;
    };
    let kind = TYPES[selector as usize % TYPES.len()];
    match ros2::decode(kind, payload) {
        Ok(Decoded::PointCloud(cloud)) => {
            let _ = pointcloud::to_sweep(&cloud);
        }
        Ok(Decoded::Image(raw)) => {
            let _ = image::decode_raw(&raw);
        }
        Ok(Decoded::CompressedImage(compressed)) => {
            let _ = image::decode_compressed(&compressed);
        }
        _ => {}
    }
});
