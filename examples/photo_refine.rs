#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Photometric consistency over the LiDARs' geometry (`rigcal::optim::photo_consistency`) for
//! every camera of a calibration: the cost at the calibration and at the reference (in the
//! calibration's gauge, aligned by the root), then a compass search from the calibration, with
//! the errors against the reference before and after.
//! `cargo run --release --no-default-features --example photo_refine -- LOG CALIB REFERENCE [OUT]`
//! Environment: `RIGCAL_PHOTO_IMAGES` (16), `RIGCAL_PHOTO_WIDTH` (480), `RIGCAL_PHOTO_ROTATE_ONLY`,
//! `RIGCAL_PHOTO_FROM_REFERENCE` (start at the reference instead), `RIGCAL_PHOTO_SCALE_SWEEP`
//! (the cost at the reference with the focal length scaled, and moved along the optical axis),
//! `RIGCAL_PHOTO_READOUT_MS` (`FIRST..LAST`: a rolling shutter's rows, ms after the stamp).

use rigcal::calib::CalibrationFile;
use rigcal::calib::dataset_json::load_reference;
use rigcal::geometry::{Rigid, RowTimes};
use rigcal::log::{Drive, DriveOptions};
use rigcal::optim::edge_align::CompassSearch;
use rigcal::optim::photo_consistency::{PhotoConfig, PhotoProblem, lidar_map, search};

