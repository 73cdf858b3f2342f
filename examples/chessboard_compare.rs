#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Checkerboard corners on the simulator's checkerboard scene, for the side-by-side with
//! OpenCV's `findChessboardCornersSB` (`scripts/bench-chessboard.sh`): every camera of the
//! pandaset rig is rendered at full size; around each board whose 35 inner corners all fall
//! inside the image (from the ground truth), a crop is written as PNG with the true corners, and
//! rigcal's detector runs on the same crop. One JSON line per board on stdout.
//! `cargo run --release --example chessboard_compare -- OUT_DIR [SCALE]`

use std::time::Instant;

use glam::DVec2;
use rigcal::features::chessboard::{ImageBoard, find_chessboards, grey_levels};
use rigcal::geometry::Trajectory;
use rigcal::sim::camera_sim::{self, Exposure, RayTable};
use rigcal::sim::rigs::{RigPreset, SimRig};
use rigcal::sim::trajectories::{self, TrajectoryConfig, TrajectoryKind};
use rigcal::sim::world::{SceneKind, World};

/// Mean corner error under the best of the four orders a 7 × 5 grid allows (as-is, rows
/// reversed, columns reversed, both).
fn best_error(found: &ImageBoard, truth: &[DVec2]) -> f64 {
    let (c, r) = (found.cols, found.rows);
    let mut best = f64::MAX;
    for (flip_c, flip_r) in [(false, false), (true, false), (false, true), (true, true)] {
        let mut sum = 0.0;
        for row in 0..r {
            for col in 0..c {
                let fc = if flip_c { c - 1 - col } else { col };
                let fr = if flip_r { r - 1 - row } else { row };
                sum += (found.corner(fc, fr) - truth[row * c + col]).length();
            }
        }
        best = best.min(sum / (c * r) as f64);
    }
    best
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let out =
        std::path::PathBuf::from(args.get(1).cloned().unwrap_or_else(|| "chessboards".into()));
    let scale: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1.0);
    std::fs::create_dir_all(&out).unwrap();
    let tcfg = TrajectoryConfig {
        kind: TrajectoryKind::Stationary,
        duration_secs: 2.0,
        rate_hz: 100.0,
        speed_mps: 8.0,
        seed: 7,
    };
    let traj = Trajectory::new(trajectories::generate(&tcfg));
    let world = World::build(
        SceneKind::Checkerboard,
        &trajectories::path_polyline(&tcfg, 1.0),
        7,
    );
    let rig = SimRig::preset(RigPreset::Pandaset).scaled(scale);
    let world_from_vehicle = traj.world_from_vehicle(1_000_000_000).unwrap();
    for cam in &rig.cameras {
        let world_from_camera = world_from_vehicle * cam.vehicle_from_camera;
        let camera_from_world = world_from_camera.inverse();
        let img = camera_sim::render(
            &world,
            &RayTable::new(&cam.intrinsics),
            &cam.intrinsics,
            world_from_camera,
            Exposure {
                gain: 1.0,
                tint: [1.0; 3],
                noise_sigma: 2.0,
                seed: 1,
            },
        );
        let (w, h) = (img.width() as usize, img.height() as usize);
        for (b, board) in world.boards.iter().enumerate() {
            let truth: Option<Vec<DVec2>> = board
                .inner_corners()
                .iter()
                .map(|p| {
                    let pc = camera_from_world.transform_point(p.as_dvec3());
                    let px = cam.intrinsics.project(pc)?;
                    (pc.z > 0.0
                        && px.x >= 0.0
                        && px.y >= 0.0
                        && px.x < w as f64 - 1.0
                        && px.y < h as f64 - 1.0)
                        .then_some(px)
                })
                .collect();
            let Some(truth) = truth else { continue };
            // Crop: the corners' box grown by 1.5 squares (the board's margin and some
            // background), at least 20 px.
            let (lo, hi) = truth
                .iter()
                .fold((DVec2::MAX, DVec2::MIN), |(a, b), p| (a.min(*p), b.max(*p)));
            let pad = ((hi - lo).max_element() / 6.0 * 1.5).max(20.0);
            let x0 = (lo.x - pad).max(0.0) as usize;
            let y0 = (lo.y - pad).max(0.0) as usize;
            let x1 = ((hi.x + pad) as usize).min(w);
            let y1 = ((hi.y + pad) as usize).min(h);
            let crop = image::imageops::crop_imm(
                &img,
                x0 as u32,
                y0 as u32,
                (x1 - x0) as u32,
                (y1 - y0) as u32,
            )
            .to_image();
            let name = format!("{}-board{}", cam.name, b);
            crop.save(out.join(format!("{name}.png"))).unwrap();
            let offset = DVec2::new(x0 as f64, y0 as f64);
            let truth_crop: Vec<[f64; 2]> =
                truth.iter().map(|p| (*p - offset).to_array()).collect();
            let grey = grey_levels(&crop);
            let (cw, ch) = (crop.width() as usize, crop.height() as usize);
            let started = Instant::now();
            let found = find_chessboards(&grey, cw, ch, (7, 5), (0, 0, cw, ch));
            let seconds = started.elapsed().as_secs_f64();
            let truth_local: Vec<DVec2> = truth.iter().map(|p| *p - offset).collect();
            let error = found
                .iter()
                .map(|f| best_error(f, &truth_local))
                .fold(f64::NAN, |a, e| if a.is_nan() || e < a { e } else { a });
            println!(
                "{}",
                serde_json::json!({
                    "name": name,
                    "camera": cam.name,
                    "board": b,
                    "crop": [x0, y0, x1, y1],
                    "truth": truth_crop,
                    "tool": "rigcal",
                    "found": !found.is_empty(),
                    "mean_error_px": if error.is_nan() { None } else { Some(error) },
                    "seconds": seconds,
                })
            );
        }
    }
}
