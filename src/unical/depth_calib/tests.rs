//! Tests of the UniCal step: known answers on small synthetic drives.

use super::super::field::FieldConfig;
use super::super::hash_grid::HashGridConfig;
use super::*;

mod camera_rays;

/// A straight drive at 8 m/s and a LiDAR 2 m above flat ground.
fn flat_drive() -> (Trajectory, Rigid, Vec<LidarSweep>) {
    let trajectory = Trajectory::new(
        (0..=20)
            .map(|i| {
                (
                    i * 50_000_000,
                    Rigid::from_translation(DVec3::new(i as f64 * 0.4, 0.0, 0.0)),
                )
            })
            .collect(),
    );
    let mount = Rigid::from_translation(DVec3::new(0.0, 0.0, 2.0));
    let sweeps: Vec<LidarSweep> = (1..10)
        .map(|k| {
            let points: Vec<[f32; 3]> = (0..400)
                .map(|j| {
                    let az = j as f32 * 0.0157;
                    let el = -0.2 - 0.3 * ((j * 7 % 11) as f32 / 11.0);
                    let r = 2.0 / -el.sin();
                    [
                        r * el.cos() * az.cos(),
                        r * el.cos() * az.sin(),
                        r * el.sin(),
                    ]
                })
                .collect();
            // Intensity falls with incidence: steep beams (near the car) return brighter,
            // which the decoder can learn from the view direction before the surface forms
            // (a release run learns 1 m reflectivity stripes too, once the surface has
            // formed after ~200 steps).
            let intensity = points
                .iter()
                .map(|p| {
                    if p[2] / p[0].hypot(p[1]) < -0.4 {
                        200.0
                    } else {
                        40.0
                    }
                })
                .collect();
            LidarSweep {
                stamp_nanos: k * 100_000_000,
                frame_id: "lidar".into(),
                intensity,
                points_in_sensor: points,
                time_offset_secs: None,
            }
        })
        .collect();
    (trajectory, mount, sweeps)
}

/// A wall at x = 20 m seen by a sweep whose returns fire over ±50 ms while the car drives
/// at 8 m/s: each return is measured from where the LiDAR was at its own time, so it lands
/// on the wall only when placed at that time (within the 0.5 ms of the pose buckets, 4 mm;
/// at the stamp it would sit up to 40 cm off).
#[test]
fn aggregated_returns_are_placed_at_their_firing_time() {
    let (trajectory, mount, _) = flat_drive();
    let stamp = 500_000_000; // the car at x = 4 m
    let offsets: Vec<f32> = (0..11).map(|k| -0.05 + 0.01 * k as f32).collect();
    let points: Vec<[f32; 3]> = offsets
        .iter()
        .map(|&t| {
            let car_x = 4.0 + 8.0 * t as f64;
            [(20.0 - car_x) as f32, 1.0, 0.0]
        })
        .collect();
    let mut sweep = LidarSweep {
        stamp_nanos: stamp,
        frame_id: "lidar".into(),
        intensity: vec![100.0; points.len()],
        points_in_sensor: points,
        time_offset_secs: Some(offsets),
    };
    let placed = deskewed_points(&trajectory, &sweep, mount, 1);
    assert_eq!(placed.len(), 11);
    for p in &placed {
        assert!((p.x - 20.0).abs() < 4e-3, "{p}");
    }
    // Every other return, and the same returns of a sweep without times: at the stamp.
    assert_eq!(deskewed_points(&trajectory, &sweep, mount, 2).len(), 6);
    sweep.time_offset_secs = None;
    let at_stamp = deskewed_points(&trajectory, &sweep, mount, 1);
    assert!((at_stamp[0].x - 20.4).abs() < 1e-4 && (at_stamp[10].x - 19.6).abs() < 1e-4);
    // A sweep reaching outside the trajectory (a second before it) gives none.
    sweep.stamp_nanos = 0;
    sweep.time_offset_secs = Some(vec![-1.0; 11]);
    assert!(deskewed_points(&trajectory, &sweep, mount, 1).is_empty());
}

