//! Fit every camera of a drive to its own motion (hand-eye against the trajectory), then its
//! translation to the LiDAR map (the LiDARs at the truth), from the ground truth and from
//! perturbed starts, and print how far each ends from the truth after each fit; then, from the
//! same start, the camera's whole pose fitted to the map (`lidar_translation::fit_pose`, which
//! needs no turns: it runs on a straight drive too).
//!
//! `cargo run --release --no-default-features --example hand_eye -- LOG.mcap GT [DEG CM SEEDS]`,
//! `GT` a native calibration file or a dataset's ground_truth.json.

mod reference;

use rigcal::classical::camera_motion::{DEFAULT_FRAMES, camera_pairs, fit_rig_cameras, lidar_map};
use rigcal::classical::lidar_translation::fit_pose;
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
    let truth = reference::at_reference(&drive.rig, gt)?;
    let frames = std::env::var("RIGCAL_FRAMES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(DEFAULT_FRAMES);
    let map = lidar_map(&drive, &truth).map_err(|e| e.to_string())?;
    let names: Vec<String> = truth.cameras().map(|c| c.name.clone()).collect();
    // The matches and the trajectory do not depend on the start: read each camera's once.
    let mut straight_pairs = std::collections::HashMap::new();
    for name in &names {
        let found = camera_pairs(&drive, &truth, name, frames, &[], false, &|_, _, _| {})
            .map_err(|e| e.to_string())?;
        straight_pairs.insert(name.clone(), found);
    }
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
        let (fitted, outcomes) = fit_rig_cameras(
            &drive,
            &start,
            &names,
            frames,
            &[],
            Some(&map),
            &|_, _, _| {},
        );
        for o in outcomes {
            let Some(t) = truth.sensor(&o.name).map(|s| s.vehicle_from_sensor) else {
                continue;
            };
            let row = |f: rigcal::geometry::Rigid| {
                let d = (f.translation - t.translation) * 100.0;
                format!(
                    "{:6.3}° dx {:6.1} dy {:6.1} dz {:6.1} cm",
                    t.difference(f).0.to_degrees(),
                    d.x,
                    d.y,
                    d.z
                )
            };
            let began = start.sensor(&o.name).map(|s| s.vehicle_from_sensor);
            let pose = match (straight_pairs.get(&o.name), began) {
                (Some(found), Some(began)) => {
                    fit_pose(&map, &found.pairs, &found.world_from_vehicle, began)
                        .map_err(|e| e.to_string())
                }
                _ => Err("no pairs or no start".to_string()),
            };
            println!(
                "  {:20} start {}  | pose on the LiDAR map {}",
                o.name,
                began.map(row).unwrap_or_default(),
                match &pose {
                    Ok(p) => format!(
                        "{}  {} points, median {:.1} cm, unobserved {:?}",
                        row(p.vehicle_from_camera),
                        p.points,
                        p.median_residual_m * 100.0,
                        p.unobserved
                    ),
                    Err(e) => e.clone(),
                }
            );
            let Ok(fit) = &o.fit else {
                println!("  {:20} {}", "", o.summary());
                continue;
            };
            let end = fitted.sensor(&o.name).map(|s| s.vehicle_from_sensor);
            // The rotation error about the camera's own axes (degrees).
            let axes_deg =
                rigcal::geometry::so3::log(t.rotation.inverse() * fit.vehicle_from_camera.rotation)
                    * 180.0
                    / std::f64::consts::PI;
            println!(
                "  {:20} hand-eye {} (camera axes {:+.3} {:+.3} {:+.3}°, σ {:.3} {:.3} {:.3}°)  | LiDAR map {}  pairs {}/{} unobserved {:?}{}",
                o.name,
                row(fit.vehicle_from_camera),
                axes_deg.x,
                axes_deg.y,
                axes_deg.z,
                fit.rotation_sigma_deg.x,
                fit.rotation_sigma_deg.y,
                fit.rotation_sigma_deg.z,
                end.map(row).unwrap_or_default(),
                fit.pairs_used,
                fit.pairs_given,
                fit.unobserved,
                match &o.translation {
                    Some(Ok(tf)) => format!(
                        " map: {} points, median {:.1} cm, unobserved {:?}",
                        tf.points,
                        tf.median_residual_m * 100.0,
                        tf.unobserved
                    ),
                    Some(Err(e)) => format!(" map: {e}"),
                    None => String::new(),
                }
            );
        }
    }
    Ok(())
}
