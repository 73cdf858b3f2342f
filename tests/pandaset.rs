#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Acceptance on the real PandaSet drive in ../shared/data/pandaset-002 (see its README):
//! sensors, counts, /tf_static against ground_truth.json, and trajectory ∘ extrinsic against the
//! dataset's own per-camera poses at each image's header stamp.

use std::path::PathBuf;

use rigcal::calib::SensorKind;
use rigcal::geometry::Rigid;
use rigcal::log::{Drive, StampSource};
use serde_json::Value;

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/pandaset-002")
}

fn rigid_from_json(v: &Value) -> Rigid {
    let mut rows = [[0.0; 4]; 4];
    for (i, row) in v.as_array().unwrap().iter().enumerate() {
        for (j, x) in row.as_array().unwrap().iter().enumerate() {
            rows[i][j] = x.as_f64().unwrap();
        }
    }
    Rigid::from_rows(rows)
}

fn open() -> Drive {
    Drive::open(&data_dir().join("pandaset-002.mcap")).unwrap()
}

#[test]
fn sensors_counts_and_trajectory() {
    let drive = open();
    assert!(drive.problems.is_empty(), "{:?}", drive.problems);
    assert_eq!(drive.rig.vehicle_frame, "pandar64");
    assert_eq!(drive.trajectory.len(), 80);
    assert_eq!(drive.rig.lidars().count(), 2);
    assert_eq!(drive.rig.cameras().count(), 6);
    for s in &drive.streams {
        assert_eq!(s.frames.len(), 16, "{}", s.sensor);
        assert_eq!(s.stamp_source, StampSource::Header);
    }
    for cam in drive.rig.cameras() {
        let c = cam.camera.as_ref().unwrap();
        assert_eq!((c.width, c.height), (1920, 1080));
    }
}

#[test]
fn tf_static_equals_ground_truth() {
    let drive = open();
    let gt: Value =
        serde_json::from_slice(&std::fs::read(data_dir().join("ground_truth.json")).unwrap())
            .unwrap();
    for (name, s) in gt["sensors"].as_object().unwrap() {
        let sensor = drive
            .rig
            .sensor(name)
            .unwrap_or_else(|| panic!("missing {name}"));
        let expected = rigid_from_json(&s["vehicle_from_sensor"]);
        let (r, t) = expected.difference(sensor.vehicle_from_sensor);
        assert!(r.to_degrees() < 1e-6 && t < 1e-6, "{name}: {r} rad {t} m");
        let kind = if s["kind"] == "lidar" {
            SensorKind::Lidar
        } else {
            SensorKind::Camera
        };
        assert_eq!(sensor.kind, kind);
        if kind == SensorKind::Camera {
            let c = sensor.camera.as_ref().unwrap();
            assert!((c.fx - s["fx"].as_f64().unwrap()).abs() < 1e-6);
            assert!((c.cy - s["cy"].as_f64().unwrap()).abs() < 1e-6);
        }
    }
}

