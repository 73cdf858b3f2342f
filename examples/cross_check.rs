#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Does a second target-free measure rank a camera's calibrations as the truth does? For each
//! camera of a log: mutual information (LiDAR reflectivity × image grey) and the edge score,
//! at a start, at a result and at the reference, each camera taken relative to the LiDAR (the
//! problem is built with the start's LiDAR; the other rigs' cameras are carried over through
//! their own LiDAR), on frames spread over the whole log.
//!
//! `cargo run --release --no-default-features --example cross_check -- LOG REFERENCE START END [LIDAR] [FRAMES]`

use rigcal::calib::Rig;
use rigcal::calib::dataset_json::load_reference;
use rigcal::calib::file::CalibrationFile;
use rigcal::classical::mutual_info::{MiConfig, MiProblem};
use rigcal::geometry::Rigid;
use rigcal::log::Drive;
use rigcal::pipeline::edge_check::EdgeCheck;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let drive = Drive::open(std::path::Path::new(&args[0])).unwrap();
    let reference = load_reference(std::path::Path::new(&args[1])).unwrap();
    let start = CalibrationFile::load_rig(std::path::Path::new(&args[2])).unwrap();
    let end = CalibrationFile::load_rig(std::path::Path::new(&args[3])).unwrap();
    let lidar = args
        .get(4)
        .cloned()
        .unwrap_or_else(|| start.lidars().next().unwrap().name.clone());
    let frames: usize = args.get(5).and_then(|a| a.parse().ok()).unwrap_or(8);
    let lidar_pose = |rig: &Rig| rig.sensor(&lidar).unwrap().vehicle_from_sensor;
    // A rig's camera carried into the start rig's vehicle frame through the LiDAR.
    let carried = |rig: &Rig, cam: &str| -> Rigid {
        lidar_pose(&start)
            * lidar_pose(rig).inverse()
            * rig.sensor(cam).unwrap().vehicle_from_sensor
    };
    println!(
        "| camera | err start | err end | MI start | MI end | MI ref | edge start | edge end | edge ref |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let cameras: Vec<String> = start.cameras().map(|c| c.name.clone()).collect();
    for cam in &cameras {
        let (s, e, r) = (
            carried(&start, cam),
            carried(&end, cam),
            carried(&reference, cam),
        );
        let (rs, ts) = s.difference(r);
        let (re, te) = e.difference(r);
        let mi = MiProblem::from_drive(
            &drive,
            &start,
            cam,
            &lidar,
            frames,
            &[],
            &MiConfig::default(),
        );
        let (mis, mie, mir) = match &mi {
            Ok(p) => (p.mi(s), p.mi(e), p.mi(r)),
            Err(_) => (f64::NAN, f64::NAN, f64::NAN),
        };
        let edge = EdgeCheck::new(&drive, &start, (cam, &lidar), frames, &[], &[]).unwrap();
        println!(
            "| {cam} | {:.3}° / {:.1} cm | {:.3}° / {:.1} cm | {mis:.4} | {mie:.4} | {mir:.4} | {:.3} | {:.3} | {:.3} |",
            rs.to_degrees(),
            ts * 100.0,
            re.to_degrees(),
            te * 100.0,
            edge.score(s),
            edge.score(e),
            edge.score(r),
        );
    }
}
