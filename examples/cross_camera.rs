//! Where overlapping cameras say one another point: a check of a calibration that uses neither
//! the LiDAR nor the drive's motion beyond the milliseconds between two cameras' triggers.
//!
//! Two cameras whose views overlap see the same scene at (nearly) the same time. Their
//! extrinsics and the trajectory between their two stamps give camera `a`'s pose from camera
//! `b`, hence an essential matrix, and the verified matches between the two images should lie on
//! its epipolar lines. With the two translations held (a few centimetres of error tilt a
//! baseline of a metre by about a degree, which moves the fitted turn far less for scenes
//! metres away), the matches pin the relative turn of the two cameras in all three axes.
//!
//! Keypoints are found on each image scaled to one focal length (ORB has a single scale, and
//! PandaSet's front camera has twice the side cameras' focal length), matched mutually with
//! the ratio test and kept where they lie within 0.03 (normalised units, a 1.7° turn) of the
//! log's epipolar lines: the same matches for every calibration. For each overlapping pair
//! and each calibration given (the log's own rig first) this prints the median Sampson
//! distance (normalised units × 1000) at the calibration and after fitting camera `b`'s turn
//! with `a` held (Cauchy-weighted Gauss–Newton), the fitted turn in the vehicle frame with a
//! 1-σ that is cluster-robust over frames, and where `b`'s given and fitted turns stand from
//! the log's rig when `a` is where that calibration puts it (`R · R_log⁻¹`, vehicle frame,
//! degrees).
//!
//! `cargo run --release --no-default-features --example cross_camera -- LOG.mcap [CALIB...]`,
//! each `CALIB` a native calibration file or a dataset's ground_truth.json. `RIGCAL_PAIRS`
//! ("a:b,c:d") picks the pairs; by default every pair whose fields of view overlap by 5° or more.

mod given_rigs;
use given_rigs::given_rigs;

use std::sync::Arc;

use glam::{DMat3, DVec2, DVec3};
use image::RgbImage;
use rigcal::calib::Rig;
use rigcal::classical::hand_eye::epipolar_residual;
use rigcal::features::matching::match_mutual;
use rigcal::features::orb::{Keypoint, detect};
use rigcal::geometry::camera::CameraIntrinsics;
use rigcal::geometry::{Rigid, so3};
use rigcal::log::Drive;

/// The focal length (px) both images of a pair are scaled to before keypoints are found.
const COMMON_FOCAL_PX: f64 = 465.0;
/// Two frames of different cameras at most this far apart form a pair (s).
const MAX_GAP_SECS: f64 = 0.06;
/// Matches farther than this (normalised units) from the log's epipolar lines are dropped.
const GATE: f64 = 0.03;
/// Matches a frame needs within the gate.
const MIN_MATCHES: usize = 8;
/// Cauchy scale (normalised units, about 3 px at a 1000 px focal length).
const SCALE: f64 = 3.0e-3;

/// Keypoints of `img` found at [`COMMON_FOCAL_PX`], positions in the image's own pixels.
fn keypoints(img: &RgbImage, k: &CameraIntrinsics) -> Vec<Keypoint> {
    let scale = (COMMON_FOCAL_PX / k.fx).min(1.0);
    let (w, h) = (
        ((img.width() as f64 * scale).round() as u32).max(1),
        ((img.height() as f64 * scale).round() as u32).max(1),
    );
    let small = image::imageops::resize(img, w, h, image::imageops::FilterType::Triangle);
    let grey = rigcal::features::grey::grey_u8(&small);
    let back = img.width() as f64 / w as f64;
    detect(&grey, w as usize, h as usize, 2048)
        .into_iter()
        .map(|p| Keypoint {
            x: ((p.x as f64 + 0.5) * back - 0.5) as f32,
            y: ((p.y as f64 + 0.5) * back - 0.5) as f32,
            ..p
        })
        .collect()
}

/// One frame's verified matches: rays in `a` and `b`, and `vehicle(t_a)_from_vehicle(t_b)`.
struct Frame {
    rays: Vec<(DVec3, DVec3)>,
    vehicle_a_from_vehicle_b: Rigid,
}

