#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Probe of UniCal's LiDAR pose gradients on a simulated drive: the scene is first learned with
//! both LiDARs at the ground truth, then the PandarGT is perturbed and only its pose (and, with
//! `joint`, the scene) is optimised while the Pandar64 stays frozen. A scene that is frozen
//! separates "the pose gradient points the wrong way" from "the scene co-adapts to the error".
//! `cargo run --release --example unical_probe -- [SCENE_STEPS] [POSE_STEPS] [frozen|joint|rounds] [SECONDS] [LR_POSE]`
//! (`rounds`: `PROBE_ROUNDS` alternations of a scene learned from scratch at the current pose
//! and preconditioned pose steps against it, from a 1° / 9 cm PandarGT start; with
//! `PROBE_ROOT_SCENE` only the Pandar64 shapes each round's scene; with `PROBE_SHARED` the
//! PandarGT's rows are kept only on surfaces the Pandar64 returns from.)

mod common;

use glam::DVec3;
use rigcal::unical::depth_calib::{DepthCalibConfig, DepthCalibration};
use rigcal::unical::pose::PoseParams;
use rigcal::unical::pose_newton::{NewtonConfig, PoseUpdate};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene_steps: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(300);
    let pose_steps: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(200);
    let joint = args.get(3).is_some_and(|s| s == "joint");
    let seconds: f64 = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(3.0);
    let lr_pose: f32 = args.get(5).and_then(|s| s.parse().ok()).unwrap_or(1e-3);
    let (rig, traj, world) = common::drive(seconds);
    let lidars = common::lidars_at_truth(&world, &rig, &traj, seconds);
    let truth: Vec<_> = rig.lidars.iter().map(|l| l.vehicle_from_lidar).collect();
    let root = rig.lidars[0].name.clone();
    let config = DepthCalibConfig {
        iterations: if std::env::var("PROBE_NODECAY").is_ok() {
            1_000_000
        } else {
            scene_steps + pose_steps
        },
        pose_warmup: scene_steps,
        frozen_sensor: Some(root),
        lr_pose,
        lidar_pose_update: if std::env::var("PROBE_ADAM").is_ok() {
            PoseUpdate::Adam
        } else {
            let env = |k: &str, d: f64| {
                std::env::var(k)
                    .ok()
                    .and_then(|v| v.parse().ok())
                    .unwrap_or(d)
            };
            let n = NewtonConfig::default();
            PoseUpdate::Newton(NewtonConfig {
                step: env("PROBE_STEP", n.step),
                damping: env("PROBE_DAMP", n.damping),
                interval: env("PROBE_INTERVAL", n.interval as f64) as usize,
                max_translation_m: env("PROBE_MAXT", n.max_translation_m),
                max_rotation_rad: env("PROBE_MAXR", n.max_rotation_rad.to_degrees()).to_radians(),
                ..n
            })
        },
        opacity: common::opacity_from_env(DepthCalibConfig::default().opacity),
        ..DepthCalibConfig::default()
    };
    if args.get(3).is_some_and(|s| s == "rounds") {
        // Alternation with scene restarts: learn a scene from scratch with the current
        // PandarGT pose (poses fixed), register the PandarGT to that frozen scene by
        // preconditioned steps, start the next round's scene from the result. Tests whether a
        // scene learned with the error still pulls the pose towards the truth, and how fast.
        let rounds: usize = std::env::var("PROBE_ROUNDS")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(4);
        // PROBE_START_SCALE scales the start's perturbation (0: from the truth).
        let start_scale: f64 = std::env::var("PROBE_START_SCALE")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(1.0);
        let mut current = truth[1].perturbed_right(
            DVec3::new(0.6, -0.5, 0.6) * start_scale.to_radians(),
            DVec3::new(0.06, -0.05, 0.05) * start_scale,
        );
        let newton = NewtonConfig {
            step: 1.0,
            interval: 1,
            robust_scale: 3.0,
            robust_floor_m: 0.02,
            ..NewtonConfig::default()
        };
        // PROBE_SHARED: the PandarGT's rows only where the Pandar64 has returns (0.5 m voxels
        // of its points under its true pose, dilated by one).
        let voxel = |p: DVec3| {
            let v = (p / 0.5).floor();
            [v.x as i32, v.y as i32, v.z as i32]
        };
        let cover: Option<rigcal::util::FastSet<[i32; 3]>> =
            std::env::var("PROBE_SHARED").is_ok().then(|| {
                let mut cover = rigcal::util::FastSet::default();
                for sweep in &lidars[0].sweeps {
                    let Ok(world_from_vehicle) = traj.world_from_vehicle(sweep.stamp_nanos) else {
                        continue;
                    };
                    let world_from_lidar = world_from_vehicle * truth[0];
                    for p in &sweep.points_in_sensor {
                        let v = voxel(world_from_lidar.transform_point(DVec3::new(
                            p[0] as f64,
                            p[1] as f64,
                            p[2] as f64,
                        )));
                        for dx in -1..=1 {
                            for dy in -1..=1 {
                                for dz in -1..=1 {
                                    cover.insert([v[0] + dx, v[1] + dy, v[2] + dz]);
                                }
                            }
                        }
                    }
                }
                cover
            });
        let t0 = std::time::Instant::now();
        // The PandarGT's error and its translation's components, and the time so far.
        let describe = |current: rigcal::geometry::Rigid| {
            let (er, et) = truth[1].difference(current);
            let dt = (current.translation - truth[1].translation) * 100.0;
            format!(
                "{:.3}° {:.2} cm (vehicle x {:.2} y {:.2} z {:.2} cm) · {:.0} s",
                er.to_degrees(),
                et * 100.0,
                dt.x,
                dt.y,
                dt.z,
                t0.elapsed().as_secs_f64()
            )
        };
        for round in 0..rounds {
            eprintln!("round {round}: start {}", describe(current));
            let mut lidars = lidars.clone();
            lidars[1].initial = current;
            let round_config = DepthCalibConfig {
                iterations: scene_steps + 1,
                pose_warmup: scene_steps + 1,
                lidar_pose_update: PoseUpdate::Newton(newton),
                // PROBE_ROOT_SCENE: only the Pandar64 shapes the scene (the PandarGT only clears
                // free space), so the scene carries no PandarGT error.
                registration_steps: if std::env::var("PROBE_ROOT_SCENE").is_ok() {
                    usize::MAX / 2
                } else {
                    0
                },
                ..config.clone()
            };
            let mut calib = DepthCalibration::new(round_config, traj.clone(), lidars);
            for _ in 0..scene_steps {
                calib.step();
            }
            let state = rigcal::unical::pose_newton::NewtonState::new(newton);
            let mut pose = PoseParams::from_rigid(current);
            for _ in 0..pose_steps {
                calib.poses[1] = pose;
                let rays = calib.lidar_batch(1, 2048);
                let (_, _, system) = calib.lidar_objective_where(1, &pose, &rays, |r| {
                    cover
                        .as_ref()
                        .is_none_or(|c| c.contains(&voxel(r.surface_world)))
                });
                state.solve_and_apply(&mut pose, &system, 1.0);
            }
            current = pose.to_rigid();
        }
        eprintln!("end: {}", describe(current));
        return;
    }
    let mut calib = DepthCalibration::new(config, traj, lidars);
    let t0 = std::time::Instant::now();
    let report = |calib: &DepthCalibration, it: usize, loss: f64, mae: f64, beta: f32| {
        let errs: Vec<String> = calib
            .extrinsics()
            .iter()
            .zip(&truth)
            .map(|((n, e), t)| {
                let (r, d) = t.difference(*e);
                format!("{n} {:.3}° {:.2} cm", r.to_degrees(), d * 100.0)
            })
            .collect();
        eprintln!(
            "it {it:4} loss {loss:.4} |err| {mae:.3} m β {beta:.1} · {} · {:.1} s",
            errs.join(" · "),
            t0.elapsed().as_secs_f64()
        );
    };
    for it in 0..scene_steps {
        let r = calib.step();
        if it % 50 == 0 && r.geometry_init_loss.is_none() {
            report(&calib, it, r.loss, r.mean_abs_error_m, r.beta);
        }
    }
    if args.get(3).is_some_and(|s| s == "fd") {
        // The assembled pose gradient against central differences of the batch objective, at
        // the truth and 5 cm off along each vehicle axis.
        let rays = calib.lidar_batch(1, 4000);
        for offset in [
            DVec3::ZERO,
            DVec3::X * 0.05,
            DVec3::Y * 0.05,
            DVec3::Z * 0.05,
        ] {
            let mut at = PoseParams::from_rigid(truth[1]);
            at.translation_m += offset;
            let (loss, g, _) = calib.lidar_objective(1, &at, &rays);
            let mut fd = [0.0; 3];
            for k in 0..3 {
                let (mut up, mut down) = (at, at);
                up.translation_m[k] += 1e-3;
                down.translation_m[k] -= 1e-3;
                fd[k] = (calib.lidar_objective(1, &up, &rays).0
                    - calib.lidar_objective(1, &down, &rays).0)
                    / 2e-3;
            }
            eprintln!(
                "offset {offset:?}: loss {loss:.5} analytic {:?} fd {fd:?}",
                g.translation_m
            );
        }
        return;
    }
    if args.get(3).is_some_and(|s| s == "newton") {
        // Preconditioned steps against the frozen scene from one start, for several kernels.
        let start = PoseParams::from_rigid(truth[1].perturbed_right(
            DVec3::new(0.6, -0.5, 0.6) * 1f64.to_radians(),
            DVec3::new(0.06, -0.05, 0.05),
        ));
        for (k, floor) in [(3.0, 0.02), (10.0, 0.1), (30.0, 0.5), (1e12, 1e12)] {
            let config = NewtonConfig {
                step: 1.0,
                interval: 1,
                robust_scale: k,
                robust_floor_m: floor,
                ..NewtonConfig::default()
            };
            calib.config.lidar_pose_update = PoseUpdate::Newton(config);
            let state = rigcal::unical::pose_newton::NewtonState::new(config);
            let mut pose = start;
            for it in 0..=40 {
                if it % 5 == 0 {
                    let (er, et) = truth[1].difference(pose.to_rigid());
                    let e = pose.translation_m - truth[1].translation;
                    eprintln!(
                        "kernel {k} floor {floor}: it {it} error {:.3}° {:.2} cm ({:.2} {:.2} {:.2})",
                        er.to_degrees(),
                        et * 100.0,
                        e.x * 100.0,
                        e.y * 100.0,
                        e.z * 100.0
                    );
                }
                calib.poses[1] = pose;
                let rays = calib.lidar_batch(1, 2048);
                let (_, _, system) = calib.lidar_objective(1, &pose, &rays);
                state.solve_and_apply(&mut pose, &system, 1.0);
            }
        }
        return;
    }
    if args.get(3).is_some_and(|s| s == "normals") {
        // The learned scene against the simulator's true surfaces, at the true pose.
        let rays = calib.lidar_batch(1, 3000);
        let pose = calib.poses[1];
        let mut scratch = calib.field.geo.zero_grad();
        let (mut grad_norm, mut angle, mut dist, mut signed) = (vec![], vec![], vec![], vec![]);
        let mut fd_angle: Vec<Vec<f64>> = vec![vec![]; 5];
        for ray in &rays {
            let c = rigcal::unical::lidar_terms::render_composite(
                &calib.field,
                calib.opacity(),
                &pose,
                ray,
            );
            if c.accumulation <= 0.5 {
                continue;
            }
            let (o, d) = pose.ray(ray.world_from_vehicle, ray.dir_in_sensor);
            let Some(hit) = world.trace(o.as_vec3(), d.as_vec3(), 300.0) else {
                continue;
            };
            let depth = (c.depth_m / c.accumulation) as f64;
            let q = calib.field.query(o + d * depth);
            let g = calib.field.backward(
                &q,
                1.0,
                &[],
                &mut None::<rigcal::unical::hash_grid::SparseGrad>,
                &mut scratch,
            );
            grad_norm.push(g.length());
            let n = hit.normal.as_dvec3();
            angle.push(
                g.normalize_or_zero()
                    .dot(n)
                    .abs()
                    .clamp(0.0, 1.0)
                    .acos()
                    .to_degrees(),
            );
            let p = o + d * depth;
            for (k, h) in [0.02, 0.05, 0.1, 0.2, 0.4].iter().enumerate() {
                let sdf = |x: DVec3| calib.field.query(x).sdf() as f64;
                let fd = DVec3::new(
                    sdf(p + DVec3::X * *h) - sdf(p - DVec3::X * *h),
                    sdf(p + DVec3::Y * *h) - sdf(p - DVec3::Y * *h),
                    sdf(p + DVec3::Z * *h) - sdf(p - DVec3::Z * *h),
                );
                fd_angle[k].push(
                    fd.normalize_or_zero()
                        .dot(n)
                        .abs()
                        .clamp(0.0, 1.0)
                        .acos()
                        .to_degrees(),
                );
            }
            dist.push((depth - hit.t as f64).abs());
            signed.push(depth - ray.range_m as f64);
        }
        let q = |v: &mut Vec<f64>, p: f64| {
            v.sort_by(f64::total_cmp);
            v[((v.len() - 1) as f64 * p) as usize]
        };
        for (name, v) in [
            ("|grad s|", &mut grad_norm),
            ("normal angle °", &mut angle),
            ("|D/A − true hit| m", &mut dist),
            ("D/A − range m", &mut signed),
        ] {
            eprintln!(
                "{name}: p10 {:.3} p25 {:.3} median {:.3} p75 {:.3} p90 {:.3}",
                q(v, 0.1),
                q(v, 0.25),
                q(v, 0.5),
                q(v, 0.75),
                q(v, 0.9)
            );
        }
        for (h, v) in [0.02, 0.05, 0.1, 0.2, 0.4].iter().zip(fd_angle.iter_mut()) {
            eprintln!(
                "FD normal h {h} m, angle °: p10 {:.3} p25 {:.3} median {:.3} p75 {:.3} p90 {:.3}",
                q(v, 0.1),
                q(v, 0.25),
                q(v, 0.5),
                q(v, 0.75),
                q(v, 0.9)
            );
        }
        return;
    }
    if args.get(3).is_some_and(|s| s == "bias") {
        for s in 0..2 {
            let mut signed: Vec<f32> = calib
                .depth_residuals(s, 8000)
                .iter()
                .map(|r| r.error_m)
                .collect();
            signed.sort_by(f32::total_cmp);
            let q = |p: f64| signed[((signed.len() - 1) as f64 * p) as usize];
            eprintln!(
                "lidar {s}: signed error p10 {:.4} p25 {:.4} median {:.4} p75 {:.4} p90 {:.4} m",
                q(0.1),
                q(0.25),
                q(0.5),
                q(0.75),
                q(0.9)
            );
        }
        return;
    }
    if args.get(3).is_some_and(|s| s == "landscape") {
        // The depth loss of the frozen scene with the PandarGT moved along each vehicle axis.
        calib.config.lr_field = 0.0;
        calib.config.lr_pose = 0.0;
        for axis in 0..3 {
            for delta_cm in [-20.0, -10.0, -5.0, 0.0, 5.0, 10.0, 20.0] {
                let mut moved = truth[1];
                moved.translation[axis] += delta_cm / 100.0;
                calib.poses[1] = PoseParams::from_rigid(moved);
                let (mut loss, mut mae, mut median) = (0.0, 0.0, Vec::new());
                for _ in 0..4 {
                    let r = calib.step();
                    loss += r.loss / 4.0;
                    mae += r.mean_abs_error_m / 4.0;
                }
                for res in calib.depth_residuals(1, 4000) {
                    median.push(res.error_m.abs());
                }
                median.sort_by(f32::total_cmp);
                let q = |p: f64| median[((median.len() - 1) as f64 * p) as usize];
                eprintln!(
                    "axis {axis} δ {delta_cm:5.1} cm: loss {loss:.4} |err| {mae:.4} m · pandar_gt |err| median {:.4} p25 {:.4} p75 {:.4} m",
                    q(0.5),
                    q(0.25),
                    q(0.75)
                );
            }
        }
        return;
    }
    // Perturb the second LiDAR by ≈ 1° and 9 cm.
    calib.poses[1] = PoseParams::from_rigid(truth[1].perturbed_right(
        DVec3::new(0.6, -0.5, 0.6) * 1f64.to_radians(),
        DVec3::new(0.06, -0.05, 0.05),
    ));
    if !joint {
        calib.config.lr_field = 0.0;
    }
    if let Some(n) = std::env::var("PROBE_RAYS")
        .ok()
        .and_then(|v| v.parse().ok())
    {
        calib.config.rays_per_sensor = n;
    }
    if std::env::var("PROBE_DEPTH_ONLY").is_ok() {
        calib.config.intensity_weight = 0.0;
        calib.config.regulariser_weight = 0.0;
    }
    let pin_rotation = std::env::var("PROBE_PIN_ROTATION").is_ok();
    let true_r6 = PoseParams::from_rigid(truth[1]).r6;
    if pin_rotation {
        calib.poses[1].r6 = true_r6;
    }
    for it in scene_steps..scene_steps + pose_steps {
        let r = calib.step();
        if pin_rotation {
            calib.poses[1].r6 = true_r6;
        }
        if it % 10 == 0 || it + 1 == scene_steps + pose_steps {
            report(&calib, it, r.loss, r.mean_abs_error_m, r.beta);
            let e = calib.poses[1].translation_m - truth[1].translation;
            eprintln!(
                "    translation error (vehicle) {:.2} {:.2} {:.2} cm",
                e.x * 100.0,
                e.y * 100.0,
                e.z * 100.0
            );
        }
    }
}
