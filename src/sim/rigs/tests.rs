//! Tests of the simulated rigs: names, mounts, scan patterns, the datasets' layouts (PandaSet, MS-Cal truck, KITTI) and round trips.

use super::*;
use glam::DVec2;
use std::collections::HashSet;

fn presets() -> Vec<SimRig> {
    RigPreset::ALL.into_iter().map(SimRig::preset).collect()
}

fn close(a: Rigid, b: Rigid, tol: f64) -> bool {
    let (r, t) = a.difference(b);
    r < tol && t < tol
}

/// Where a camera's name says it looks, in the vehicle's ground plane.
fn expected_heading(name: &str) -> DVec2 {
    let has = |word: &str| name.split('_').any(|w| w == word);
    if has("stereo") {
        return DVec2::X;
    }
    let mut v = DVec2::ZERO;
    if has("front") {
        v += DVec2::X;
    }
    if has("back") || has("rear") {
        v -= DVec2::X;
    }
    if has("left") {
        v += DVec2::Y;
    }
    if has("right") {
        v -= DVec2::Y;
    }
    v.normalize_or_zero()
}

#[test]
fn preset_names_round_trip() {
    for p in RigPreset::ALL {
        assert_eq!(p.as_str().parse::<RigPreset>(), Ok(p));
        assert_eq!(SimRig::preset(p).name, p.as_str());
    }
    assert!("PandaSet".parse::<RigPreset>().is_ok());
    let err = "van".parse::<RigPreset>().unwrap_err().to_string();
    assert!(err.contains("van") && err.contains("kitti"));
}

#[test]
fn sensor_names_are_unique() {
    for rig in presets() {
        let names: Vec<&str> = rig
            .lidars
            .iter()
            .map(|l| l.name.as_str())
            .chain(rig.cameras.iter().map(|c| c.name.as_str()))
            .collect();
        let unique: HashSet<&str> = names.iter().copied().collect();
        assert_eq!(unique.len(), names.len(), "{}: {names:?}", rig.name);
        assert!(
            names
                .iter()
                .all(|n| !n.is_empty() && !n.contains(['/', ' ']))
        );
        assert_eq!(rig.vehicle_frame, "base_link");
    }
}

#[test]
fn cameras_look_where_their_names_say() {
    for rig in presets() {
        for cam in &rig.cameras {
            let expected = expected_heading(&cam.name);
            assert!(
                expected != DVec2::ZERO,
                "{}: no direction in the name",
                cam.name
            );
            let axis = cam.vehicle_from_camera.transform_vector(DVec3::Z);
            let heading = axis.truncate().normalize();
            let off = heading.angle_to(expected).abs().to_degrees();
            assert!(off < 30.0, "{} {}: {off:.1}° off", rig.name, cam.name);
            assert!((cam.heading_deg() - heading.to_angle().to_degrees()).abs() < 1e-9);
            // The principal ray is near the horizon; image "up" is vehicle up.
            let elevation = axis.z.asin().to_degrees();
            assert!(elevation.abs() < 30.0, "{}: {elevation:.1}°", cam.name);
            let up = cam.vehicle_from_camera.transform_vector(DVec3::NEG_Y);
            assert!(up.z > 0.8, "{}: image is not upright", cam.name);
        }
    }
    let kitti = SimRig::preset(RigPreset::Kitti);
    for cam in &kitti.cameras {
        assert!(cam.heading_deg().abs() < 2.0, "{}", cam.name);
    }
}

#[test]
fn sensors_are_mounted_above_the_ground_on_the_vehicle() {
    for rig in presets() {
        let lidars = rig.lidars.iter().map(|l| (&l.name, l.vehicle_from_lidar));
        let cameras = rig.cameras.iter().map(|c| (&c.name, c.vehicle_from_camera));
        for (name, pose) in lidars.chain(cameras) {
            let t = pose.translation;
            assert!(t.z > 1.0 && t.z < 4.0, "{} {name}: {t}", rig.name);
            assert!(
                t.x.abs() < 4.0 && t.y.abs() < 2.0,
                "{} {name}: {t}",
                rig.name
            );
            let q = pose.rotation;
            assert!(q.is_finite() && (q.length() - 1.0).abs() < 1e-12);
        }
    }
}