#[test]
fn pose_rates_wait_ramp_up_then_decay() {
    let config = DepthCalibConfig {
        pose_warmup: 10,
        pose_ramp: 4,
        iterations: 110,
        ..DepthCalibConfig::default()
    };
    let rate = |it| config.pose_rate(1.0, 0.01, it);
    assert_eq!(rate(0), 0.0);
    assert_eq!(rate(9), 0.0);
    // Linear over the ramp (times the decay, 0.01^(k/100) after k iterations).
    for k in 0..4 {
        let expected = (k + 1) as f32 / 4.0 * 0.01f32.powf(k as f32 / 100.0);
        assert!(
            (rate(10 + k) - expected).abs() < 1e-6,
            "{k}: {}",
            rate(10 + k)
        );
    }
    assert!((rate(60) - 0.1).abs() < 1e-5, "{}", rate(60));
    assert!((rate(110) - 0.01).abs() < 1e-6 && rate(500) == rate(110));
    // Without a ramp the full (decayed) rate starts at once.
    let at_once = DepthCalibConfig {
        pose_ramp: 0,
        ..config.clone()
    };
    assert_eq!(at_once.pose_rate(1.0, 0.01, 10), 1.0);
    // A run too short for the ramp ramps over a quarter of its moving iterations.
    let short = DepthCalibConfig {
        pose_ramp: 150,
        iterations: 50,
        ..config.clone()
    };
    let expected = 0.01f32.powf(9.0 / 40.0);
    assert!((short.pose_rate(1.0, 0.01, 19) - expected).abs() < 1e-6);
    assert!((short.pose_rate(1.0, 0.01, 14) - 0.5 * 0.01f32.powf(4.0 / 40.0)).abs() < 1e-6);
}

#[test]
fn a_translation_with_its_own_decay_keeps_more_of_its_rate_late() {
    let config = DepthCalibConfig {
        iterations: 1200,
        pose_warmup: 200,
        camera_pose_final_fraction: 0.01,
        camera_translation_rate: 2.0,
        camera_translation_final_fraction: Some(0.05),
        ..DepthCalibConfig::default()
    };
    // At the warm-up's end the plain multiple; by the end the two decays' ratio on top.
    assert!((config.camera_translation_scale(0) - 2.0).abs() < 1e-12);
    assert!((config.camera_translation_scale(200) - 2.0).abs() < 1e-12);
    assert!((config.camera_translation_scale(1200) - 10.0).abs() < 1e-5);
    assert!((config.camera_translation_scale(5000) - 10.0).abs() < 1e-5);
    // The translation's own rate is the rate decayed to its own final fraction.
    for it in [300, 700, 1100] {
        let s = (it - 200) as f64 / 1000.0;
        let rotation = decayed_lr(1.0, 0.01, it - 200, 1000) as f64;
        let translation = rotation * config.camera_translation_scale(it);
        assert!((translation - 2.0 * 0.05f64.powf(s)).abs() < 1e-5, "{it}");
    }
    // Without its own decay it is the plain multiple throughout.
    let plain = DepthCalibConfig {
        camera_translation_final_fraction: None,
        ..config
    };
    assert_eq!(plain.camera_translation_scale(900), 2.0);
    // After a hand-eye start: rotations at a tenth of the preset's rate, translations at a
    // fifth when poses are released, decaying to 5 % instead of 1 %.
    let preset = DepthCalibConfig::default();
    let he = preset.clone().after_hand_eye(&["front".to_string()], 1.0);
    assert_eq!(
        he.camera_rotation_bounds_deg,
        vec![("front".to_string(), 1.0)]
    );
    assert_eq!(preset.clone().after_hand_eye(&[], 1.0), preset);
    assert_eq!(he.lr_camera_pose, preset.lr_camera_pose * 0.1);
    // The warm-up and ramp scale with the run, never below the preset's.
    let long = DepthCalibConfig {
        iterations: 1400,
        ..preset.clone()
    }
    .after_hand_eye(&["front".to_string()], 1.0);
    assert_eq!((long.pose_warmup, long.pose_ramp), (400, 300));
    let short = DepthCalibConfig {
        iterations: 300,
        ..preset.clone()
    }
    .after_hand_eye(&["front".to_string()], 1.0);
    assert_eq!(
        (short.pose_warmup, short.pose_ramp),
        (preset.pose_warmup, preset.pose_ramp)
    );
    assert!(
        !he.alignment_release_rotates,
        "its rotations stay during a release"
    );
    assert_eq!(he.camera_release(), HAND_EYE_RELEASE);
    assert!(he.camera_release() < he.pose_warmup);
    let release = he.pose_warmup;
    let translation_at = |c: &DepthCalibConfig, it: usize| {
        c.pose_rate(c.lr_camera_pose, c.camera_pose_final_fraction, it) as f64
            * c.camera_translation_scale(it)
    };
    // Against the preset's rates on the same warm-up and ramp.
    let preset = DepthCalibConfig {
        pose_warmup: he.pose_warmup,
        pose_ramp: he.pose_ramp,
        ..preset
    };
    // Twice the rotations' reduced rate at the release, decaying to 5 % instead of 1 %.
    let reduced = 2.0 * HAND_EYE_RATE as f64;
    assert!(translation_at(&he, release) > 0.0);
    let at_release = translation_at(&he, release) / translation_at(&preset, release);
    assert!((at_release / reduced - 1.0).abs() < 1e-5, "{at_release}");
    let last = he.iterations - 1;
    let ratio = translation_at(&he, last) / translation_at(&preset, last);
    assert!((ratio / reduced - 5.0).abs() < 0.1, "{ratio}");
}

