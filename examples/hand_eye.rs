//! Fit every camera of a drive to its own motion (hand-eye against the trajectory) from the
//! ground truth and from perturbed starts, and print how far each ends from the truth.
//!
//! `cargo run --release --no-default-features --example hand_eye -- LOG.mcap GT.yaml [DEG CM SEEDS]`

use rigcal::calib::CalibrationFile;
use rigcal::classical::camera_motion::{DEFAULT_FRAMES, fit_camera};
use rigcal::log::Drive;
use rigcal::sim::synth::perturb_rig;

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (log, gt) = match (args.first(), args.get(1)) {
        (Some(l), Some(g)) => (l, g),
        _ => return Err("usage: hand_eye LOG.mcap GT.yaml [DEG CM SEEDS]".into()),
    };
    let number = |k: usize, default: f64| {
        args.get(k)
            .and_then(|s| s.parse::<f64>().ok())
            .unwrap_or(default)
    };
    let (deg, cm, seeds) = (number(2, 10.0), number(3, 100.0), number(4, 1.0) as u64);
    let drive = Drive::open(std::path::Path::new(log)).map_err(|e| e.to_string())?;
    let truth = CalibrationFile::load_rig(std::path::Path::new(gt)).map_err(|e| e.to_string())?;
    let frames = std::env::var("RIGCAL_FRAMES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(DEFAULT_FRAMES);
    for seed in 0..=seeds {
        let start = if seed == 0 {
            truth.clone()
        } else {
            perturb_rig(&truth, deg, cm, seed)
        };
        println!(
            "start: {}",
            if seed == 0 {
                "truth".to_string()
            } else {
                format!("{deg}° / {cm} cm, seed {seed}")
            }
        );
        for cam in truth.cameras() {
            let t = cam.vehicle_from_sensor;
            match fit_camera(&drive, &start, &cam.name, frames, &[], &|_, _, _| {}) {
                Ok(fit) => {
                    let f = fit.vehicle_from_camera;
                    let (rot, _) = t.difference(f);
                    let d = (f.translation - t.translation) * 100.0;
                    println!(
                        "  {:20} {:6.3}°  dx {:6.1} dy {:6.1} dz {:6.1} cm  pairs {}/{} res {:.2}° {:.2}° unobserved {:?}",
                        cam.name,
                        rot.to_degrees(),
                        d.x,
                        d.y,
                        d.z,
                        fit.pairs_used,
                        fit.pairs_given,
                        fit.rotation_residual_deg,
                        fit.direction_residual_deg,
                        fit.unobserved
                    );
                }
                Err(e) => println!("  {:20} {e}", cam.name),
            }
        }
    }
    Ok(())
}
