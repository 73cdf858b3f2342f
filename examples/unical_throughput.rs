#![allow(clippy::unwrap_used, clippy::expect_used)]
//! UniCal's throughput at the CPU preset (`DepthCalibConfig::default()`) on a simulated drive
//! (urban scene, pandaset rig, figure8, 3 s of sweeps of both LiDARs): iterations per second of
//! the geometry initialisation and of the rendering steps, field samples per second, an
//! estimate of the useful arithmetic per sample, and peak memory.
//! `cargo run --release --no-default-features --example unical_throughput -- [RENDER_STEPS]`
//! (`scripts/bench-unical-throughput.sh` puts the machine's dense f32 matrix-multiply rate
//! beside it.)
//!
//! Samples per step are counted on batches drawn like the step's own (every LiDAR's
//! `rays_per_sensor` rays: their sample distances), once every ten steps. Arithmetic per
//! sample: the geometry MLP's multiply-adds (2 FLOPs each) forward, twice that backward (input
//! and weight gradients), plus the hash grid's trilinear interpolation of every level forward
//! and its scatter backward; activations, compositing and the optimiser are not counted.

mod common;

use rigcal::unical::depth_calib::{DepthCalibConfig, DepthCalibration};

fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn main() {
    let render_steps: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(60);
    let seconds = 3.0;
    let (rig, traj, world) = common::drive(seconds);
    let lidars = common::lidars_at_truth(&world, &rig, &traj, seconds);
    let config = DepthCalibConfig::default();
    let (init_steps, rays_per_sensor) = (config.geometry_init_steps, config.rays_per_sensor);
    let started = std::time::Instant::now();
    let mut calib = DepthCalibration::new(config, traj, lidars);
    let setup_s = started.elapsed().as_secs_f64();
    let started = std::time::Instant::now();
    for _ in 0..init_steps {
        calib.step();
    }
    let init_s = started.elapsed().as_secs_f64();
    let (mut render_s, mut samples, mut counted_steps) = (0.0, 0usize, 0usize);
    for k in 0..render_steps {
        if k % 10 == 0 {
            for s in 0..calib.poses.len() {
                samples += calib
                    .lidar_batch(s, rays_per_sensor)
                    .iter()
                    .map(|r| r.taus_m.len())
                    .sum::<usize>();
            }
            counted_steps += 1;
        }
        let t = std::time::Instant::now();
        calib.step();
        render_s += t.elapsed().as_secs_f64();
    }
    let samples_per_step = samples as f64 / counted_steps.max(1) as f64;
    let mlp_macs: usize = calib
        .field
        .geo
        .layers
        .iter()
        .map(|l| l.inputs * l.outputs)
        .sum();
    let grid = &calib.field.grid.config;
    let grid_flops = grid.levels * rigcal::unical::hash_grid::F * 8 * 2;
    // Forward 2·MACs, backward twice that; the grid's interpolation forward and scatter back.
    let flops_per_sample = 3 * 2 * mlp_macs + 2 * grid_flops;
    let it_s = render_steps as f64 / render_s;
    let samples_s = samples_per_step * it_s;
    println!(
        "threads {} · setup (occupancy, field) {setup_s:.1} s",
        rayon::current_num_threads()
    );
    println!(
        "geometry initialisation: {init_steps} iterations in {init_s:.1} s ({:.2} it/s)",
        init_steps as f64 / init_s
    );
    println!(
        "rendering steps: {render_steps} in {render_s:.1} s ({it_s:.2} it/s), {samples_per_step:.0} samples per step, {:.3} M samples/s",
        samples_s / 1e6
    );
    println!(
        "arithmetic per sample ≈ {flops_per_sample} FLOP (MLP {mlp_macs} multiply-adds, grid {} levels × {} features) → {:.2} GFLOP/s",
        grid.levels,
        rigcal::unical::hash_grid::F,
        samples_s * flops_per_sample as f64 / 1e9
    );
    println!("peak RSS {:.0} MB", peak_rss_mb());
}