/// Cameras released early by the correspondence term ramp up from their release and start
/// the usual schedule again at the warm-up's end; LiDARs still wait for it; a release after
/// the warm-up changes nothing.
#[test]
fn an_alignment_release_starts_only_the_cameras_early() {
    let config = DepthCalibConfig {
        pose_warmup: 10,
        pose_ramp: 4,
        iterations: 110,
        alignment_release: Some(4),
        alignment_release_rate: 0.5,
        ..DepthCalibConfig::default()
    };
    assert_eq!(config.camera_release(), 4);
    assert_eq!(config.camera_pose_rate(1.0, 0.01, 3), 0.0);
    let first = 0.25 * 0.5;
    assert!((config.camera_pose_rate(1.0, 0.01, 4) - first).abs() < 1e-6);
    assert_eq!(config.camera_pose_rate(1.0, 0.01, 7), 0.5, "ramped up by 7");
    assert_eq!(config.pose_rate(1.0, 0.01, 9), 0.0, "LiDARs wait");
    // From the warm-up's end the cameras' schedule is the LiDARs' (ramped again).
    for it in [10, 11, 30, 109] {
        assert_eq!(
            config.camera_pose_rate(1.0, 0.01, it),
            config.pose_rate(1.0, 0.01, it)
        );
    }
    let late = DepthCalibConfig {
        alignment_release: Some(50),
        ..config.clone()
    };
    assert_eq!(late.camera_release(), 10);
    for it in [0, 9, 10, 30, 109] {
        assert_eq!(
            late.camera_pose_rate(1.0, 0.01, it),
            late.pose_rate(1.0, 0.01, it)
        );
    }
}

fn small_config() -> DepthCalibConfig {
    DepthCalibConfig {
        field: FieldConfig {
            grid: HashGridConfig {
                levels: 6,
                log2_table_size: 14,
                base_resolution: 8.0,
                max_resolution: 256.0,
            },
            hidden: 32,
            feature_dim: 3,
            initial_sdf_m: 0.5,
            cubic_box: false,
        },
        rays_per_sensor: 128,
        rays_per_camera: 128,
        iterations: 40,
        geometry_init_steps: 0,
        pose_warmup: 0,
        pose_ramp: 0,
        ..DepthCalibConfig::default()
    }
}

