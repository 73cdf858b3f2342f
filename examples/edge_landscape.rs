#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Where edge alignment's cost is lowest on a real log: for every camera against the log's
//! reference LiDAR (its first), the cost at the dataset's reference extrinsics, the cost along
//! each camera rotation axis through the reference (±2°), and where the compass search ends from
//! starts turned 1° (translation at the reference, then also 10 cm off). A minimum away from the
//! reference is the objective's bias, not the search's. `EDGE_TAU=6` changes the truncation
//! (the library's is 20 px); `EDGE_WINDOW_DEG=0.1` takes the silhouettes from an angular window
//! instead of one elevation bin per beam ([`occluding_points`], `EDGE_AZ` its azimuth reach,
//! default 0.6°); `EDGE_PNG_DIR=DIR` draws each camera's first frame at the reference.
//! Measured and not kept: docs/experiments/real-camera-methods.md.
//! `cargo run --release --example edge_landscape -- LOG.mcap GROUND_TRUTH.json [FRAMES]`

use glam::DVec3;
use rigcal::geometry::Rigid;
use rigcal::log::Drive;
use rigcal::optim::edge_align::{CompassSearch, EdgeAlignment};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let drive = Drive::open(std::path::Path::new(&args[1])).unwrap();
    let reference =
        rigcal::calib::dataset_json::load_reference(std::path::Path::new(&args[2])).unwrap();
    let frames: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(4);
    let mut truth = drive.rig.clone();
    for s in &mut truth.sensors {
        if let Some(r) = reference.sensor(&s.name) {
            s.vehicle_from_sensor = r.vehicle_from_sensor;
        }
    }
    let lidar = truth.lidars().next().unwrap().name.clone();
    let cameras: Vec<String> = truth.cameras().map(|c| c.name.clone()).collect();
    for cam in &cameras {
        let at_truth = truth.sensor(cam).unwrap().vehicle_from_sensor;
        let mut p = EdgeAlignment::from_drive(
            &drive,
            &truth,
            (cam, &lidar),
            frames,
            &[],
            drive.camera_readout,
        )
        .unwrap();
        if let Some(el_window) = env_f32("EDGE_WINDOW_DEG") {
            // Silhouettes from an angular window instead of one elevation bin per beam, for the
            // same sweeps (matched by stamp: a frame outside the trajectory was left out).
            let az_window = env_f32("EDGE_AZ").unwrap_or(0.6);
            let pairs =
                rigcal::optim::edge_align::sweep_image_pairs(&drive, cam, &lidar, frames, &[])
                    .unwrap();
            let vehicle_from_lidar = truth.sensor(&lidar).unwrap().vehicle_from_sensor;
            for f in &mut p.frames {
                let pair = pairs
                    .iter()
                    .find(|pair| pair.sweep.stamp_nanos == f.sweep_stamp_nanos)
                    .unwrap();
                let idx = occluding_points(&pair.sweep.points_in_sensor, el_window, az_window);
                f.points_in_vehicle = rigcal::optim::edge_align::points_in_vehicle_at(
                    &pair.sweep,
                    &idx,
                    &drive.trajectory,
                    vehicle_from_lidar,
                    pair.image_stamp_nanos + drive.camera_readout.middle_nanos(),
                )
                .unwrap();
            }
            p.keep_visible(at_truth);
        }
        if let Some(tau) = env_f32("EDGE_TAU") {
            p.truncation_px = tau as f64;
        }
        let c0 = p.cost(at_truth);
        println!(
            "{cam} × {lidar}: {} frames, {} points, cost at the reference {c0:.3} px",
            p.frames.len(),
            p.point_count()
        );
        let mut d = p.distances(at_truth);
        d.sort_by(f32::total_cmp);
        let share = |r: f32| d.iter().filter(|&&x| x <= r).count() as f64 / d.len() as f64;
        println!(
            "  at the reference: median {:.1} px; within 1 px {:.2}, 2 px {:.2}, 3 px {:.2}, 5 px {:.2}",
            d[d.len() / 2],
            share(1.0),
            share(2.0),
            share(3.0),
            share(5.0)
        );
        if let Ok(dir) = std::env::var("EDGE_PNG_DIR") {
            draw(&p, at_truth, &format!("{dir}/{cam}.png"));
        }
        for axis in 0..3 {
            let row: Vec<String> = (-8..=8)
                .map(|k| {
                    let mut w = DVec3::ZERO;
                    w[axis] = (k as f64 * 0.25).to_radians();
                    format!(
                        "{:.2}",
                        p.cost(at_truth.perturbed_right(w, DVec3::ZERO)) - c0
                    )
                })
                .collect();
            println!(
                "  axis {axis} (−2°..2° by 0.25°, minus the reference's): {}",
                row.join(" ")
            );
        }
        for seed in 301..306u64 {
            let turned = rigcal::sim::synth::perturb_rig(&truth, 1.0, 0.0, seed);
            let shifted = rigcal::sim::synth::perturb_rig(&truth, 1.0, 10.0, seed);
            let mut line = format!("  seed {seed}:");
            for (label, rig) in [("1°", &turned), ("1°/10 cm", &shifted)] {
                let start = rig.sensor(cam).unwrap().vehicle_from_sensor;
                let (end, cost) = search(&p, start);
                let (r0, _) = at_truth.difference(start);
                let (r1, _) = at_truth.difference(end);
                line += &format!(
                    "  {label}: {:.3}° → {:.3}° (cost {:.3} → {cost:.3})",
                    r0.to_degrees(),
                    r1.to_degrees(),
                    p.cost(start)
                );
            }
            println!("{line}");
        }
    }
}

