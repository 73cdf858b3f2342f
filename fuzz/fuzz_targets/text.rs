//! The text readers: the first byte picks one (the native calibration YAML, the pipeline's
//! `--config` YAML, ROS camera_info YAML, URDF joints, a dataset's reference JSON, a pasted
//! transform), the rest is the file. Each reads to a value or a clean error.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use rigcal::calib::{CalibrationFile, dataset_json, transform_text};
use rigcal::interop::{camera_info, urdf};
use rigcal::pipeline::config::PipelineConfig;

fuzz_target!(|data: &[u8]| {
    let Some((&selector, rest)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(rest) else {
        return;
    };
    let path = Path::new("fuzz-input");
    match selector % 6 {
        0 => {
            if let Ok(file) = CalibrationFile::parse(text, path) {
                let _ = file.to_rig(path);
            }
        }
        1 => {
            let _ = PipelineConfig::from_yaml(text, "fuzz-input");
        }
        2 => {
            let _ = camera_info::parse(text, path);
        }
        3 => {
            let _ = urdf::parse_joints(text, path);
        }
        4 => {
            let _ = dataset_json::parse(text, path);
        }
        _ => {
            let _ = transform_text::parse_transform(text);
        }
    }
});