/// A forward camera 1.5 m up, pitched down, imaging the ground's colour pattern (blocks of
/// 1 m) seen through its true pose, 64×48 pixels.
fn ground_camera(trajectory: &Trajectory) -> CameraData {
    let intrinsics = CameraIntrinsics::pinhole(64, 48, 40.0, 40.0, 31.5, 23.5);
    // Optical frame: z forward (vehicle +x), x right (−y), y down (−z), pitched 25° down.
    let level = glam::DMat3::from_cols(-DVec3::Y, -DVec3::Z, DVec3::X);
    let pitch = glam::DMat3::from_rotation_y(25f64.to_radians());
    let vehicle_from_camera = Rigid::new(
        glam::DQuat::from_mat3(&(pitch * level)),
        DVec3::new(1.0, 0.0, 1.5),
    );
    let frames = (2..9)
        .map(|k| {
            let stamp_nanos = k * 100_000_000;
            let wc = trajectory.world_from_vehicle(stamp_nanos).unwrap() * vehicle_from_camera;
            let mut rgb = Vec::new();
            for y in 0..48 {
                for x in 0..64 {
                    let u = intrinsics
                        .unproject(DVec2::new(x as f64, y as f64))
                        .unwrap();
                    let (o, d) = (wc.translation, wc.rotation * u);
                    let c = if d.z < -1e-3 {
                        let p = o + d * (-o.z / d.z);
                        let cell = (p.x.floor() as i64 + p.y.floor() as i64).rem_euclid(3);
                        [[200u8, 60, 40], [40, 160, 70], [60, 70, 200]][cell as usize]
                    } else {
                        [150, 190, 230]
                    };
                    rgb.extend_from_slice(&c);
                }
            }
            CameraFrame {
                stamp_nanos,
                rgb,
                keypoints: Vec::new(),
                masked: Vec::new(),
            }
        })
        .collect();
    CameraData {
        name: "camera".into(),
        initial: vehicle_from_camera,
        intrinsics,
        frames,
        readout: RowTimes::GLOBAL,
    }
}

/// Coarse-to-fine sampling (§10): uniform before the start, then σ shrinks geometrically
/// from 40 to 5 px (at 1920 wide), and heat-map draws land near the keypoints.
/// Cameras join: the colour loss falls, the camera's pose is
/// reported with the LiDAR's, and the run stays deterministic.
#[test]
fn the_colour_term_learns_the_cameras_view_deterministically() {
    let (trajectory, mount, sweeps) = flat_drive();
    let camera = ground_camera(&trajectory);
    let run = || {
        let mut c = DepthCalibration::new(
            small_config(),
            trajectory.clone(),
            vec![LidarData {
                name: "lidar".into(),
                initial: mount,
                sweeps: sweeps.clone(),
            }],
        )
        .with_cameras(vec![camera.clone()]);
        let reports: Vec<DepthReport> = (0..40).map(|_| c.step()).collect();
        (reports, c.extrinsics())
    };
    let (a, ea) = run();
    let first = a[0].colour_loss;
    let last: f64 = a[35..].iter().map(|r| r.colour_loss).sum::<f64>() / 5.0;
    // 40 steps learn the view's mean colour and exposure (0.26 -> ~0.17); the blocks'
    // texture follows once the surface has formed (~150 steps: 0.12 at 190 in a release run).
    assert!(
        first > 0.0 && last < 0.75 * first,
        "colour loss {first} -> {last}"
    );
    assert_eq!(ea.len(), 2);
    assert_eq!(ea[1].0, "camera");
    assert!(ea[1].1.translation.is_finite());
    let (b, eb) = run();
    assert_eq!(
        a.last().map(|r| r.colour_loss),
        b.last().map(|r| r.colour_loss)
    );
    assert_eq!(ea, eb);
}

