//! Point-to-plane ICP side by side with Open3D (`scripts/bench-icp.sh` runs both).
//!
//! `cargo run --release --no-default-features --example icp_compare -- LOG GROUND_TRUTH OUT_DIR`
//!
//! Takes the first two LiDARs of the reference present in the log, one sweep of the second and
//! the first's sweep nearest in time, and makes the rigid problem both tools solve: the target
//! is the first LiDAR's sweep in the vehicle frame at the source sweep's stamp (reference
//! extrinsic, the vehicle's motion between the two stamps compensated; use deskewed or
//! stationary data), the source is the
//! second LiDAR's sweep in its own frame, the start is its reference extrinsic turned by 1° and
//! moved by 10 cm (fixed axis and direction). Writes `target.ply`, `source.ply` and `case.json`
//! (start, reference, levels, stopping rule) into OUT_DIR for `benches/icp_open3d.py`, then runs
//! rigcal's ICP on the same clouds and prints one JSON line: errors against the reference,
//! wall time (loading excluded: downsampling, normals and iterations included), point counts.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use glam::{DMat4, DVec3};
use rigcal::calib::dataset_json::load_reference;
use rigcal::classical::icp::{IcpConfig, IcpProblem, SourcePoint};
use rigcal::geometry::{Rigid, so3};
use rigcal::log::Drive;

fn write_ply(path: &std::path::Path, points: &[DVec3]) -> Result<()> {
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
        points.len()
    )
    .into_bytes();
    for p in points {
        for v in [p.x as f32, p.y as f32, p.z as f32] {
            bytes.write_all(&v.to_le_bytes())?;
        }
    }
    rigcal::util::write_atomic(path, &bytes)
        .with_context(|| format!("cannot write {}", path.display()))
}

fn matrix(t: Rigid) -> [[f64; 4]; 4] {
    let m = DMat4::from_rotation_translation(t.rotation, t.translation);
    let c = m.to_cols_array_2d();
    let mut rows = [[0.0; 4]; 4];
    for (r, row) in rows.iter_mut().enumerate() {
        for (col, v) in row.iter_mut().enumerate() {
            *v = c[col][r];
        }
    }
    rows
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [log, gt, out] = args.as_slice() else {
        bail!("usage: icp_compare LOG GROUND_TRUTH OUT_DIR");
    };
    let out = PathBuf::from(out);
    std::fs::create_dir_all(&out)?;
    let drive = Drive::open(std::path::Path::new(log))?;
    let reference = load_reference(std::path::Path::new(gt))?;
    let lidars: Vec<String> = reference
        .lidars()
        .map(|l| l.name.clone())
        .filter(|n| drive.stream(n).is_some())
        .collect();
    let [root, other, ..] = lidars.as_slice() else {
        bail!("{log} has fewer than two LiDARs of {gt}");
    };
    let x_root = reference
        .sensor(root)
        .map(|s| s.vehicle_from_sensor)
        .context("root")?;
    let truth = reference
        .sensor(other)
        .map(|s| s.vehicle_from_sensor)
        .context("other")?;
    let other_frames = &drive.stream(other).context("other stream")?.frames;
    let k = other_frames.len() / 2;
    let stamp = other_frames[k].stamp_nanos;
    let root_frames = &drive.stream(root).context("root stream")?.frames;
    let j = (0..root_frames.len())
        .min_by_key(|&j| (root_frames[j].stamp_nanos - stamp).abs())
        .context("no root sweep")?;
    let to_points = |s: &rigcal::log::LidarSweep| -> Vec<DVec3> {
        s.points_in_sensor
            .iter()
            .map(|p| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
            .filter(|p| p.length() > 0.5)
            .collect()
    };
    // The target in the source sweep's vehicle frame: both sweeps are deskewed to their
    // stamps, and the vehicle moves between the two stamps.
    let world_from = |stamp| drive.trajectory.world_from_vehicle(stamp);
    let source_from_target_vehicle =
        world_from(stamp)?.inverse() * world_from(root_frames[j].stamp_nanos)?;
    let target: Vec<DVec3> = to_points(&drive.load_sweep(root, j)?)
        .into_iter()
        .map(|p| source_from_target_vehicle.transform_point(x_root.transform_point(p)))
        .collect();
    let source = to_points(&drive.load_sweep(other, k)?);
    let start = Rigid::new(
        so3::exp(DVec3::new(0.3, -0.5, 0.8).normalize_or_zero() * 1f64.to_radians())
            * truth.rotation,
        truth.translation + DVec3::new(0.6, 0.7, -0.4).normalize_or_zero() * 0.10,
    );
    // Open3D uses every correspondence: so does rigcal here, for a like-for-like comparison.
    let mut config = IcpConfig {
        min_incidence_cos: 0.0,
        ..IcpConfig::default()
    };
    // For experiments: RIGCAL_ICP_FLATNESS overrides the flatness test of target normals.
    if let Some(f) = std::env::var("RIGCAL_ICP_FLATNESS")
        .ok()
        .and_then(|v| v.parse().ok())
    {
        config.max_flatness = f;
    }
    write_ply(&out.join("target.ply"), &target)?;
    write_ply(&out.join("source.ply"), &source)?;
    let case = serde_json::json!({
        "start": matrix(start),
        "truth": matrix(truth),
        "levels": config.levels,
        "iterations_per_level": config.iterations_per_level,
        "target_voxel_m": config.target_voxel_m,
        "normal_radius_m": 0.5,
        "huber_m": config.huber_m,
        "source": other, "target": root,
    });
    rigcal::util::write_atomic(
        &out.join("case.json"),
        serde_json::to_string_pretty(&case)?.as_bytes(),
    )?;
    let started = Instant::now();
    let points: Vec<SourcePoint> = source
        .iter()
        .map(|p| SourcePoint {
            in_sensor: *p,
            world_from_vehicle: Rigid::IDENTITY,
        })
        .collect();
    let mut icp = IcpProblem::new(&target, &points, start, config);
    let prepared = started.elapsed().as_secs_f64();
    let mut iterations = 0;
    while !icp.done {
        icp.step();
        iterations += 1;
    }
    let seconds = started.elapsed().as_secs_f64();
    let (rot, trans) = truth.difference(icp.vehicle_from_source);
    let (rot0, trans0) = truth.difference(start);
    println!(
        "{}",
        serde_json::json!({
            "tool": "rigcal",
            "seconds": seconds,
            "prepare_seconds": prepared,
            "iterations": iterations,
            "rotation_deg": rot.to_degrees(),
            "translation_cm": trans * 100.0,
            "start_rotation_deg": rot0.to_degrees(),
            "start_translation_cm": trans0 * 100.0,
            "fitness": icp.last.fitness,
            "inlier_rmse_cm": icp.last.inlier_rmse_m * 100.0,
            "source_points": source.len(),
            "target_points": target.len(),
            "target_with_normals": icp.target_points(),
        })
    );
    Ok(())
}
