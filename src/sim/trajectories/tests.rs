//! Tests of the trajectory shapes: rates, smoothness, headings, seeds, each shape's geometry and the road under it.

use super::*;
use crate::geometry::so3;

fn config(kind: TrajectoryKind, duration_secs: f64, seed: u64) -> TrajectoryConfig {
    TrajectoryConfig {
        kind,
        duration_secs,
        seed,
        ..TrajectoryConfig::default()
    }
}

fn moving_kinds() -> impl Iterator<Item = TrajectoryKind> {
    TrajectoryKind::ALL
        .into_iter()
        .filter(|k| *k != TrajectoryKind::Stationary)
}

fn yaw(pose: &Rigid) -> f64 {
    let x = pose.rotation * DVec3::X;
    x.y.atan2(x.x)
}

fn wrap(angle: f64) -> f64 {
    (angle + PI).rem_euclid(TAU) - PI
}

#[test]
fn names_round_trip() {
    for kind in TrajectoryKind::ALL {
        assert_eq!(kind.as_str().parse::<TrajectoryKind>(), Ok(kind));
        assert_eq!(kind.to_string(), kind.as_str());
        let yaml = serde_yaml::to_string(&kind).unwrap();
        assert_eq!(yaml.trim(), kind.as_str());
    }
    assert_eq!("S_Curve".parse(), Ok(TrajectoryKind::SCurve));
    let err = "zigzag".parse::<TrajectoryKind>().unwrap_err().to_string();
    assert!(err.contains("zigzag") && err.contains("figure8"), "{err}");
}

#[test]
fn samples_at_the_requested_rate() {
    for (rate, duration) in [(100.0, 3.0), (250.0, 1.0), (10.0, 2.0), (100.0, 0.0)] {
        let cfg = TrajectoryConfig {
            rate_hz: rate,
            ..config(TrajectoryKind::Circle, duration, 1)
        };
        let poses = generate(&cfg);
        let rate = f64::max(rate, MIN_RATE_HZ);
        assert_eq!(poses.len(), (duration * rate).round() as usize + 1);
        assert_eq!(poses[0].0, 0);
        let last = poses.last().unwrap().0;
        assert!((last as f64 - duration * 1e9).abs() < 1.0, "{last}");
        for pair in poses.windows(2) {
            let dt = (pair[1].0 - pair[0].0) as f64;
            assert!((dt - 1e9 / rate).abs() <= 1.0, "{dt}");
        }
    }
}

/// Speed, acceleration, yaw rate and yaw acceleration from finite differences.
#[test]
fn motion_is_smooth_and_drivable() {
    for kind in moving_kinds() {
        for seed in [0, 7, 1234] {
            let poses = generate(&config(kind, 60.0, seed));
            let dt = 0.01;
            let speeds: Vec<f64> = poses
                .windows(2)
                .map(|w| (w[1].1.translation - w[0].1.translation).length() / dt)
                .collect();
            let yaw_rates: Vec<f64> = poses
                .windows(2)
                .map(|w| {
                    let delta = so3::log(w[0].1.rotation.conjugate() * w[1].1.rotation);
                    delta.z / dt
                })
                .collect();
            let what = format!("{kind} seed {seed}");
            assert!(
                speeds[0] > 3.0 && speeds[0] < 5.0,
                "{what}: rolling start {}",
                speeds[0]
            );
            for w in speeds.windows(2) {
                assert!((w[1] - w[0]).abs() / dt < 2.5, "{what}: acceleration");
            }
            assert!(speeds.iter().all(|&v| v > 3.0 && v < 9.5), "{what}: speed");
            for w in yaw_rates.windows(2) {
                assert!((w[1] - w[0]).abs() / dt < 1.2, "{what}: yaw acceleration");
            }
            let max_rate = yaw_rates.iter().fold(0.0_f64, |m, r| m.max(r.abs()));
            assert!(
                max_rate <= MAX_YAW_RATE + 1e-3,
                "{what}: yaw rate {max_rate}"
            );
            // Radius of the tightest turn.
            let tightest = speeds
                .iter()
                .zip(&yaw_rates)
                .map(|(v, w)| v / w.abs().max(1e-9))
                .fold(f64::INFINITY, f64::min);
            assert!(tightest >= 12.0, "{what}: radius {tightest}");
            // Flat ground, upright vehicle.
            for (_, pose) in &poses {
                assert!(pose.translation.z.abs() < 1e-12);
                assert!((pose.rotation * DVec3::Z - DVec3::Z).length() < 1e-12);
            }
        }
    }
}

#[test]
fn heading_is_tangent_to_the_path() {
    for kind in moving_kinds() {
        let poses = generate(&config(kind, 30.0, 3));
        for w in poses.windows(3) {
            let velocity = w[2].1.translation - w[0].1.translation;
            let direction = velocity.y.atan2(velocity.x);
            let error = wrap(direction - yaw(&w[1].1)).abs();
            assert!(error < 1e-4, "{kind}: side-slip {error} rad");
        }
    }
}