#[test]
fn lidar_scan_patterns_are_plausible() {
    for rig in presets() {
        for lidar in &rig.lidars {
            let what = format!("{} {}", rig.name, lidar.name);
            assert!(lidar.beam_count() >= 32, "{what}");
            assert!(
                lidar.beam_elevations_deg.windows(2).all(|w| w[0] > w[1]),
                "{what}"
            );
            assert!(
                lidar.rotation_hz == 10.0 && lidar.max_range_m >= 50.0,
                "{what}"
            );
            assert!(
                lidar.range_noise_m > 0.0 && lidar.range_noise_m < 0.05,
                "{what}"
            );
            if lidar.spinning {
                assert_eq!(lidar.azimuth_range_deg, (-180.0, 180.0), "{what}");
            } else {
                // A solid-state LiDAR's window is centred on the vehicle's forward direction.
                let (a, b) = lidar.azimuth_range_deg;
                let centre = 0.5 * (a + b);
                assert!((centre - lidar.forward_azimuth_deg()).abs() < 5.0, "{what}");
                let ray = SimLidar::ray_direction(centre, 0.0);
                let forward = lidar.vehicle_from_lidar.transform_vector(ray);
                assert!(forward.x > 0.99, "{what}: {forward}");
            }
        }
    }
    let pandaset = SimRig::preset(RigPreset::Pandaset);
    let p64 = pandaset.lidar("pandar64").unwrap();
    assert_eq!(p64.beam_count(), 64);
    assert_eq!(p64.azimuth_steps(), 1800);
    let (top, bottom) = (p64.beam_elevations_deg[0], p64.beam_elevations_deg[63]);
    assert!((top - 15.0).abs() < 0.5 && (bottom + 25.0).abs() < 0.5);
    // Denser near the horizon than at the edges.
    let near = p64
        .beam_elevations_deg
        .iter()
        .filter(|e| e.abs() < 3.0)
        .count();
    assert!(near >= 30, "{near}");
    let gt = pandaset.lidar("pandar_gt").unwrap();
    assert!(!gt.spinning && (50_000..=70_000).contains(&gt.rays_per_sweep()));
    let velodyne = &SimRig::preset(RigPreset::Kitti).lidars[0];
    assert_eq!(velodyne.beam_count(), 64);
    assert!((velodyne.beam_elevations_deg[0] - 2.0).abs() < 1e-9);
    assert!((velodyne.beam_elevations_deg[63] + 24.8).abs() < 1e-9);
    assert!((velodyne.vehicle_from_lidar.translation.z - 1.73).abs() < 1e-9);
}

#[test]
fn ray_directions_follow_the_documented_convention() {
    let close = |a: DVec3, b: DVec3| (a - b).length() < 1e-12;
    assert!(close(SimLidar::ray_direction(0.0, 0.0), DVec3::X));
    assert!(close(SimLidar::ray_direction(90.0, 0.0), DVec3::Y));
    assert!(close(SimLidar::ray_direction(-180.0, 0.0), DVec3::NEG_X));
    assert!(close(SimLidar::ray_direction(33.0, 90.0), DVec3::Z));
}