/// A calibration of one LiDAR, named `lidar`, mounted at `mount`.
fn one_lidar(
    config: DepthCalibConfig,
    trajectory: &Trajectory,
    mount: Rigid,
    sweeps: Vec<LidarSweep>,
) -> DepthCalibration {
    DepthCalibration::new(
        config,
        trajectory.clone(),
        vec![LidarData {
            name: "lidar".into(),
            initial: mount,
            sweeps,
        }],
    )
}

/// The shared translation changes where the free cameras go and leaves a held one alone.
#[test]
fn a_shared_translation_moves_only_the_free_cameras() {
    let (trajectory, mount, sweeps) = flat_drive();
    let camera = ground_camera(&trajectory);
    let run = |shared: bool| {
        let config = DepthCalibConfig {
            shared_camera_translation: shared,
            held_sensors: vec!["held".into()],
            ..small_config()
        };
        let cameras = ["camera", "second", "held"].map(|name| CameraData {
            name: name.into(),
            ..camera.clone()
        });
        let mut c =
            one_lidar(config, &trajectory, mount, sweeps.clone()).with_cameras(cameras.to_vec());
        for _ in 0..12 {
            c.step();
        }
        c.extrinsics()
    };
    let (with, without) = (run(true), run(false));
    for extrinsics in [&with, &without] {
        assert_eq!(extrinsics[3].0, "held");
        let held = extrinsics[3].1;
        assert_eq!(
            held.translation, camera.initial.translation,
            "a held camera stays"
        );
        assert!(held.rotation.angle_between(camera.initial.rotation) < 1e-9);
        assert_ne!(extrinsics[1].1, camera.initial, "a free camera moves");
    }
    for k in [1, 2] {
        let gap = (with[k].1.translation - without[k].1.translation).length();
        assert!(gap > 1e-9, "camera {k}: the shared step moved it ({gap} m)");
    }
}

/// A restart keeps every sensor where it got to and the data, and starts the scene and the
/// schedule afresh: the next step renders exactly what a new calibration started at those
/// extrinsics renders.
#[test]
fn a_restart_keeps_the_extrinsics_and_starts_a_fresh_scene() {
    let (trajectory, mount, sweeps) = flat_drive();
    let camera = ground_camera(&trajectory);
    let lidar = LidarData {
        name: "lidar".into(),
        initial: mount,
        sweeps,
    };
    let mut c = DepthCalibration::new(small_config(), trajectory.clone(), vec![lidar.clone()])
        .with_cameras(vec![camera.clone()]);
    for _ in 0..10 {
        c.step();
    }
    let reached = c.extrinsics();
    assert_ne!(
        reached[1].1, camera.initial,
        "the camera moved in the first round"
    );
    c.restart();
    for ((_, now), (_, before)) in c.extrinsics().iter().zip(&reached) {
        let (rot, trans) = now.difference(*before);
        assert!(rot < 1e-12 && trans < 1e-12, "{rot} {trans}");
    }
    assert_eq!(c.iteration, 0);
    let mut fresh = DepthCalibration::new(
        small_config(),
        trajectory,
        vec![LidarData {
            initial: reached[0].1,
            ..lidar
        }],
    )
    .with_cameras(vec![CameraData {
        initial: reached[1].1,
        ..camera
    }]);
    assert_eq!(c.field.grid.params, fresh.field.grid.params);
    let (a, b) = (c.step(), fresh.step());
    assert_eq!(a, b);
    assert_eq!(c.extrinsics(), fresh.extrinsics());
}

