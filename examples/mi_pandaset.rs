#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Mutual-information calibration of the PandaSet cameras against the Pandar64 from a perturbed
//! start, errors against the recorded reference before and after, and MI at the reference.
//! `cargo run --release --example mi_pandaset -- [DEG] [CM] [SEED] [FRAMES]`

use glam::DVec3;
use rigcal::classical::mi_calibrator::MiCalibrator;
use rigcal::classical::mutual_info::MiConfig;
use rigcal::log::Drive;
use rigcal::optim::runner::Calibrator;

fn main() {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let (deg, cm) = (
        args.first().copied().unwrap_or(1.0),
        args.get(1).copied().unwrap_or(10.0),
    );
    let seed = args.get(2).copied().unwrap_or(1.0) as u64;
    let frames = args.get(3).copied().unwrap_or(3.0) as usize;
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/pandaset-002/pandaset-002.mcap");
    let drive = Drive::open(&path).unwrap();
    let reference = drive.rig.clone();
    let mut start = reference.clone();
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut unit = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let v = DVec3::new(
            (state % 2001) as f64 - 1000.0,
            ((state >> 11) % 2001) as f64 - 1000.0,
            ((state >> 22) % 2001) as f64 - 1000.0,
        );
        v.normalize_or(DVec3::X)
    };
    let cameras: Vec<String> = reference.cameras().map(|c| c.name.clone()).collect();
    for c in &cameras {
        let s = start.sensor_mut(c).unwrap();
        s.vehicle_from_sensor = s
            .vehicle_from_sensor
            .perturbed_right(unit() * deg.to_radians(), unit() * cm / 100.0);
    }
    let t0 = std::time::Instant::now();
    let mut cal = MiCalibrator::from_drive(
        &drive,
        &start,
        "pandar64",
        &cameras,
        frames,
        &[],
        MiConfig::default(),
    )
    .unwrap();
    let prep = t0.elapsed().as_secs_f64();
    let mut steps = 0;
    while steps < cal.max_steps() {
        steps += 1;
        if cal.step().done {
            break;
        }
    }
    let total = t0.elapsed().as_secs_f64();
    println!(
        "MI, {deg}° / {cm} cm start (seed {seed}), {frames} frames: prep {prep:.1} s, {steps} steps, total {total:.1} s"
    );
    println!(
        "| camera | start ° | start cm | final ° | final cm | MI start | MI final | MI at reference |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let end = cal.best();
    for (p, s) in cal.problems() {
        let r = reference.sensor(&p.camera).unwrap().vehicle_from_sensor;
        let (r0, t0) = start
            .sensor(&p.camera)
            .unwrap()
            .vehicle_from_sensor
            .difference(r);
        let (r1, t1) = end
            .sensor(&p.camera)
            .unwrap()
            .vehicle_from_sensor
            .difference(r);
        println!(
            "| {} | {:.3} | {:.1} | {:.3} | {:.1} | {:.4} | {:.4} | {:.4} |",
            p.camera,
            r0.to_degrees(),
            t0 * 100.0,
            r1.to_degrees(),
            t1 * 100.0,
            p.mi(s.start),
            s.best_mi,
            p.mi(r)
        );
    }
    // Where each camera ended, as a rotation vector in the vehicle (Pandar64) frame, and the
    // translation's offset (est · ref⁻¹ and est − ref).
    for (p, _) in cal.problems() {
        let r = reference.sensor(&p.camera).unwrap().vehicle_from_sensor;
        let e = end.sensor(&p.camera).unwrap().vehicle_from_sensor;
        let w = (e.rotation * r.rotation.inverse()).to_scaled_axis();
        let t = (e.translation - r.translation) * 100.0;
        println!(
            "{}: rotation (vehicle) {:+.2} {:+.2} {:+.2} °, translation {:+.1} {:+.1} {:+.1} cm",
            p.camera,
            w.x.to_degrees(),
            w.y.to_degrees(),
            w.z.to_degrees(),
            t.x,
            t.y,
            t.z
        );
    }
}
