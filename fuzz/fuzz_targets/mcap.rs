//! The MCAP container and chunk walk, the index the drive builds from it and every frame it
//! then decodes: any bytes open to a drive or a clean error, never a panic or a hang.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rigcal::log::Drive;

fuzz_target!(|data: &[u8]| {
    // Drive::open reads a path: one scratch file per process, rewritten per input.
    let path = std::env::temp_dir().join(format!("rigcal-fuzz-{}.mcap", std::process::id()));
    if std::fs::write(&path, data).is_err() {
        return;
    }
    if let Ok(drive) = Drive::open(&path) {
        for stream in &drive.streams {
            for index in 0..stream.frames.len().min(4) {
                let _ = drive.sweep_or_skip(&stream.sensor, index);
                let _ = drive.image_or_skip(&stream.sensor, index);
            }
        }
        let _ = drive.skipped_summary();
    }
});