#[test]
fn pandaset_matches_the_dataset_calibration() {
    let rig = SimRig::preset(RigPreset::Pandaset);
    let base_from_p64 = pandaset_base_link_from_pandar64();
    // The Pandar64 sits level at 1.9 m, turned about 92° (its -y is forward).
    assert!((base_from_p64.translation - DVec3::new(0.0, 0.0, 1.9)).length() < 1e-12);
    let minus_y = base_from_p64.transform_vector(DVec3::NEG_Y);
    assert!(minus_y.x > 0.999 && minus_y.z.abs() < 1e-12);
    // Every camera keeps the dataset's pose relative to the Pandar64.
    for c in &PANDASET_CAMERAS {
        let cam = rig.camera(c.name).unwrap();
        let p64_from_cam = base_from_p64.inverse() * cam.vehicle_from_camera;
        assert!(close(
            p64_from_cam,
            rigid_from_rows(c.pandar64_from_camera),
            1e-9
        ));
        assert_eq!((cam.intrinsics.width, cam.intrinsics.height), (1920, 1080));
        let fx = cam.intrinsics.fx;
        let expected = if c.name == "front_camera" {
            1970.0
        } else {
            930.0
        };
        assert!((fx - expected).abs() < 10.0, "{}: {fx}", c.name);
        assert!((0.85..=1.15).contains(&cam.exposure_gain));
        assert!(cam.tint_rgb.iter().all(|t| (t - 1.0).abs() <= 0.05 + 1e-12));
    }
    // The front camera looks along +x (to within its real mounting error).
    let front = rig.camera("front_camera").unwrap();
    assert!(front.heading_deg().abs() < 1e-6);
    // Camera timing: back first, then left, front-left, front, front-right, right.
    let order: Vec<&str> = {
        let mut cams: Vec<&SimCamera> = rig.cameras.iter().collect();
        cams.sort_by(|a, b| a.trigger_offset_secs.total_cmp(&b.trigger_offset_secs));
        cams.iter().map(|c| c.name.as_str()).collect()
    };
    assert_eq!(
        order,
        [
            "back_camera",
            "left_camera",
            "front_left_camera",
            "front_camera",
            "front_right_camera",
            "right_camera"
        ]
    );
    let back = rig.camera("back_camera").unwrap().trigger_offset_secs;
    assert!((back + 0.05).abs() < 0.002);
    assert_eq!(front.trigger_offset_secs, 0.0);
}

#[test]
fn sweep_trigger_offsets_follow_a_clockwise_lidar() {
    assert_eq!(sweep_trigger_offset_secs(0.0, 10.0), 0.0);
    assert!((sweep_trigger_offset_secs(90.0, 10.0) + 0.025).abs() < 1e-12);
    assert!((sweep_trigger_offset_secs(-90.0, 10.0) - 0.025).abs() < 1e-12);
    // Straight back, on either side of ±180°, fires half a sweep early.
    assert!((sweep_trigger_offset_secs(179.0, 10.0) + 0.0497).abs() < 1e-3);
    assert!((sweep_trigger_offset_secs(-179.0, 10.0) + 0.0503).abs() < 1e-3);
    let truck = SimRig::preset(RigPreset::Truck);
    let rear_left = truck.camera("rear_left_medium").unwrap();
    let rear_right = truck.camera("rear_right_medium").unwrap();
    assert!(rear_left.trigger_offset_secs < -0.03 && rear_right.trigger_offset_secs > 0.03);
}