fn env<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    // A rolling shutter's readout, `FIRST..LAST` ms after the stamp.
    let camera_readout = std::env::var("RIGCAL_PHOTO_READOUT_MS")
        .ok()
        .map_or(RowTimes::GLOBAL, |v| {
            RowTimes::parse_millis(&v).unwrap_or_else(|e| panic!("RIGCAL_PHOTO_READOUT_MS {e}"))
        });
    let options = DriveOptions {
        camera_readout,
        ..DriveOptions::default()
    };
    let drive = Drive::open_with(std::path::Path::new(&args[0]), &options).unwrap();
    let calibration = CalibrationFile::load_rig(std::path::Path::new(&args[1])).unwrap();
    let reference = load_reference(std::path::Path::new(&args[2])).unwrap();
    let root = reference.lidars().next().unwrap().name.clone();
    let mut rig = drive.rig.clone();
    for s in calibration.sensors.iter() {
        if let Some(t) = rig.sensor_mut(&s.name) {
            t.vehicle_from_sensor = s.vehicle_from_sensor;
        }
    }
    let alignment = rig.sensor(&root).unwrap().vehicle_from_sensor
        * reference
            .sensor(&root)
            .unwrap()
            .vehicle_from_sensor
            .inverse();
    let config = PhotoConfig {
        images: env("RIGCAL_PHOTO_IMAGES", 16),
        working_width_px: env("RIGCAL_PHOTO_WIDTH", 480),
        blur_sigma_px: env("RIGCAL_PHOTO_BLUR", 1.0),
        min_range_m: env("RIGCAL_PHOTO_MIN_RANGE", 2.0),
        max_range_m: env("RIGCAL_PHOTO_MAX_RANGE", 60.0),
        cell_px: env("RIGCAL_PHOTO_CELL", 4),
        depth_margin: env("RIGCAL_PHOTO_MARGIN", 0.03),
        min_views: env("RIGCAL_PHOTO_MIN_VIEWS", 3),
        truncation: env("RIGCAL_PHOTO_TRUNCATION", 1.0),
        vignetting_k: env("RIGCAL_PHOTO_DEVIGNETTE", 0.0),
        ..PhotoConfig::default()
    };
    let rotate_only = std::env::var("RIGCAL_PHOTO_ROTATE_ONLY").is_ok();
    let error = |est: Rigid, truth: Rigid| {
        // In the reference's gauge: truth vs alignment⁻¹ · est.
        let aligned = alignment.inverse() * est;
        let (r, t) = truth.difference(aligned);
        let rv = rigcal::geometry::so3::log(aligned.rotation * truth.rotation.conjugate());
        format!(
            "{:.3}° / {:.2} cm (about x,y,z {:+.2} {:+.2} {:+.2}°; d {:+.1} {:+.1} {:+.1} cm)",
            r.to_degrees(),
            t * 100.0,
            rv.x.to_degrees(),
            rv.y.to_degrees(),
            rv.z.to_degrees(),
            (aligned.translation.x - truth.translation.x) * 100.0,
            (aligned.translation.y - truth.translation.y) * 100.0,
            (aligned.translation.z - truth.translation.z) * 100.0,
        )
    };
    // The problem with every image taken `ms` later than stamped (as stamped where that
    // leaves the trajectory).
    let shifted = |problem: &PhotoProblem, ms: i64| {
        problem
            .delayed(&drive.trajectory, ms * 1_000_000)
            .unwrap_or_else(|| problem.clone())
    };
    let run = |problem: &PhotoProblem, start: Rigid| -> (CompassSearch, usize) {
        let mut s = search(problem, start);
        s.translate = !rotate_only;
        let mut rounds = 0;
        while !s.converged() && rounds < 400 {
            s.step_with(|pose| problem.cost(pose));
            rounds += 1;
        }
        (s, rounds)
    };
    let map = lidar_map(&drive, &rig, &config).unwrap();
    let cameras: Vec<String> = rig.cameras().map(|c| c.name.clone()).collect();
    let mut out = rig.clone();
    let only: Option<String> = std::env::var("RIGCAL_PHOTO_CAMERAS").ok();
    for camera in &cameras {
        if only
            .as_ref()
            .is_some_and(|o| !o.split(',').any(|c| c == camera))
        {
            continue;
        }
        let t0 = std::time::Instant::now();
        let mut problem_rig = rig.clone();
        if std::env::var("RIGCAL_PHOTO_FROM_REFERENCE").is_ok() {
            problem_rig.sensor_mut(camera).unwrap().vehicle_from_sensor =
                alignment * reference.sensor(camera).unwrap().vehicle_from_sensor;
        }
        let problem =
            PhotoProblem::from_drive(&drive, &problem_rig, camera, &map, &config).unwrap();
        let truth = reference.sensor(camera).unwrap().vehicle_from_sensor;
        let truth_here = alignment * truth;
        let start = if std::env::var("RIGCAL_PHOTO_FROM_REFERENCE").is_ok() {
            truth_here
        } else {
            rig.sensor(camera).unwrap().vehicle_from_sensor
        };
        let prep = t0.elapsed().as_secs_f64();
        if std::env::var("RIGCAL_PHOTO_TIME_SEARCH").is_ok() {
            for ms in (-60..=20).step_by(10) {
                let shifted = shifted(&problem, ms);
                let (search, _) = run(&shifted, start);
                println!(
                    "{camera} {ms:+} ms: cost {:.5} -> {:.5}  end {}",
                    shifted.cost(start),
                    search.best_cost,
                    error(search.best, truth)
                );
            }
            continue;
        }
        if std::env::var("RIGCAL_PHOTO_TIME_SWEEP").is_ok() {
            let mut line = String::new();
            for ms in (-80..=80).step_by(10) {
                let shifted = shifted(&problem, ms);
                line += &format!(" {ms:+}:{:.5}", shifted.cost(truth_here));
            }
            println!("{camera} time offset (ms) at the reference:{line}");
            continue;
        }
        if std::env::var("RIGCAL_PHOTO_SCALE_SWEEP").is_ok() {
            // The focal length scaled (an intrinsic error) and the camera moved along its
            // own optical axis, both from the reference: the two look alike to one image.
            let mut line = String::new();
            for k in -6..=6 {
                let s = 1.0 + k as f64 * 0.0025;
                let scaled = problem.with_focal_scale(s);
                line += &format!(" {s:.4}:{:.5}", scaled.cost(truth_here));
            }
            println!("{camera} focal scale at the reference:{line}");
            let axis = truth_here.rotation * glam::DVec3::Z;
            let mut line = String::new();
            for k in -6..=6 {
                let d = k as f64 * 0.05;
                let pose = Rigid::new(truth_here.rotation, truth_here.translation + axis * d);
                line += &format!(" {:+.0}:{:.5}", d * 100.0, problem.cost(pose));
            }
            println!("{camera} along its optical axis (cm) from the reference:{line}");
            if std::env::var("RIGCAL_PHOTO_SCALE_GRID").is_ok() {
                // Both at once: the best axial shift at each focal scale.
                for k in -8..=2 {
                    let s = 1.0 + k as f64 * 0.0025;
                    let scaled = problem.with_focal_scale(s);
                    let mut line = String::new();
                    for j in -6..=4 {
                        let d = j as f64 * 0.05;
                        let pose =
                            Rigid::new(truth_here.rotation, truth_here.translation + axis * d);
                        line += &format!(" {:+.0}:{:.5}", d * 100.0, scaled.cost(pose));
                    }
                    println!("  scale {s:.4}:{line}");
                }
            }
            continue;
        }
        if let Ok(axis) = std::env::var("RIGCAL_PHOTO_SWEEP") {
            let axis: usize = axis.parse().unwrap();
            let mut line = String::new();
            for k in -8..=8 {
                let mut w = glam::DVec3::ZERO;
                w[axis] = (k as f64 * 0.05).to_radians();
                let pose = Rigid::new(
                    rigcal::geometry::so3::exp(w) * truth_here.rotation,
                    truth_here.translation,
                );
                line += &format!(" {:+.2}:{:.5}", k as f64 * 0.05, problem.cost(pose));
            }
            println!("{camera} about vehicle axis {axis} from the reference:{line}");
            continue;
        }
        let (search, rounds) = run(&problem, start);
        println!(
            "{camera}: {} points, {} views, prep {prep:.1} s, {rounds} rounds, {:.1} s\n  cost start {:.5}  at reference {:.5}  end {:.5}\n  start {}\n  end   {}",
            problem.point_count(),
            problem.view_count(),
            t0.elapsed().as_secs_f64(),
            problem.cost(start),
            problem.cost(truth_here),
            search.best_cost,
            error(start, truth),
            error(search.best, truth),
        );
        out.sensor_mut(camera).unwrap().vehicle_from_sensor = search.best;
    }
    if let Some(path) = args.get(3) {
        CalibrationFile::from_rig(&out)
            .save(std::path::Path::new(path))
            .unwrap();
    }
}
