#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Checkerboard corner error of every camera–LiDAR pair of a drive, with the drive's own
//! extrinsics or a calibration file's.
//! `cargo run --release --example corner_error -- LOG.mcap [CALIBRATION.yaml] [FRAMES]`

use rigcal::calib::CalibrationFile;
use rigcal::eval::checkerboard::{BoardSpec, pair_corner_error};
use rigcal::log::Drive;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let log = args.get(1).ok_or_else(|| {
        anyhow::anyhow!("usage: corner_error LOG.mcap [CALIBRATION.yaml] [FRAMES]")
    })?;
    let drive = Drive::open(std::path::Path::new(log))?;
    let mut rig = drive.rig.clone();
    if let Some(c) = args.get(2) {
        let other = CalibrationFile::load_rig(std::path::Path::new(c))?;
        for s in &other.sensors {
            if let Some(t) = rig.sensor_mut(&s.name) {
                t.vehicle_from_sensor = s.vehicle_from_sensor;
            }
        }
    }
    let frames: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(2);
    let spec = BoardSpec::default();
    for cam in rig.cameras() {
        for lidar in rig.lidars() {
            match pair_corner_error(&drive, &rig, &cam.name, &lidar.name, frames, &spec) {
                Ok(Some(e)) => println!(
                    "{:>20} {:>10}: {} boards, {} corners, {:.2} px {:.2?}",
                    cam.name, lidar.name, e.boards, e.corners, e.mean_px, e.per_board_px
                ),
                Ok(None) => println!("{:>20} {:>10}: no board", cam.name, lidar.name),
                Err(e) => println!("{:>20} {:>10}: error {e}", cam.name, lidar.name),
            }
        }
    }
    Ok(())
}
