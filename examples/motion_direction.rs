//! Where each camera's own motion says it points: a check of a calibration that uses no LiDAR.
//!
//! Between two images of one camera the trajectory says how the vehicle moved; a camera
//! extrinsic turns that into the camera's motion, hence an essential matrix, and the two images'
//! verified matches (the hand-eye's, [`rigcal::classical::camera_motion::camera_pairs`]) should
//! lie on its epipolar lines. A wrong turn of the camera tilts every pair's epipolar geometry the
//! same way. Even on a straight drive this pins the two turns square to the travel; the turn
//! about the mean travel is held here (a straight drive leaves it unseen).
//!
//! For each camera and each calibration given (the log's own rig first) this prints the median
//! Sampson distance of the matches (normalised image units × 1000) at that calibration and after
//! fitting the turn (Cauchy-weighted Gauss–Newton, the translation held), the fitted turn in the
//! camera's axes and in the vehicle's, with a 1-σ that is cluster-robust over image pairs, and
//! where the calibration and the fit stand from the log's rig (`R · R_log⁻¹` as a rotation vector
//! in the vehicle frame, degrees).
//!
//! `cargo run --release --no-default-features --example motion_direction -- LOG.mcap [CALIB...]`,
//! each `CALIB` a native calibration file or a dataset's ground_truth.json.

mod given_rigs;
use given_rigs::given_rigs;

use glam::{DMat3, DVec3};
use rigcal::classical::camera_motion::{CameraPairs, camera_pairs, picked_images};
use rigcal::classical::hand_eye::epipolar_residual;
use rigcal::geometry::{Rigid, RowTimes, so3};
use rigcal::log::Drive;

struct Fit {
    end: Rigid,
    omega_camera_deg: DVec3,
    sigma_deg: DVec3,
    /// Median |Sampson distance| (normalised units × 1000) at the given extrinsic and the fit.
    median_before: f64,
    median_after: f64,
    used: usize,
}

/// One verified match: its rays in the two images and `vehicle_i_from_vehicle_j` at the times
/// their rows were exposed.
struct Match {
    a: DVec3,
    b: DVec3,
    vehicle_motion: Rigid,
}

/// Each pair's matches, with the vehicle's motion between the rows they lie on when `readout`
/// is a rolling shutter's (the pair's own motion otherwise).
fn matches(
    drive: &Drive,
    name: &str,
    found: &CameraPairs,
    frames: usize,
    readout: RowTimes,
) -> Vec<Vec<Match>> {
    let (Some(stream), Some(camera)) = (
        drive.stream(name),
        drive.rig.sensor(name).and_then(|s| s.camera.clone()),
    ) else {
        return Vec::new();
    };
    let stamps: Vec<i64> = picked_images(drive, name, frames, &[])
        .iter()
        .map(|&i| stream.frames[i].stamp_nanos)
        .collect();
    let poses = &found.world_from_vehicle;
    found
        .pairs
        .iter()
        .filter_map(|p| {
            let i = p.first_image;
            let wi = poses.get(i).copied().flatten()?;
            // The second image: the frame whose pose gives the pair's motion.
            let j = (0..poses.len())
                .filter_map(|k| {
                    let wk = poses[k]?;
                    let d =
                        ((wi.inverse() * wk).translation - p.vehicle_motion.translation).length();
                    Some((k, d))
                })
                .min_by(|x, y| x.1.total_cmp(&y.1))?
                .0;
            let at = |stamp: i64, ray: DVec3| -> Option<Rigid> {
                let y = camera.project(ray)?.y;
                drive
                    .trajectory
                    .world_from_vehicle(stamp + readout.offset_nanos(y, camera.height))
                    .ok()
            };
            Some(
                p.rays
                    .iter()
                    .filter_map(|&(a, b)| {
                        let vehicle_motion = if readout.is_global() {
                            p.vehicle_motion
                        } else {
                            at(stamps[i], a)?.inverse() * at(stamps[j], b)?
                        };
                        Some(Match {
                            a,
                            b,
                            vehicle_motion,
                        })
                    })
                    .collect(),
            )
        })
        .filter(|m: &Vec<Match>| !m.is_empty())
        .collect()
}

/// Per pair, its matches' residuals for extrinsic `x`.
fn residuals(pairs: &[Vec<Match>], x: Rigid) -> Vec<Vec<f64>> {
    let inverse = x.inverse();
    pairs
        .iter()
        .map(|p| {
            p.iter()
                .map(|m| epipolar_residual(inverse * m.vehicle_motion * x, m.a, m.b))
                .collect()
        })
        .collect()
}

/// Cauchy scale (normalised units, about 3 px at a 1000 px focal length).
const SCALE: f64 = 3.0e-3;

