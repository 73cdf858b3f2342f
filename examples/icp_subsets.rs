#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Where the PandarGT's ICP answer comes from: the same registration as `calibrate --method icp`
//! (every second LiDAR against the first, each source sweep against the first LiDAR's nearest
//! three, all deskewed; the default `IcpConfig`), started at the reference and run on subsets of
//! the source returns: all of them, the ground only, everything above it, near and far, and
//! the first and second half of the drive. Each row prints the result's difference from the
//! reference, as a rotation about the source LiDAR's own axes and a translation in the vehicle
//! frame. Subsets that agree with each other but not with the reference point at the
//! reference; subsets that disagree point at the sensors (e.g. a beam-elevation error that
//! bends the ground).
//!
//! `cargo run --release --no-default-features --example icp_subsets -- LOG GROUND_TRUTH [SWEEPS]`

use std::path::PathBuf;

use glam::DVec3;
use rigcal::calib::dataset_json::load_reference;
use rigcal::classical::icp::{IcpConfig, IcpProblem, SourcePoint};
use rigcal::classical::icp_calibrator::{reference_points_near, source_points};
use rigcal::geometry::Rigid;
use rigcal::log::{Drive, spread_evenly};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let drive = Drive::open(&PathBuf::from(&args[1])).unwrap();
    let reference = load_reference(&PathBuf::from(&args[2])).unwrap();
    let sweeps: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(16);
    let lidars: Vec<_> = reference.lidars().collect();
    let (fixed, moving) = (lidars[0], lidars[1]);
    let target_frames = drive.frames_within(&fixed.name, &[]);
    let source_stream = drive.stream(&moving.name).unwrap();
    // (source point, its sweep's place in the drive 0..1), and the target.
    let mut source: Vec<(SourcePoint, f64)> = Vec::new();
    let mut target = Vec::new();
    let picked = spread_evenly(&drive.frames_within(&moving.name, &[]), sweeps);
    for (n, &i) in picked.iter().enumerate() {
        let sweep = drive.load_sweep(&moving.name, i).unwrap();
        let place = n as f64 / picked.len().max(1) as f64;
        source.extend(
            source_points(&sweep, &drive.trajectory, 1)
                .into_iter()
                .map(|p| (p, place)),
        );
        target.extend(
            reference_points_near(
                &drive,
                &fixed.name,
                fixed.vehicle_from_sensor,
                &target_frames,
                source_stream.frames[i].stamp_nanos,
            )
            .unwrap(),
        );
    }
    let truth = moving.vehicle_from_sensor;
    // Height above the ground in the vehicle frame: the ground is the 5th percentile of the
    // source's heights under the reference (the fixed LiDAR's frame is the vehicle's on PandaSet).
    let in_vehicle: Vec<DVec3> = source
        .iter()
        .map(|(p, _)| truth.transform_point(p.in_sensor))
        .collect();
    let mut heights: Vec<f64> = in_vehicle.iter().map(|p| p.z).collect();
    heights.sort_by(f64::total_cmp);
    let ground_z = heights[heights.len() / 20];
    println!(
        "{} source returns over {} sweeps, {} target; ground at z = {ground_z:.2} m (vehicle frame)",
        source.len(),
        picked.len(),
        target.len()
    );
    let min_cos: Vec<f64> = std::env::var("RIGCAL_MIN_COS")
        .ok()
        .map(|v| v.split(',').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or_else(|| vec![0.0]);
    let subsets: [(&str, Box<dyn Fn(DVec3, f64) -> bool>); 8] = [
        ("all", Box::new(|_, _| true)),
        (
            "ground (< 0.3 m above)",
            Box::new(move |p, _| p.z < ground_z + 0.3),
        ),
        (
            "above the ground",
            Box::new(move |p, _| p.z >= ground_z + 0.3),
        ),
        ("above 1 m", Box::new(move |p, _| p.z >= ground_z + 1.0)),
        ("nearer than 20 m", Box::new(|p, _| p.length() < 20.0)),
        ("20 m and farther", Box::new(|p, _| p.length() >= 20.0)),
        ("first half of the drive", Box::new(|_, t| t < 0.5)),
        ("second half of the drive", Box::new(|_, t| t >= 0.5)),
    ];
    println!(
        "| subset | returns | rotation about the {} x / y / z (°) | translation, vehicle x / y / z (cm) | angle | distance |",
        moving.name
    );
    println!("|---|---|---|---|---|---|");
    for (name, keep, cos) in subsets
        .iter()
        .flat_map(|(n, k)| min_cos.iter().map(move |c| (n, k, *c)))
    {
        let chosen: Vec<SourcePoint> = source
            .iter()
            .zip(&in_vehicle)
            .filter(|((_, t), p)| keep(**p, *t))
            .map(|((s, _), _)| *s)
            .collect();
        let config = IcpConfig {
            min_incidence_cos: cos,
            ..IcpConfig::default()
        };
        let mut problem = IcpProblem::new(&target, &chosen, truth, config);
        problem.run();
        let fitted: Rigid = problem.vehicle_from_source;
        let error = truth.inverse() * fitted;
        let w = error.rotation.to_scaled_axis();
        let t = (fitted.translation - truth.translation) * 100.0;
        let (angle, distance) = truth.difference(fitted);
        println!(
            "| {name}, |cos| ≥ {cos} | {} | {:+.3} / {:+.3} / {:+.3} | {:+.2} / {:+.2} / {:+.2} | {:.3}° | {:.2} cm |",
            chosen.len(),
            w.x.to_degrees(),
            w.y.to_degrees(),
            w.z.to_degrees(),
            t.x,
            t.y,
            t.z,
            angle.to_degrees(),
            distance * 100.0
        );
    }
}