/// A number from the environment, if set.
fn env_f32(name: &str) -> Option<f32> {
    std::env::var(name).ok().map(|v| v.parse().unwrap())
}

fn search(p: &EdgeAlignment, start: Rigid) -> (Rigid, f64) {
    let mut s = CompassSearch::new(p, start);
    for _ in 0..300 {
        if s.converged() {
            break;
        }
        s.step(p);
    }
    (s.best, s.best_cost)
}

/// The first frame's edge map (grey: distance < 1 px) with the silhouette points at `pose`
/// (green within 2 px of an edge, red beyond).
fn draw(p: &EdgeAlignment, pose: Rigid, path: &str) {
    let f = &p.frames[0];
    let mut img = image::RgbImage::from_fn(f.width as u32, f.height as u32, |x, y| {
        let d = f.distance_px[y as usize * f.width + x as usize];
        if d < 0.5 {
            image::Rgb([160, 160, 160])
        } else {
            image::Rgb([0, 0, 0])
        }
    });
    let camera_from_vehicle = pose.inverse();
    for q in &f.points_in_vehicle {
        let c = camera_from_vehicle.transform_point(*q);
        let Some(px) = p.intrinsics.project(c) else {
            continue;
        };
        let (x, y) = (px.x.round() as i64, px.y.round() as i64);
        if x < 1 || y < 1 || x >= f.width as i64 - 1 || y >= f.height as i64 - 1 {
            continue;
        }
        let d = f.distance_px[y as usize * f.width + x as usize];
        let colour = if d <= 2.0 {
            image::Rgb([0, 255, 0])
        } else {
            image::Rgb([255, 40, 40])
        };
        for (dx, dy) in [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)] {
            img.put_pixel((x + dx) as u32, (y + dy) as u32, colour);
        }
    }
    img.save(path).unwrap();
}

/// Indices of occluding points: a point whose nearest neighbour to the left or to the right in
/// azimuth, among the points within `elevation_window_deg` of its elevation and
/// `azimuth_window_deg` of its azimuth (seen from the LiDAR's origin), is farther by more than
/// max(0.5 m, 10 %): the nearer side of a depth edge, as
/// `rigcal::eval::edges::depth_discontinuities` finds it on one beam.
///
/// Unlike that detector this needs no beam structure: a multi-laser LiDAR's lasers sit
/// centimetres off its origin, so one beam's elevation *from the origin* changes with range
/// (about offset / range: 0.6° for 4 cm at 4 m), and a near object and the background behind it
/// on the same beam fall in different elevation bins; a cropped or reordered cloud has no ring
/// order either. The window (0.1° suits beams 0.17° or more apart) finds the background point
/// beside a near one whichever laser measured it, while the ground's beams stay apart.
fn occluding_points(
    points_in_lidar: &[[f32; 3]],
    elevation_window_deg: f32,
    azimuth_window_deg: f32,
) -> Vec<usize> {
    use std::collections::HashMap;
    let (el_w, az_w) = (elevation_window_deg.max(1e-3), azimuth_window_deg.max(1e-3));
    let az_cells = ((360.0 / az_w).floor() as i32).max(1);
    // (elevation °, azimuth ° in [0, 360), range m) of every point at least 0.5 m away.
    let keys: Vec<Option<(f32, f32, f32)>> = points_in_lidar
        .iter()
        .map(|p| {
            let r_xy = (p[0] * p[0] + p[1] * p[1]).sqrt();
            let range = (r_xy * r_xy + p[2] * p[2]).sqrt();
            (range >= 0.5 && range.is_finite()).then(|| {
                let az = p[1].atan2(p[0]).to_degrees().rem_euclid(360.0);
                (p[2].atan2(r_xy).to_degrees(), az, range)
            })
        })
        .collect();
    let cell = |el: f32, az: f32| {
        (
            (el / el_w).floor() as i32,
            ((az / az_w).floor() as i32).rem_euclid(az_cells),
        )
    };
    let mut grid: HashMap<(i32, i32), Vec<u32>> = HashMap::new();
    for (i, k) in keys.iter().enumerate() {
        if let Some((el, az, _)) = *k {
            grid.entry(cell(el, az)).or_default().push(i as u32);
        }
    }
    let mut out = Vec::new();
    for (i, k) in keys.iter().enumerate() {
        let Some((el, az, range)) = *k else { continue };
        let (ce, ca) = cell(el, az);
        let jump = (0.5f32).max(0.1 * range);
        // The nearest point on each side in azimuth among those within the elevation window:
        // the generalisation of a beam's neighbours to points measured by any laser.
        let (mut left, mut right) = ((f32::MAX, 0.0f32), (f32::MAX, 0.0f32));
        for de in -1..=1 {
            for da in -1..=1 {
                let Some(cell_points) = grid.get(&(ce + de, (ca + da).rem_euclid(az_cells))) else {
                    continue;
                };
                for &j in cell_points {
                    let Some((o_el, o_az, o_range)) = keys[j as usize] else {
                        continue;
                    };
                    let d_az = (o_az - az + 540.0).rem_euclid(360.0) - 180.0;
                    if j as usize == i || (o_el - el).abs() > el_w || d_az.abs() > az_w {
                        continue;
                    }
                    let side = if d_az < 0.0 { &mut left } else { &mut right };
                    if d_az.abs() < side.0 {
                        *side = (d_az.abs(), o_range);
                    }
                }
            }
        }
        let behind = [left, right]
            .iter()
            .any(|&(d_az, o_range)| d_az < f32::MAX && o_range - range > jump);
        if behind {
            out.push(i);
        }
    }
    out
}