fn frames(drive: &Drive, (a, xa): (&str, Rigid), (b, xb): (&str, Rigid)) -> Vec<Frame> {
    let (Some(sa), Some(sb)) = (drive.stream(a), drive.stream(b)) else {
        return Vec::new();
    };
    let intrinsics = |n: &str| drive.rig.sensor(n).and_then(|s| s.camera.clone());
    let (Some(ka), Some(kb)) = (intrinsics(a), intrinsics(b)) else {
        return Vec::new();
    };
    let image = |n: &str, i: usize| -> Option<Arc<RgbImage>> { drive.image_or_skip(n, i) };
    let mut out = Vec::new();
    for (i, fa) in sa.frames.iter().enumerate() {
        let Some((j, fb)) = sb
            .frames
            .iter()
            .enumerate()
            .min_by_key(|(_, f)| (f.stamp_nanos - fa.stamp_nanos).abs())
        else {
            continue;
        };
        if (fb.stamp_nanos - fa.stamp_nanos).abs() as f64 * 1e-9 > MAX_GAP_SECS {
            continue;
        }
        let (Ok(wa), Ok(wb)) = (
            drive.trajectory.world_from_vehicle(fa.stamp_nanos),
            drive.trajectory.world_from_vehicle(fb.stamp_nanos),
        ) else {
            continue;
        };
        let (Some(ia), Some(ib)) = (image(a, i), image(b, j)) else {
            continue;
        };
        let (pa, pb) = (keypoints(&ia, &ka), keypoints(&ib, &kb));
        let (rays_a, rays_b): (Vec<DVec3>, Vec<DVec3>) = match_mutual(&pa, &pb, 0.8, 64)
            .iter()
            .filter_map(|&(x, y)| {
                Some((
                    ka.unproject(DVec2::new(pa[x].x as f64, pa[x].y as f64))?,
                    kb.unproject(DVec2::new(pb[y].x as f64, pb[y].y as f64))?,
                ))
            })
            .unzip();
        // Gated at the log's rig, generously (a 1.7° turn): the same matches for every
        // calibration, then weighed by the fit's Cauchy loss.
        let vehicle_a_from_vehicle_b = wa.inverse() * wb;
        let a_from_b = xa.inverse() * vehicle_a_from_vehicle_b * xb;
        let rays: Vec<(DVec3, DVec3)> = rays_a
            .into_iter()
            .zip(rays_b)
            .filter(|&(ra, rb)| epipolar_residual(a_from_b, ra, rb).abs() < GATE)
            .collect();
        if std::env::var("RIGCAL_DEBUG").is_ok() {
            eprintln!(
                "{a} {i} × {b} {j}: {} and {} keypoints, {} within the gate",
                pa.len(),
                pb.len(),
                rays.len()
            );
        }
        if rays.len() >= MIN_MATCHES {
            out.push(Frame {
                rays,
                vehicle_a_from_vehicle_b,
            });
        }
    }
    out
}

/// Per frame, its matches' residuals with `a` at `xa` and `b` at `xb`.
fn residuals(frames: &[Frame], xa: Rigid, xb: Rigid) -> Vec<Vec<f64>> {
    frames
        .iter()
        .map(|f| {
            let a_from_b = xa.inverse() * f.vehicle_a_from_vehicle_b * xb;
            f.rays
                .iter()
                .map(|&(ra, rb)| epipolar_residual(a_from_b, ra, rb))
                .collect()
        })
        .collect()
}

