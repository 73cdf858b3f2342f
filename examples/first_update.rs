#![allow(clippy::unwrap_used, clippy::expect_used)]
//! How soon a UniCal run's extrinsics first change for a listener: the stage is prepared as
//! the pipeline prepares it after its LiDAR stage (the CPU preset, every LiDAR
//! held where the log puts it, the cameras free), then handed to [`Run::spawn`], the worker
//! the studio and the CLI use, and the caller polls its packets as the studio does. Printed:
//! the time from the spawn to the first packet, and to the first packet whose rig differs from
//! the initial one (issue 5: within 5 s of the optimisation starting).
//! `cargo run --release --example first_update -- LOG [CAMERA_FRAMES] [CAMERA_SCALE]`
//! (`RIGCAL_ALIGN_RELEASE=N`: the cameras released early, at iteration N,
//! [`DepthCalibConfig::alignment_release`]).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use rigcal::calib::SensorKind;
use rigcal::log::Drive;
use rigcal::optim::runner::{Calibrator, Run};
use rigcal::unical::calibrator::UnicalLidarStage;
use rigcal::unical::depth_calib::DepthCalibConfig;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let log = PathBuf::from(&args[1]);
    let frames: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(16);
    let scale: f64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(0.25);
    let drive = Drive::open(&log).unwrap();
    let rig = drive.rig.clone();
    let held = rig
        .sensors
        .iter()
        .filter(|s| s.kind == SensorKind::Lidar)
        .map(|s| s.name.clone())
        .collect();
    let config = DepthCalibConfig {
        iterations: 1400,
        held_sensors: held,
        correspondence_cache: Some(std::env::temp_dir().join("rigcal-probe-matches")),
        ..DepthCalibConfig::default()
    };
    // `RIGCAL_ALIGN_RELEASE=N`: the cameras follow the correspondence term from iteration N.
    let config = match std::env::var("RIGCAL_ALIGN_RELEASE").map(|v| v.parse::<usize>()) {
        Ok(Ok(n)) => DepthCalibConfig {
            alignment_release: Some(n),
            ..config
        },
        _ => config,
    };
    let prepared = Instant::now();
    let stage = UnicalLidarStage::from_drive(&drive, &rig, 4, &[], config)
        .unwrap()
        .with_cameras(&drive, frames, &[], scale)
        .unwrap();
    let initial = stage.current();
    println!("prepared in {:.1} s", prepared.elapsed().as_secs_f64());
    let started = Instant::now();
    let run = Run::spawn(Box::new(stage));
    let mut first_packet = true;
    loop {
        let Ok(packet) = run.packets.recv_timeout(Duration::from_secs(120)) else {
            println!("no change within 120 s");
            break;
        };
        let at = started.elapsed().as_secs_f64();
        if first_packet {
            first_packet = false;
            println!(
                "first packet: step {}, {at:.2} s after the spawn",
                packet.step
            );
        }
        // Above the round trip through the optimiser's parameters (≈ 1e-16).
        let moved = initial.sensors.iter().find_map(|s| {
            let now = packet.current.sensor(&s.name)?;
            let (r, t) = s.vehicle_from_sensor.difference(now.vehicle_from_sensor);
            (r + t > 1e-9).then_some((s.name.clone(), r.to_degrees(), t * 100.0))
        });
        if let Some((name, deg, cm)) = moved {
            println!(
                "first changed extrinsic ({name}, by {deg:.2e}° / {cm:.2e} cm): step {}, \
                 {at:.2} s after the spawn",
                packet.step
            );
            break;
        }
        if packet.finished {
            println!("finished without a change");
            break;
        }
    }
    run.stop();
    drop(run.join());
}