#[test]
fn same_seed_same_drive() {
    for kind in TrajectoryKind::ALL {
        let a = generate(&config(kind, 5.0, 42));
        assert_eq!(a, generate(&config(kind, 5.0, 42)));
        assert_eq!(
            path_polyline(&config(kind, 5.0, 42), 1.0),
            path_polyline(&config(kind, 5.0, 42), 1.0)
        );
        if kind != TrajectoryKind::Stationary {
            assert_ne!(a, generate(&config(kind, 5.0, 43)), "{kind}");
        }
    }
}

#[test]
fn stays_near_the_origin() {
    for kind in TrajectoryKind::ALL {
        for (speed, seed) in [(8.0, 0), (8.0, 99), (4.0, 5), (15.0, 11), (30.0, 2)] {
            let cfg = TrajectoryConfig {
                speed_mps: speed,
                ..config(kind, 60.0, seed)
            };
            let poses = generate(&cfg);
            let road = path_polyline(&cfg, 2.0);
            for p in poses.iter().map(|(_, p)| p.translation).chain(road) {
                assert!(
                    p.x.abs() <= 120.0 && p.y.abs() <= 120.0,
                    "{kind} at {speed}: {p}"
                );
            }
            // Fast requests are slowed down for the curves, not driven off them.
            let dt = 0.01;
            for w in poses.windows(2) {
                let v = (w[1].1.translation - w[0].1.translation).length() / dt;
                let rate = so3::angle_rad(w[0].1.rotation.conjugate() * w[1].1.rotation) / dt;
                assert!(rate <= MAX_YAW_RATE + 1e-3, "{kind} at {speed}: {rate}");
                assert!(
                    v * rate <= MAX_LATERAL_ACCEL + 0.05,
                    "{kind} at {speed}: {}",
                    v * rate
                );
            }
        }
    }
}

#[test]
fn circle_closes_after_a_lap() {
    let poses = generate(&config(TrajectoryKind::Circle, 40.0, 5));
    let start = poses[0].1;
    // After the first few seconds, the closest return to the start is within one sample.
    let (index, distance) = poses
        .iter()
        .enumerate()
        .skip(500)
        .map(|(i, (_, p))| (i, (p.translation - start.translation).length()))
        .fold(
            (0, f64::INFINITY),
            |best, c| if c.1 < best.1 { c } else { best },
        );
    assert!(distance < 0.1, "{distance}");
    let returned = poses[index].1;
    assert!(wrap(yaw(&returned) - yaw(&start)).abs() < 0.01);
    // The circle has a radius near 25 m and is centred on the origin.
    for (_, p) in &poses {
        let r = p.translation.truncate().length();
        assert!((r - 25.0).abs() < 1.5, "{r}");
    }
}

/// Whether segments p0-p1 and q0-q1 cross.
fn crosses(p0: DVec2, p1: DVec2, q0: DVec2, q1: DVec2) -> bool {
    let side = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - a);
    side(p0, p1, q0) * side(p0, p1, q1) < 0.0 && side(q0, q1, p0) * side(q0, q1, p1) < 0.0
}

fn self_crossings(poses: &[(i64, Rigid)]) -> usize {
    let points: Vec<DVec2> = poses
        .iter()
        .step_by(10)
        .map(|(_, p)| p.translation.truncate())
        .collect();
    let mut count = 0;
    for i in 0..points.len() - 1 {
        for j in i + 20..points.len() - 1 {
            if crosses(points[i], points[i + 1], points[j], points[j + 1]) {
                count += 1;
            }
        }
    }
    count
}

#[test]
fn figure8_crosses_itself_and_turns_both_ways() {
    let poses = generate(&config(TrajectoryKind::Figure8, 60.0, 8));
    assert!(self_crossings(&poses) >= 1);
    let turns: Vec<f64> = poses
        .windows(2)
        .map(|w| so3::log(w[0].1.rotation.conjugate() * w[1].1.rotation).z)
        .collect();
    assert!(turns.iter().any(|&w| w > 0.003) && turns.iter().any(|&w| w < -0.003));
    // Lobes of ~25 m radius on either side of the origin along x.
    let xs = poses.iter().map(|(_, p)| p.translation.x);
    let (min, max) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    assert!(min < -40.0 && max > 40.0, "{min} {max}");
}

#[test]
fn flower_has_three_petals_round_a_centre() {
    let cfg = config(TrajectoryKind::Flower, 60.0, 2);
    let poses = generate(&cfg);
    assert!(self_crossings(&poses) >= 1);
    // Distance from the centre rises and falls once per petal: three petals a lap.
    let road = path_polyline(&config(TrajectoryKind::Flower, 120.0, 2), 1.0);
    assert_eq!(road.first(), road.last(), "a full lap");
    let r: Vec<f64> = road.iter().map(|p| p.truncate().length()).collect();
    let peaks = (1..r.len() - 1)
        .filter(|&i| r[i] > r[i - 1] && r[i] >= r[i + 1] && r[i] > 30.0)
        .count();
    assert_eq!(peaks, 3);
    // The path passes through the centre between petals.
    assert!(r.iter().cloned().fold(f64::INFINITY, f64::min) < 1.0);
}