fn median(r: &[Vec<f64>]) -> f64 {
    let mut v: Vec<f64> = r.iter().flatten().map(|e| e.abs() * 1000.0).collect();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// `b`'s extrinsic turned (camera axes) to fit every frame's matches with `a` held, and the
/// turn's covariance (rad², camera axes), cluster-robust over frames.
fn fit(frames: &[Frame], xa: Rigid, xb: Rigid) -> (Rigid, DMat3) {
    let mut current = xb;
    let mut covariance = DMat3::ZERO;
    const STEP: f64 = 1e-6;
    for _ in 0..10 {
        let r = residuals(frames, xa, current);
        let columns: Vec<Vec<Vec<f64>>> = (0..3)
            .map(|k| {
                let mut d = DVec3::ZERO;
                d[k] = STEP;
                residuals(frames, xa, current.perturbed_right(d, DVec3::ZERO))
                    .iter()
                    .zip(&r)
                    .map(|(m, h)| m.iter().zip(h).map(|(m, h)| (m - h) / STEP).collect())
                    .collect()
            })
            .collect();
        let (mut normal, mut rhs, mut meat) = (DMat3::ZERO, DVec3::ZERO, DMat3::ZERO);
        for (f, rf) in r.iter().enumerate() {
            let mut score = DVec3::ZERO;
            for (i, e) in rf.iter().enumerate() {
                let w = 1.0 / (1.0 + (e / SCALE).powi(2));
                let j = DVec3::new(columns[0][f][i], columns[1][f][i], columns[2][f][i]);
                normal += so3::outer(j, j) * w;
                rhs -= j * (w * e);
                score += j * (w * e);
            }
            meat += so3::outer(score, score);
        }
        let bread = normal.inverse();
        covariance = bread * meat * bread;
        let step = bread * rhs;
        current = current.perturbed_right(step, DVec3::ZERO);
        if step.length() < 1e-9 {
            break;
        }
    }
    (current, covariance)
}

/// Pairs of cameras whose horizontal fields of view overlap by `min_deg` or more.
fn overlapping(rig: &Rig, min_deg: f64) -> Vec<(String, String)> {
    let cams: Vec<(String, DVec3, f64)> = rig
        .cameras()
        .filter_map(|c| {
            let k = c.camera.as_ref()?;
            let axis = DMat3::from_quat(c.vehicle_from_sensor.rotation) * DVec3::Z;
            Some((c.name.clone(), axis, (k.width as f64 / 2.0 / k.fx).atan()))
        })
        .collect();
    let mut out = Vec::new();
    for (i, a) in cams.iter().enumerate() {
        for b in &cams[i + 1..] {
            let apart = a.1.dot(b.1).clamp(-1.0, 1.0).acos();
            if (a.2 + b.2 - apart).to_degrees() >= min_deg {
                out.push((a.0.clone(), b.0.clone()));
            }
        }
    }
    out
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(log) = args.first() else {
        return Err("usage: cross_camera LOG.mcap [CALIB...]".into());
    };
    let drive = Drive::open(std::path::Path::new(log)).map_err(|e| e.to_string())?;
    let rigs = given_rigs(&drive, &args[1..])?;
    let pairs = match std::env::var("RIGCAL_PAIRS") {
        Ok(text) => text
            .split(',')
            .filter_map(|p| p.split_once(':'))
            .map(|(a, b)| (a.trim().to_owned(), b.trim().to_owned()))
            .collect(),
        Err(_) => overlapping(&drive.rig, 5.0),
    };
    let extrinsic = |rig: &Rig, n: &str| rig.sensor(n).map(|s| s.vehicle_from_sensor);
    for (a, b) in &pairs {
        let (Some(la), Some(lb)) = (extrinsic(&drive.rig, a), extrinsic(&drive.rig, b)) else {
            continue;
        };
        let found = frames(&drive, (a, la), (b, lb));
        let matches: usize = found.iter().map(|f| f.rays.len()).sum();
        println!("{a} × {b}: {} frames, {matches} matches", found.len());
        if found.len() < 3 {
            println!("  too few frames");
            continue;
        }
        let log_b = lb;
        for (label, rig) in &rigs {
            // The calibration's turns on the log's translations: a few centimetres of
            // translation tilt the pair's baseline by degrees, and only the turns are compared.
            let (Some(xa), Some(xb)) = (
                extrinsic(rig, a).map(|x| Rigid::new(x.rotation, la.translation)),
                extrinsic(rig, b).map(|x| Rigid::new(x.rotation, lb.translation)),
            ) else {
                continue;
            };
            let before = median(&residuals(&found, xa, xb));
            let (end, cov) = fit(&found, xa, xb);
            let after = median(&residuals(&found, xa, end));
            let turn = DMat3::from_quat(xb.rotation);
            let cov_vehicle = turn * cov * turn.transpose();
            let sigma = DVec3::new(
                cov_vehicle.x_axis.x.sqrt(),
                cov_vehicle.y_axis.y.sqrt(),
                cov_vehicle.z_axis.z.sqrt(),
            )
            .to_array()
            .map(f64::to_degrees);
            // b against the log's b, with a where this calibration puts it: the relative turn
            // the matches see, carried onto the log's a.
            let carry = |x: Rigid| -> DVec3 {
                let relative = xa.inverse() * x;
                let on_log = extrinsic(&drive.rig, a).map_or(x, |la| la * relative);
                so3::log(on_log.rotation * log_b.rotation.inverse()) * 180.0 / std::f64::consts::PI
            };
            let (given, fitted) = (carry(xb), carry(end));
            println!(
                "  {label:40} median {before:.3} → {after:.3}  {b} given−log {:+.2} {:+.2} {:+.2}°  fit−log {:+.2} {:+.2} {:+.2}° (σ {:.2} {:.2} {:.2}, vehicle axes; {a} held)",
                given.x,
                given.y,
                given.z,
                fitted.x,
                fitted.y,
                fitted.z,
                sigma[0],
                sigma[1],
                sigma[2],
            );
        }
    }
    Ok(())
}
