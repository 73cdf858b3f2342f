//! Foxglove messages in protobuf and in JSON: the first byte picks the encoding and the type
//! (PointCloud, CompressedImage, RawImage, CameraCalibration, FrameTransform(s),
//! PoseInFrame, PosesInFrame), the rest is the payload.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rigcal::log::foxglove::{self, FoxgloveType};
use rigcal::log::types::Decoded;
use rigcal::log::{image, pointcloud};

const TYPES: [FoxgloveType; 8] = [
    FoxgloveType::PointCloud,
    FoxgloveType::CompressedImage,
    FoxgloveType::RawImage,
    FoxgloveType::CameraCalibration,
    FoxgloveType::FrameTransform,
    FoxgloveType::FrameTransforms,
    FoxgloveType::PoseInFrame,
    FoxgloveType::PosesInFrame,
];

fn use_decoded(decoded: Decoded<'_>) {
    match decoded {
        Decoded::PointCloud(cloud) => {
            let _ = pointcloud::to_sweep(&cloud);
        }
        Decoded::Image(raw) => {
            let _ = image::decode_raw(&raw);
        }
        Decoded::CompressedImage(compressed) => {
            let _ = image::decode_compressed(&compressed);
        }
        _ => {}
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&selector, payload)) = data.split_first() else {
        return;
    };
    let kind = TYPES[(selector as usize / 2) % TYPES.len()];
    if selector % 2 == 0 {
        if let Ok(d) = foxglove::decode_protobuf(kind, payload) {
            use_decoded(d);
        }
    } else if let Ok(d) = foxglove::decode_json(kind, payload) {
        use_decoded(d);
    }
});