#[test]
fn s_curve_bends_left_then_right() {
    let poses = generate(&config(TrajectoryKind::SCurve, 16.0, 4));
    let yaws: Vec<f64> = poses.iter().map(|(_, p)| yaw(p)).collect();
    let (first, last) = (yaws[0], *yaws.last().unwrap_or(&0.0));
    assert!(
        first.abs() < 1e-6 && last.abs() < 1e-6,
        "straight in, straight out"
    );
    let max = yaws.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    assert!(max > 1.0, "{max}");
    let peak = yaws.iter().position(|&y| y == max).unwrap_or(0);
    // After the left bend the heading swings back through zero to the right... and back to
    // straight, offset sideways.
    assert!(yaws[peak..].iter().any(|&y| y < 0.3));
    let shift = poses.last().unwrap().1.translation.y - poses[0].1.translation.y;
    assert!(shift > 20.0, "{shift}");
}

#[test]
fn straight_is_straight_and_centred() {
    let poses = generate(&config(TrajectoryKind::Straight, 15.0, 6));
    for (_, p) in &poses {
        assert!(p.translation.y.abs() < 1e-9 && yaw(p).abs() < 1e-12);
    }
    let (a, b) = (
        poses[0].1.translation.x,
        poses.last().unwrap().1.translation.x,
    );
    assert!(a < -40.0 && b > 40.0 && (a + b).abs() < 1.0, "{a} {b}");
}

#[test]
fn short_straight_drives_keep_their_speed() {
    let cfg = TrajectoryConfig {
        speed_mps: 25.0,
        ..config(TrajectoryKind::Straight, 6.0, 1)
    };
    let poses = generate(&cfg);
    let last = &poses[poses.len() - 2..];
    let v = (last[1].1.translation - last[0].1.translation).length() / 0.01;
    assert!(v > 22.0, "{v}");
    assert!(poses.iter().all(|(_, p)| p.translation.y.abs() < 1e-9));
}

#[test]
fn stationary_stands_still() {
    let cfg = config(TrajectoryKind::Stationary, 5.0, 9);
    let poses = generate(&cfg);
    assert_eq!(poses.len(), 501);
    assert!(poses.iter().all(|(_, p)| *p == Rigid::IDENTITY));
    let road = path_polyline(&cfg, 1.0);
    assert_eq!(road.len(), 61);
    assert_eq!(road[0], DVec3::new(-30.0, 0.0, 0.0));
    assert_eq!(road[60], DVec3::new(30.0, 0.0, 0.0));
}

#[test]
fn the_road_runs_under_the_whole_drive() {
    for kind in TrajectoryKind::ALL {
        for duration in [5.0, 60.0] {
            let cfg = config(kind, duration, 12);
            let road = path_polyline(&cfg, 0.5);
            for w in road.windows(2) {
                let step = (w[1] - w[0]).length();
                assert!(step <= 0.5 + 1e-9, "{kind}: {step}");
            }
            for (_, pose) in generate(&cfg).iter().step_by(25) {
                let nearest = road
                    .iter()
                    .map(|p| (*p - pose.translation).length())
                    .fold(f64::INFINITY, f64::min);
                assert!(nearest < 0.3, "{kind}: {nearest}");
            }
            if kind != TrajectoryKind::Stationary && duration < 10.0 {
                // A short drive's road reaches the margin past both ends.
                let poses = generate(&cfg);
                let (first, last) = (poses[0].1.translation, poses.last().unwrap().1.translation);
                let to_start = (road[0] - first).length();
                let to_end = (*road.last().unwrap() - last).length();
                assert!(
                    to_start > 20.0 && to_end > 20.0,
                    "{kind}: {to_start} {to_end}"
                );
            }
        }
    }
}

#[test]
fn heading_is_the_integral_of_curvature() {
    let segment = Segment::ramp(0.01, -0.04, 12.0);
    let mut integral = 0.0;
    let n = 12_000;
    for k in 0..n {
        let u = 12.0 * (k as f64 + 0.5) / n as f64;
        integral += segment.curvature(u) * 12.0 / n as f64;
    }
    assert!((integral - segment.heading_change(12.0)).abs() < 1e-9);
    assert!((segment.curvature(0.0) - 0.01).abs() < 1e-15);
    assert!((segment.curvature(12.0) + 0.04).abs() < 1e-15);
}

#[test]
fn loops_close_exactly() {
    for kind in moving_kinds() {
        let design = Design::of(kind);
        let path = Path::new(&design.segments);
        assert!(
            path.end_position.length() < 1e-9,
            "{kind}: {}",
            path.end_position
        );
        let turns = path.end_heading / TAU;
        assert!((turns - turns.round()).abs() < 1e-12, "{kind}: {turns}");
    }
}
