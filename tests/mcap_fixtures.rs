#![allow(clippy::unwrap_used, clippy::expect_used)]
//! MCAP fixtures written by the official Python writers (mcap-ros2-support, foxglove-sdk; see
//! tests/fixtures/mcap/README.md) read back exactly: every topic, every message, every field the
//! expected JSON lists.

use std::collections::BTreeMap;
use std::path::PathBuf;

use rigcal::log::container::McapContainer;
use rigcal::log::decode::Codec;
use rigcal::log::types::Decoded;
use rigcal::log::{Drive, image, pointcloud};
use serde_json::Value;

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/mcap")
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a.is_nan() && b.is_nan()) || (a - b).abs() <= tol
}

/// Decode every message of the file; per topic: (log_time, owned debug-able result).
fn check(name: &str) {
    let expected: Value = serde_json::from_slice(
        &std::fs::read(dir().join(format!("{name}.expected.json"))).unwrap(),
    )
    .unwrap();
    let container = McapContainer::open(&dir().join(format!("{name}.mcap"))).unwrap();
    assert!(container.problems.is_empty(), "{:?}", container.problems);
    // topic → payload list in log-time order
    let (kept, problems) = container.scan(|r, ch, payload| {
        Some((
            ch.topic.clone(),
            r.log_time_nanos,
            payload.to_vec(),
            Codec::for_channel(ch),
        ))
    });
    assert!(problems.is_empty(), "{problems:?}");
    let mut by_topic: BTreeMap<String, Vec<(u64, Vec<u8>, Option<Codec>)>> = BTreeMap::new();
    for (_, (topic, t, payload, codec)) in kept {
        by_topic.entry(topic).or_default().push((t, payload, codec));
    }
    for v in by_topic.values_mut() {
        v.sort_by_key(|(t, _, _)| *t);
    }
    let mut checked_fields = 0usize;
    for (topic, exp) in expected["topics"].as_object().unwrap() {
        let got = by_topic
            .get(topic)
            .unwrap_or_else(|| panic!("{name}: missing {topic}"));
        let ch = container
            .channels
            .values()
            .find(|c| &c.topic == topic)
            .unwrap();
        assert_eq!(ch.schema_name, exp["schema_name"].as_str().unwrap());
        assert_eq!(
            got.len() as u64,
            exp["message_count"].as_u64().unwrap(),
            "{topic}"
        );
        for ((log_time, payload, codec), m) in got.iter().zip(exp["messages"].as_array().unwrap()) {
            assert_eq!(*log_time, m["log_time"].as_u64().unwrap(), "{topic}");
            let codec = codec.unwrap_or_else(|| panic!("{topic}: no decoder"));
            let decoded = codec
                .decode(payload)
                .unwrap_or_else(|e| panic!("{name} {topic}: {e}"));
            let stamp = m["stamp_ns"].as_i64();
            match decoded {
                Decoded::Transforms(ts) => {
                    let exp_ts = m["transforms"].as_array().unwrap();
                    assert_eq!(ts.len(), exp_ts.len());
                    for (t, e) in ts.iter().zip(exp_ts) {
                        assert_eq!(t.stamp_nanos, e["stamp_ns"].as_i64().unwrap());
                        assert_eq!(t.parent, e["parent"].as_str().unwrap());
                        assert_eq!(t.child, e["child"].as_str().unwrap());
                        for i in 0..3 {
                            assert!(close(
                                t.parent_from_child.translation[i],
                                f(&e["translation"][i]),
                                1e-12
                            ));
                        }
                        let q = t.parent_from_child.rotation;
                        let eq = &e["rotation_xyzw"];
                        let dot =
                            q.x * f(&eq[0]) + q.y * f(&eq[1]) + q.z * f(&eq[2]) + q.w * f(&eq[3]);
                        assert!(dot.abs() > 1.0 - 1e-12, "{topic}");
                        checked_fields += 1;
                    }
                }
                Decoded::Pose(p) => {
                    assert_eq!(Some(p.stamp_nanos), stamp);
                    assert_eq!(p.frame_id, m["frame_id"].as_str().unwrap());
                    if let Some(c) = m["child_frame_id"].as_str() {
                        assert_eq!(p.child_frame_id.as_deref(), Some(c));
                    }
                    for i in 0..3 {
                        assert!(close(
                            p.frame_from_body.translation[i],
                            f(&m["translation"][i]),
                            1e-12
                        ));
                    }
                    checked_fields += 1;
                }
                Decoded::CameraInfo(c) => {
                    assert_eq!(Some(c.stamp_nanos), stamp);
                    let i = &c.intrinsics;
                    assert_eq!(
                        (i.width as u64, i.height as u64),
                        (m["width"].as_u64().unwrap(), m["height"].as_u64().unwrap())
                    );
                    assert_eq!(i.model.as_str(), m["distortion_model"].as_str().unwrap());
                    let k = if m["k"].is_null() { &m["K"] } else { &m["k"] };
                    let d = if m["d"].is_null() { &m["D"] } else { &m["d"] };
                    assert_eq!(
                        (i.fx, i.cx, i.fy, i.cy),
                        (f(&k[0]), f(&k[2]), f(&k[4]), f(&k[5]))
                    );
                    let d: Vec<f64> = d.as_array().unwrap().iter().map(f).collect();
                    assert_eq!(i.distortion, d);
                    checked_fields += 1;
                }
                Decoded::PointCloud(cloud) => {
                    assert_eq!(Some(cloud.stamp_nanos), stamp);
                    assert_eq!(cloud.frame_id, m["frame_id"].as_str().unwrap());
                    let sweep = pointcloud::to_sweep(&cloud).unwrap();
                    let exp_points: Vec<&Value> = m["points"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .filter(|p| !p["x"].is_null())
                        .collect();
                    assert_eq!(
                        sweep.len(),
                        exp_points.len(),
                        "{topic}: NaN points are dropped"
                    );
                    for (k, e) in exp_points.iter().enumerate() {
                        let p = sweep.points_in_sensor[k];
                        // Points are stored as f32 in the sweep.
                        for (a, key) in p.iter().zip(["x", "y", "z"]) {
                            assert_eq!(*a, f(&e[key]) as f32, "{topic} point {k} {key}");
                        }
                        assert_eq!(
                            sweep.intensity[k],
                            f(&e["intensity"]) as f32,
                            "{topic} point {k}"
                        );
                        match (&sweep.time_offset_secs, e.get("time_rel_s")) {
                            (Some(times), Some(t)) => assert!(
                                close(times[k] as f64, f(t), 2e-6),
                                "{topic} point {k}: {} vs {}",
                                times[k],
                                t
                            ),
                            (None, None) => {}
                            (a, b) => panic!("{topic}: time field mismatch {a:?} {b:?}"),
                        }
                        checked_fields += 1;
                    }
                }
                Decoded::Image(raw) => {
                    assert_eq!(Some(raw.stamp_nanos), stamp);
                    let img = image::decode_raw(&raw).unwrap();
                    assert_eq!(
                        img.dimensions(),
                        (
                            m["width"].as_u64().unwrap() as u32,
                            m["height"].as_u64().unwrap() as u32
                        )
                    );
                    if let Some(rgb) = m["rgb"].as_array() {
                        let want: Vec<u8> = rgb.iter().map(|v| v.as_u64().unwrap() as u8).collect();
                        assert_eq!(img.as_raw(), &want, "{topic}");
                    } else {
                        let mono: Vec<u64> = m["mono_values"]
                            .as_array()
                            .unwrap()
                            .iter()
                            .map(|v| v.as_u64().unwrap())
                            .collect();
                        let shift = if raw.encoding == "mono16" { 8 } else { 0 };
                        let want: Vec<u8> =
                            mono.iter().flat_map(|v| [(v >> shift) as u8; 3]).collect();
                        assert_eq!(img.as_raw(), &want, "{topic}");
                    }
                    checked_fields += 1;
                }
                Decoded::CompressedImage(c) => {
                    assert_eq!(Some(c.stamp_nanos), stamp);
                    assert_eq!(c.format, m["format"].as_str().unwrap());
                    let img = image::decode_compressed(&c).unwrap();
                    assert_eq!(
                        img.dimensions(),
                        (
                            m["width"].as_u64().unwrap() as u32,
                            m["height"].as_u64().unwrap() as u32
                        )
                    );
                    if let Some(rgb) = m["rgb"].as_array() {
                        let want: Vec<u8> = rgb.iter().map(|v| v.as_u64().unwrap() as u8).collect();
                        assert_eq!(img.as_raw(), &want, "{topic}");
                    } else {
                        let src: Vec<i64> = m["source_rgb"]
                            .as_array()
                            .unwrap()
                            .iter()
                            .map(|v| v.as_i64().unwrap())
                            .collect();
                        let tol = m["max_abs_error_vs_source"].as_i64().unwrap();
                        for (a, b) in img.as_raw().iter().zip(&src) {
                            assert!(
                                (*a as i64 - b).abs() <= tol,
                                "{topic}: jpeg pixel {a} vs {b}"
                            );
                        }
                    }
                    checked_fields += 1;
                }
                Decoded::Poses(_) => unreachable!("no PosesInFrame in the fixtures"),
            }
        }
    }
    assert!(checked_fields > 30, "{name}: checked {checked_fields}");
}

#[test]
fn ros2_fixture_reads_back_exactly() {
    check("ros2");
}

#[test]
fn foxglove_protobuf_fixture_reads_back_exactly() {
    check("foxglove_protobuf");
}

#[test]
fn foxglove_json_fixture_reads_back_exactly() {
    check("foxglove_json");
}

#[test]
fn ros2_fixture_as_a_drive_uses_header_stamps_and_composes_tf_chains() {
    let drive = Drive::open(&dir().join("ros2.mcap")).unwrap();
    assert_eq!(drive.rig.vehicle_frame, "base_link");
    assert_eq!(drive.trajectory.len(), 20);
    let cam = drive.rig.sensor("front_camera_optical").unwrap();
    let t = cam.vehicle_from_sensor;
    assert!((t.translation - glam::DVec3::new(1.6, 0.0, 1.5)).length() < 1e-12);
    let q = glam::DQuat::from_xyzw(-0.5, 0.5, -0.5, 0.5);
    assert!(t.rotation.dot(q).abs() > 1.0 - 1e-12);
    // Header stamps, not log times (which are 5 ms later).
    let lidar = drive.stream("lidar_top").unwrap();
    assert_eq!(lidar.frames[0].stamp_nanos % 1_000_000, 0);
    assert_eq!(
        lidar.frames[0].stamp_nanos + 5_000_000,
        lidar.frames[0].msg.log_time_nanos as i64
    );
}

#[test]
fn foxglove_fixtures_as_drives() {
    for name in ["foxglove_protobuf", "foxglove_json"] {
        let drive = Drive::open(&dir().join(format!("{name}.mcap"))).unwrap();
        assert_eq!(drive.trajectory.len(), 5, "{name}: PoseInFrame trajectory");
        assert!(drive.rig.sensor("lidar_top").is_some(), "{name}");
        let sweep = drive.load_sweep("lidar_top", 0).unwrap();
        assert_eq!(sweep.len(), 20);
    }
}