/// A LiDAR 2 m above flat ground on a straight drive: the depth loss falls, the pose stays
/// finite and the run is deterministic for a seed.
#[test]
fn steps_reduce_the_depth_loss_deterministically() {
    let (trajectory, mount, sweeps) = flat_drive();
    let config = small_config();
    let run = || {
        let mut c = DepthCalibration::new(
            config.clone(),
            trajectory.clone(),
            vec![LidarData {
                name: "lidar".into(),
                initial: mount,
                sweeps: sweeps.clone(),
            }],
        );
        let reports: Vec<DepthReport> = (0..40).map(|_| c.step()).collect();
        (reports, c.extrinsics())
    };
    let (a, ea) = run();
    let first: f64 = a[..5].iter().map(|r| r.mean_abs_error_m).sum::<f64>() / 5.0;
    let last: f64 = a[35..].iter().map(|r| r.mean_abs_error_m).sum::<f64>() / 5.0;
    assert!(last < 0.5 * first, "range error {first} -> {last}");
    assert!(ea[0].1.translation.is_finite());
    // Same thread count, same seed: same result.
    let (b, eb) = run();
    assert_eq!(a.last().map(|r| r.loss), b.last().map(|r| r.loss));
    assert_eq!(ea, eb);
}

/// Two LiDARs with intensity: the intensity loss falls, the regulariser is reported, and a
/// frozen root keeps its extrinsic exactly while the other sensor moves.
#[test]
fn intensity_and_regulariser_join_and_a_frozen_root_stays_put() {
    let (trajectory, mount, sweeps) = flat_drive();
    let config = DepthCalibConfig {
        frozen_sensor: Some("lidar".into()),
        intensity_weight: 1.0,
        ..small_config()
    };
    // The second LiDAR sees the same returns from the same mount, but starts 5 cm off.
    let second_initial = Rigid::from_translation(mount.translation + DVec3::new(0.05, 0.0, 0.0));
    let mut c = DepthCalibration::new(
        config,
        trajectory,
        vec![
            LidarData {
                name: "lidar".into(),
                initial: mount,
                sweeps: sweeps.clone(),
            },
            LidarData {
                name: "second".into(),
                initial: second_initial,
                sweeps,
            },
        ],
    );
    assert!(c.has_intensity());
    let reports: Vec<DepthReport> = (0..40).map(|_| c.step()).collect();
    let first: f64 = reports[..5].iter().map(|r| r.intensity_loss).sum::<f64>() / 5.0;
    let last: f64 = reports[35..].iter().map(|r| r.intensity_loss).sum::<f64>() / 5.0;
    assert!(last < 0.5 * first, "intensity loss {first} -> {last}");
    assert!(reports.iter().all(|r| r.regulariser_loss.is_finite()));
    assert!(reports.iter().any(|r| r.regulariser_loss > 0.0));
    let e = c.extrinsics();
    assert_eq!(e[0].1.translation, mount.translation);
    assert_eq!(
        e[0].1.rotation,
        PoseParams::from_rigid(mount).to_rigid().rotation
    );
    assert_ne!(e[1].1.translation, second_initial.translation);
    assert_eq!(c.intensity_maps().len(), 2);
}

/// The geometry initialisation puts the surface where the returns are: the first rendered
/// depth after it is far closer than from the empty initial scene, and poses stay fixed.
#[test]
fn geometry_initialisation_places_the_surface_before_rendering() {
    let (trajectory, mount, sweeps) = flat_drive();
    let lidar = LidarData {
        name: "lidar".into(),
        initial: mount,
        sweeps,
    };
    let first_render_error = |init_steps: usize| {
        let config = DepthCalibConfig {
            geometry_init_steps: init_steps,
            geometry_init_rays: 1024,
            ..small_config()
        };
        let mut c = DepthCalibration::new(config, trajectory.clone(), vec![lidar.clone()]);
        for _ in 0..init_steps {
            let r = c.step();
            assert!(r.geometry_init_loss.is_some_and(f64::is_finite));
        }
        assert!(!c.initialising_geometry());
        assert_eq!(
            c.extrinsics()[0].1,
            PoseParams::from_rigid(mount).to_rigid()
        );
        let r = c.step();
        assert!(r.geometry_init_loss.is_none());
        r.mean_abs_error_m
    };
    let (cold, warm) = (first_render_error(0), first_render_error(30));
    assert!(warm < 0.15 * cold && warm < 1.0, "{cold} m -> {warm} m");
}