#[test]
fn trajectory_times_extrinsic_reproduces_camera_poses() {
    let drive = open();
    let poses: Value =
        serde_json::from_slice(&std::fs::read(data_dir().join("camera_poses.json")).unwrap())
            .unwrap();
    let mut checked = 0;
    for (camera, entries) in poses["cameras"].as_object().unwrap() {
        let sensor = drive.rig.sensor(camera).unwrap();
        let stream = drive.stream(camera).unwrap();
        for e in entries.as_array().unwrap() {
            let frame = e["frame"].as_u64().unwrap();
            if frame % 5 != 0 {
                continue; // the MCAP holds every 5th frame's images
            }
            let image = &stream.frames[(frame / 5) as usize];
            let stamp_s = e["stamp_s"].as_f64().unwrap();
            // The image's own header stamp is the camera's trigger time.
            assert!(
                (image.stamp_nanos as f64 * 1e-9 - stamp_s).abs() < 1e-5,
                "{camera} frame {frame}"
            );
            let world_from_vehicle = drive
                .trajectory
                .world_from_vehicle(image.stamp_nanos)
                .unwrap();
            let ours = world_from_vehicle * sensor.vehicle_from_sensor;
            let (r, t) = rigid_from_json(&e["world_from_camera"]).difference(ours);
            assert!(
                t < 0.03 && r.to_degrees() < 0.1,
                "{camera} frame {frame}: {t} m, {} deg",
                r.to_degrees()
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 6 * 16);
}

#[test]
fn sweeps_and_images_decode() {
    let drive = open();
    let sweep = drive.load_sweep("pandar64", 3).unwrap();
    assert!(sweep.len() > 100_000, "{}", sweep.len());
    assert!(sweep.intensity.iter().any(|&i| i > 0.0));
    let gt = drive.load_sweep("pandar_gt", 0).unwrap();
    assert!(gt.len() > 50_000);
    let img = drive.load_image("front_camera", 0).unwrap();
    assert_eq!(img.dimensions(), (1920, 1080));
    assert!(drive.load_image("front_camera", 99).is_err());
    assert!(drive.load_sweep("nope", 0).is_err());
}

#[test]
fn a_camera_time_offset_moves_the_image_stamps_only() {
    let plain = open();
    let options = rigcal::log::DriveOptions {
        camera_time_offset_nanos: -20_000_000,
        ..rigcal::log::DriveOptions::default()
    };
    let shifted = Drive::open_with(&data_dir().join("pandaset-002.mcap"), &options).unwrap();
    let mut cameras = 0;
    for stream in &plain.streams {
        let other = shifted.stream(&stream.sensor).unwrap();
        let delta = if stream.kind == SensorKind::Camera {
            cameras += 1;
            -20_000_000
        } else {
            0
        };
        assert_eq!(stream.frames.len(), other.frames.len());
        for (a, b) in stream.frames.iter().zip(&other.frames) {
            assert_eq!(b.stamp_nanos - a.stamp_nanos, delta, "{}", stream.sensor);
        }
    }
    assert_eq!(cameras, 6);
    let t = plain.time_range_nanos().unwrap().0 + 1_000_000_000;
    assert_eq!(
        plain.trajectory.world_from_vehicle(t).unwrap(),
        shifted.trajectory.world_from_vehicle(t).unwrap()
    );
}

/// With a rolling shutter a camera frame is usable only when every row's time is inside the
/// trajectory: the back camera's first image, stamped 50 ms before the first pose (within the
/// 100 ms the trajectory may extrapolate), is left out when its first row was exposed 60 ms
/// earlier still; LiDAR sweeps and the other frames are not affected. The hand-eye then places
/// each image it reads at its middle row's pose.
#[test]
fn a_rolling_shutter_keeps_only_frames_whose_rows_are_inside_the_trajectory() {
    let plain = open();
    let options = rigcal::log::DriveOptions {
        camera_readout: rigcal::geometry::RowTimes::from_millis(-60.0, 10.0),
        ..rigcal::log::DriveOptions::default()
    };
    let rolling = Drive::open_with(&data_dir().join("pandaset-002.mcap"), &options).unwrap();
    let start = plain.trajectory.time_range_nanos().unwrap().0;
    let back = plain.frames_within("back_camera", &[]);
    assert!(back.contains(&0));
    assert!(plain.stream("back_camera").unwrap().frames[0].stamp_nanos < start - 40_000_000);
    let back_rolling = rolling.frames_within("back_camera", &[]);
    assert_eq!(back_rolling, back[1..].to_vec());
    assert_eq!(
        rolling.frames_within("pandar64", &[]),
        plain.frames_within("pandar64", &[])
    );
    assert_eq!(rolling.camera_readout.last_row_nanos, 10_000_000);
    // The studio's way: the open log seen with the readout, without reading the file again.
    let viewed = plain.with_camera_readout(options.camera_readout);
    assert_eq!(viewed.frames_within("back_camera", &[]), back_rolling);
    assert_eq!(viewed.camera_readout, rolling.camera_readout);
    // The hand-eye places each image at its middle row's time (25 ms before its stamp here).
    let rolled = rigcal::classical::camera_motion::camera_pairs(
        &rolling,
        &rolling.rig,
        "back_camera",
        2,
        &[],
        false,
        &|_, _, _| {},
    )
    .unwrap();
    let stream = rolling.stream("back_camera").unwrap();
    let picked = rigcal::log::spread_evenly(&back_rolling, 2);
    for (k, &i) in picked.iter().enumerate() {
        let stamp = stream.frames[i].stamp_nanos;
        let at = |t: i64| plain.trajectory.world_from_vehicle(t).unwrap().translation;
        let rolled_at = rolled.world_from_vehicle[k].unwrap().translation;
        assert!(rolled_at.distance(at(stamp - 25_000_000)) < 1e-9);
        // Not the stamp's pose (4.7 mm away at the first image read, a quarter into the log).
        assert!(rolled_at.distance(at(stamp)) > 1e-3);
    }
}