#[test]
fn truck_follows_the_ms_cal_layout() {
    let rig = SimRig::preset(RigPreset::Truck);
    let long: Vec<&SimLidar> = rig
        .lidars
        .iter()
        .filter(|l| l.name.starts_with("long"))
        .collect();
    let medium: Vec<&SimLidar> = rig
        .lidars
        .iter()
        .filter(|l| l.name.starts_with("medium"))
        .collect();
    assert_eq!((long.len(), medium.len(), rig.cameras.len()), (2, 3, 8));
    assert!(
        long.iter()
            .all(|l| l.beam_count() == 64 && l.max_range_m == 200.0)
    );
    assert!(
        medium
            .iter()
            .all(|l| l.beam_count() == 32 && l.max_range_m == 50.0)
    );
    let mounts = rig
        .lidars
        .iter()
        .map(|l| l.vehicle_from_lidar.translation)
        .chain(
            rig.cameras
                .iter()
                .map(|c| c.vehicle_from_camera.translation),
        );
    for t in mounts {
        assert!((2.5..=3.5).contains(&t.z), "{t}");
    }
    let fx_of = |name: &str| rig.camera(name).unwrap().intrinsics.fx;
    for name in ["front_wide", "left_wide", "right_wide"] {
        let intrinsics = &rig.camera(name).unwrap().intrinsics;
        assert!((fx_of(name) - 600.0).abs() < 20.0);
        assert_eq!(intrinsics.model, CameraModel::PlumbBob);
        assert!((intrinsics.distortion[0] + 0.3).abs() < 0.05);
    }
    for name in ["front_medium", "rear_left_medium", "rear_right_medium"] {
        assert!((fx_of(name) - 1400.0).abs() < 50.0);
    }
    let (left, right) = (
        rig.camera("stereo_left").unwrap(),
        rig.camera("stereo_right").unwrap(),
    );
    assert!((fx_of("stereo_left") - 3000.0).abs() < 50.0);
    let baseline = left.vehicle_from_camera.translation - right.vehicle_from_camera.translation;
    assert!((baseline.length() - 0.5).abs() < 0.05 && baseline.y > 0.0);
}

#[test]
fn every_pixel_of_every_camera_has_a_ray() {
    for rig in presets() {
        for cam in &rig.cameras {
            let k = &cam.intrinsics;
            let (w, h) = (k.width as f64 - 0.5, k.height as f64 - 0.5);
            for (u, v) in [
                (-0.5, -0.5),
                (w, -0.5),
                (-0.5, h),
                (w, h),
                (k.cx, -0.5),
                (-0.5, k.cy),
            ] {
                let pixel = glam::DVec2::new(u, v);
                let ray = k.unproject(pixel);
                let ray = ray.unwrap_or_else(|| panic!("{} {}: ({u}, {v})", rig.name, cam.name));
                let back = k.project(ray).unwrap();
                assert!((back - pixel).length() < 1e-6, "{}: {back}", cam.name);
            }
        }
    }
}

#[test]
fn kitti_is_a_forward_stereo_pair_over_a_velodyne() {
    let rig = SimRig::preset(RigPreset::Kitti);
    let (left, right) = (
        rig.camera("stereo_left").unwrap(),
        rig.camera("stereo_right").unwrap(),
    );
    assert_eq!((left.intrinsics.width, left.intrinsics.height), (1242, 375));
    assert!((left.intrinsics.fx - 721.5).abs() < 0.5);
    // Rectified: the same orientation, offset (almost only) along the cameras' x axis.
    let right_from_left = right.vehicle_from_camera.inverse() * left.vehicle_from_camera;
    let (rotation, _) = right_from_left.difference(Rigid::IDENTITY);
    assert!(rotation < 1e-9);
    let offset = right_from_left.translation;
    let baseline = offset.x.abs();
    assert!((baseline - 0.54).abs() < 0.02, "{offset}");
    assert!(
        offset.y.abs() < 0.01 * baseline && offset.z.abs() < 0.01 * baseline,
        "{offset}"
    );
    assert!(left.vehicle_from_camera.translation.y > right.vehicle_from_camera.translation.y);
    let height = left.vehicle_from_camera.translation.z;
    assert!((height - 1.65).abs() < 0.05, "{height}");
}