/// The turn `ω` (camera axes) with `x · exp(ω)` best fitting every pair's matches (Sampson
/// distance, Cauchy-weighted), the translation held; the turn about the travel is damped.
fn fit(pairs: &[Vec<Match>], x: Rigid) -> Option<Fit> {
    let median = |r: &[Vec<f64>]| {
        let mut v: Vec<f64> = r.iter().flatten().map(|e| e.abs() * 1000.0).collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
    };
    if pairs.len() < 3 {
        return None;
    }
    let before = residuals(pairs, x);
    let median_before = median(&before);
    let matches: usize = before.iter().map(Vec::len).sum();
    // The mean travel (vehicle frame), each pair's motion signed along the first's.
    let first = pairs[0][0].vehicle_motion.translation;
    let travel = pairs
        .iter()
        .map(|p| {
            let t = p[0].vehicle_motion.translation.normalize_or_zero();
            if t.dot(first) < 0.0 { -t } else { t }
        })
        .sum::<DVec3>()
        .normalize_or_zero();
    let mut current = x;
    let mut total = DVec3::ZERO;
    let mut covariance = DMat3::ZERO;
    const STEP: f64 = 1e-6;
    for _ in 0..8 {
        let r = residuals(pairs, current);
        let columns: Vec<Vec<Vec<f64>>> = (0..3)
            .map(|k| {
                let mut d = DVec3::ZERO;
                d[k] = STEP;
                let moved = residuals(pairs, current.perturbed_right(d, DVec3::ZERO));
                moved
                    .iter()
                    .zip(&r)
                    .map(|(m, h)| m.iter().zip(h).map(|(m, h)| (m - h) / STEP).collect())
                    .collect()
            })
            .collect();
        let mut normal = DMat3::ZERO;
        let mut rhs = DVec3::ZERO;
        let mut meat = DMat3::ZERO;
        for (p, rp) in r.iter().enumerate() {
            let mut score = DVec3::ZERO;
            for (i, e) in rp.iter().enumerate() {
                let w = 1.0 / (1.0 + (e / SCALE).powi(2));
                let j = DVec3::new(columns[0][p][i], columns[1][p][i], columns[2][p][i]);
                normal += so3::outer(j, j) * w;
                rhs -= j * (w * e);
                score += j * (w * e);
            }
            meat += so3::outer(score, score);
        }
        // Hold the turn about the mean travel, which a straight drive leaves unseen.
        let along = current.rotation.inverse() * travel;
        let damping =
            so3::outer(along, along) * (normal.x_axis.x + normal.y_axis.y + normal.z_axis.z);
        let bread = (normal + damping).inverse();
        covariance = bread * meat * bread;
        let step = bread * rhs;
        current = current.perturbed_right(step, DVec3::ZERO);
        total += step;
        if step.length() < 1e-8 {
            break;
        }
    }
    let sigma_deg = DVec3::new(
        covariance.x_axis.x.sqrt(),
        covariance.y_axis.y.sqrt(),
        covariance.z_axis.z.sqrt(),
    ) * 180.0
        / std::f64::consts::PI;
    Some(Fit {
        end: current,
        omega_camera_deg: total * 180.0 / std::f64::consts::PI,
        sigma_deg,
        median_before,
        median_after: median(&residuals(pairs, current)),
        used: matches,
    })
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(log) = args.first() else {
        return Err("usage: motion_direction LOG.mcap [CALIB...]".into());
    };
    let drive = Drive::open(std::path::Path::new(log)).map_err(|e| e.to_string())?;
    let rigs = given_rigs(&drive, &args[1..])?;
    let frames = std::env::var("RIGCAL_FRAMES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(48);
    // A rolling shutter's readout, "FIRST,LAST" ms from the stamp (global when unset).
    let readout = match std::env::var("RIGCAL_READOUT_MS") {
        Ok(text) => RowTimes::parse_millis(&text).map_err(|e| e.to_string())?,
        Err(_) => RowTimes::GLOBAL,
    };
    let names: Vec<String> = drive.rig.cameras().map(|c| c.name.clone()).collect();
    for name in &names {
        let found = camera_pairs(&drive, &drive.rig, name, frames, &[], false, &|_, _, _| {})
            .map_err(|e| e.to_string())?;
        println!("{name}: {} pairs", found.pairs.len());
        let with_rows = matches(&drive, name, &found, frames, readout);
        let first = drive.rig.sensor(name).map(|s| s.vehicle_from_sensor);
        for (label, rig) in &rigs {
            let Some(x) = rig.sensor(name).map(|s| s.vehicle_from_sensor) else {
                continue;
            };
            match fit(&with_rows, x) {
                Some(f) => {
                    let vehicle = DMat3::from_quat(x.rotation) * f.omega_camera_deg;
                    let turn = DMat3::from_quat(x.rotation);
                    let cov =
                        turn * DMat3::from_diagonal(f.sigma_deg * f.sigma_deg) * turn.transpose();
                    let vehicle_sigma = DVec3::new(
                        cov.x_axis.x.sqrt(),
                        cov.y_axis.y.sqrt(),
                        cov.z_axis.z.sqrt(),
                    );
                    // Where the fit and the given extrinsic stand from the log's (vehicle frame).
                    let from_log = |r: Rigid| {
                        first.map_or(DVec3::ZERO, |l| {
                            so3::log(r.rotation * l.rotation.inverse()) * 180.0
                                / std::f64::consts::PI
                        })
                    };
                    let (given, end) = (from_log(x), from_log(f.end));
                    println!(
                        "  {label:40} median {:.3} → {:.3} ({} matches)  ω camera {:+.3} {:+.3} {:+.3}° (σ {:.3} {:.3} {:.3})  vehicle {:+.3} {:+.3} {:+.3}°  given−log {:+.2} {:+.2} {:+.2}  fit−log {:+.2} {:+.2} {:+.2} (σ≈ {:.2} {:.2} {:.2})",
                        f.median_before,
                        f.median_after,
                        f.used,
                        f.omega_camera_deg.x,
                        f.omega_camera_deg.y,
                        f.omega_camera_deg.z,
                        f.sigma_deg.x,
                        f.sigma_deg.y,
                        f.sigma_deg.z,
                        vehicle.x,
                        vehicle.y,
                        vehicle.z,
                        given.x,
                        given.y,
                        given.z,
                        end.x,
                        end.y,
                        end.z,
                        vehicle_sigma.x,
                        vehicle_sigma.y,
                        vehicle_sigma.z,
                    );
                }
                None => println!("  {label:40} too few pairs"),
            }
        }
    }
    Ok(())
}
