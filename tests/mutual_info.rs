#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Mutual-information calibration from known answers: a textured room whose LiDAR reflectivity
//! and camera grey level are the same pattern through a non-linear response; MI peaks at the
//! true extrinsic and the bounded search returns to it from perturbed starts in both
//! directions. On the real PandaSet drive, `rigcal calibrate --method mi` runs end to end.

use glam::{DQuat, DVec3};
use rigcal::classical::mutual_info::{
    MiConfig, MiFrame, MiProblem, MiSearch, equalize, gaussian_blur, rank_bins,
};
use rigcal::geometry::Rigid;
use rigcal::geometry::camera::CameraIntrinsics;

/// The pattern on every wall: blobs of about half a metre.
fn pattern(p: DVec3) -> f64 {
    let a = (p.x * 3.1).sin() * (p.y * 2.3 + 0.5).sin();
    let b = (p.z * 2.7 + p.x).sin() * (p.y * 3.7).cos();
    (0.5 + 0.35 * a + 0.15 * b).clamp(0.0, 1.0)
}

/// Nearest wall of a 10 m wide room (x right, y down, z forward in the camera frame at the
/// truth; floor 1.6 m below, ceiling 4 m above, back wall at 14 m).
fn hit(origin: DVec3, dir: DVec3) -> Option<DVec3> {
    let planes = [
        (DVec3::X, 5.0),
        (DVec3::NEG_X, 5.0),
        (DVec3::Y, 1.6),
        (DVec3::NEG_Y, 4.0),
        (DVec3::Z, 14.0),
    ];
    planes
        .iter()
        .filter_map(|(n, d)| {
            let denom = n.dot(dir);
            (denom > 1e-9).then(|| (d - n.dot(origin)) / denom)
        })
        .filter(|t| *t > 0.0)
        .fold(None, |best: Option<f64>, t| {
            Some(best.map_or(t, |b| b.min(t)))
        })
        .map(|t| origin + dir * t)
}

fn room_problem(vehicle_from_camera: Rigid) -> MiProblem {
    let intr = CameraIntrinsics::pinhole(320, 240, 250.0, 250.0, 160.0, 120.0);
    // The image: every pixel sees the pattern, through a gamma-like response.
    let (w, h) = (intr.width as usize, intr.height as usize);
    let grey: Vec<f32> = (0..w * h)
        .map(|k| {
            let ray = intr
                .unproject(glam::DVec2::new((k % w) as f64, (k / w) as f64))
                .unwrap();
            hit(DVec3::ZERO, ray).map_or(0.0, |p| pattern(p).powf(0.6) as f32)
        })
        .collect();
    let grey = equalize(&gaussian_blur(&grey, w, h, 1.0));
    // The LiDAR: a dense grid of returns on the walls, reflectivity = the pattern itself.
    let mut points = Vec::new();
    let mut reflectivity = Vec::new();
    for i in 0..160 {
        for j in 0..120 {
            let dir = DVec3::new((i as f64 - 80.0) / 90.0, (j as f64 - 60.0) / 90.0, 1.0)
                .normalize_or_zero();
            if let Some(p) = hit(DVec3::ZERO, dir) {
                points.push(vehicle_from_camera.transform_point(p));
                reflectivity.push(pattern(p) as f32);
            }
        }
    }
    MiProblem {
        camera: "cam".into(),
        lidar: "lidar".into(),
        intrinsics: intr,
        frames: vec![MiFrame {
            width: w,
            height: h,
            grey,
            points_in_vehicle: points,
            reflectivity_bin: rank_bins(&reflectivity, 32),
        }],
        bins: 32,
    }
}