#[test]
fn to_rig_round_trips_through_the_calibration_file() {
    for sim in presets() {
        let rig = sim.to_rig();
        assert_eq!(rig.sensors.len(), sim.lidars.len() + sim.cameras.len());
        let lidar = rig.sensor(&sim.lidars[0].name).unwrap();
        assert_eq!(lidar.kind, SensorKind::Lidar);
        assert_eq!(lidar.topics, [format!("/{}/points", lidar.name)]);
        assert_eq!(lidar.frame_id, lidar.name);
        let cam = rig.sensor(&sim.cameras[0].name).unwrap();
        assert_eq!(
            cam.topics,
            [
                format!("/{}/image/compressed", cam.name),
                format!("/{}/camera_info", cam.name)
            ]
        );
        let file = CalibrationFile::from_rig(&rig);
        let path = Path::new("round-trip.yaml");
        let text = file.to_yaml();
        let back = CalibrationFile::parse(&text, path)
            .unwrap()
            .to_rig(path)
            .unwrap();
        assert_eq!(back.vehicle_frame, rig.vehicle_frame);
        assert_eq!(back.sensors.len(), rig.sensors.len());
        for (a, b) in rig.sensors.iter().zip(&back.sensors) {
            assert_eq!(
                (&a.name, a.kind, &a.frame_id, &a.topics),
                (&b.name, b.kind, &b.frame_id, &b.topics)
            );
            assert!(
                close(a.vehicle_from_sensor, b.vehicle_from_sensor, 1e-12),
                "{}",
                a.name
            );
            assert_eq!(a.camera, b.camera);
        }
    }
}

#[test]
fn from_calibration_file_round_trips_via_a_temporary_file() {
    let dir = std::env::temp_dir().join(format!("rigcal-sim-rigs-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for preset in RigPreset::ALL {
        let sim = SimRig::preset(preset);
        let mut rig = sim.to_rig();
        // A 32-beam name gets the 32-beam default pattern.
        rig.sensors[0].name = format!("{}_vlp32", rig.sensors[0].name);
        let path = dir.join(format!("{preset}.yaml"));
        CalibrationFile::from_rig(&rig).save(&path).unwrap();
        let loaded = SimRig::from_calibration_file(&path).unwrap();
        assert_eq!(loaded.name, preset.as_str());
        assert_eq!(loaded.vehicle_frame, "base_link");
        assert_eq!(loaded.lidars.len(), sim.lidars.len());
        assert_eq!(loaded.cameras.len(), sim.cameras.len());
        for (a, b) in loaded.lidars.iter().zip(&sim.lidars) {
            assert!(close(a.vehicle_from_lidar, b.vehicle_from_lidar, 1e-12));
            assert!(a.spinning && a.azimuth_range_deg == (-180.0, 180.0));
            let beams = if a.name.contains("32") { 32 } else { 64 };
            assert_eq!(a.beam_count(), beams, "{}", a.name);
        }
        for (a, b) in loaded.cameras.iter().zip(&sim.cameras) {
            assert_eq!((&a.name, &a.intrinsics), (&b.name, &b.intrinsics));
            assert!(close(a.vehicle_from_camera, b.vehicle_from_camera, 1e-12));
            assert_eq!(
                (a.exposure_gain, a.tint_rgb, a.trigger_offset_secs),
                (1.0, [1.0; 3], 0.0)
            );
        }
        // And it converts back to the same rig.
        let again = loaded.to_rig();
        for (a, b) in again.sensors.iter().zip(&rig.sensors) {
            assert_eq!(a.name, b.name);
            assert!(close(a.vehicle_from_sensor, b.vehicle_from_sensor, 1e-12));
        }
    }
    let missing = SimRig::from_calibration_file(&dir.join("missing.yaml"));
    assert!(missing.unwrap_err().to_string().contains("missing.yaml"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn scaling_changes_only_the_images() {
    let rig = SimRig::preset(RigPreset::Pandaset);
    let half = rig.scaled(0.5);
    assert_eq!(half.lidars, rig.lidars);
    for (a, b) in half.cameras.iter().zip(&rig.cameras) {
        assert_eq!(a.intrinsics, b.intrinsics.scaled(0.5));
        assert_eq!((a.intrinsics.width, a.intrinsics.height), (960, 540));
        assert_eq!(a.vehicle_from_camera, b.vehicle_from_camera);
    }
    assert_eq!(rig.scaled(0.0), rig);
    assert_eq!(rig.scaled(f64::NAN), rig);
}