#[test]
fn mi_peaks_at_the_truth_and_the_search_returns_to_it() {
    let truth = Rigid::new(
        DQuat::from_euler(glam::EulerRot::ZYX, 0.3, -0.05, 0.02),
        DVec3::new(1.2, 0.1, 1.5),
    );
    let problem = room_problem(truth);
    let at_truth = problem.mi(truth);
    assert!(at_truth > 0.5, "{at_truth}");
    // Moving any degree of freedom away from the truth lowers MI.
    for axis in 0..6 {
        for sign in [-1.0, 1.0] {
            let mut omega = DVec3::ZERO;
            let mut v = DVec3::ZERO;
            if axis < 3 {
                omega[axis] = sign * 0.5f64.to_radians();
            } else {
                v[axis - 3] = sign * 0.05;
            }
            let off = problem.mi(truth.perturbed_right(omega, v));
            assert!(off < at_truth, "axis {axis} {sign}: {off} >= {at_truth}");
        }
    }
    let config = MiConfig {
        bins: 32,
        iterations: 80,
        ..MiConfig::default()
    };
    let starts = [
        (DVec3::new(1.0, -0.6, 0.4), DVec3::new(0.05, -0.03, 0.04)),
        (DVec3::new(-1.0, 0.6, -0.4), DVec3::new(-0.05, 0.03, -0.04)),
        (DVec3::new(0.2, 1.2, -0.8), DVec3::new(-0.02, 0.06, 0.03)),
    ];
    for (deg, m) in starts {
        let start = truth.perturbed_right(deg * 1f64.to_radians(), m);
        let mut search = MiSearch::new(&problem, start, &config);
        for _ in 0..config.iterations {
            search.step(&problem);
            if search.converged() {
                break;
            }
        }
        let (r0, t0) = start.difference(truth);
        let (r, t) = search.best.difference(truth);
        assert!(
            r.to_degrees() < 0.1 && t < 0.01,
            "from {:.2}° / {:.1} cm: {:.3}° / {:.2} cm after {} iterations",
            r0.to_degrees(),
            t0 * 100.0,
            r.to_degrees(),
            t * 100.0,
            search.iterations
        );
        assert!(search.best_mi >= problem.mi(start));
    }
}

#[test]
fn the_search_stays_within_the_papers_bounds() {
    let truth = Rigid::IDENTITY;
    let problem = room_problem(truth);
    // The truth is 5° away: the search may not go past 2° (per axis) from its start.
    let start = truth.perturbed_right(DVec3::new(0.0, 5f64.to_radians(), 0.0), DVec3::ZERO);
    let config = MiConfig {
        bins: 32,
        ..MiConfig::default()
    };
    let mut search = MiSearch::new(&problem, start, &config);
    for _ in 0..40 {
        search.step(&problem);
    }
    let (r, t) = search.best.difference(start);
    assert!(r.to_degrees() <= 2.0 * 3f64.sqrt() + 1e-6 && t <= 0.2 * 3f64.sqrt() + 1e-9);
    // It did move towards the truth.
    assert!(search.best.difference(truth).0 < start.difference(truth).0);
}

#[test]
fn calibrate_with_mi_on_pandaset_writes_the_native_file() {
    let pandaset = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/pandaset-002/pandaset-002.mcap");
    let dir = std::env::temp_dir().join(format!("rigcal-mi-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("mi.yaml");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .arg("calibrate")
        .arg(&pandaset)
        .args([
            "--method",
            "mi",
            "--sensors",
            "front_camera",
            "--iterations",
            "3",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let doc = rigcal::calib::CalibrationFile::load(&out).unwrap();
    assert!(
        doc.metrics
            .keys()
            .any(|k| k.starts_with("mi_nats/front_camera")),
        "{:?}",
        doc.metrics
    );
    let drive = rigcal::log::Drive::open(&pandaset).unwrap();
    let rig = doc.to_rig(&out).unwrap();
    // Three iterations from the recorded extrinsic stay within the bounds; others untouched.
    let (r, t) = rig
        .sensor("front_camera")
        .unwrap()
        .vehicle_from_sensor
        .difference(
            drive
                .rig
                .sensor("front_camera")
                .unwrap()
                .vehicle_from_sensor,
        );
    assert!(r.to_degrees() < 3.5 && t < 0.35);
    let (r, t) = rig
        .sensor("left_camera")
        .unwrap()
        .vehicle_from_sensor
        .difference(drive.rig.sensor("left_camera").unwrap().vehicle_from_sensor);
    assert!(r + t < 1e-12);
    std::fs::remove_dir_all(&dir).unwrap();
}
