//! Ingest throughput on the real PandaSet drive, side by side with the official Python reader.
//!
//! `cargo bench --bench ingest [-- LOG.mcap]` (default ../shared/data/pandaset-002/pandaset-002.mcap).
//! Two levels of work, each timed best-of-3 from opening the file:
//! - messages: every message decoded (CDR), PointCloud2 points unpacked into arrays;
//! - full: additionally every image decoded to RGB pixels (what the studio and optimisers need).
//!
//! rigcal runs on 1 thread and on all cores; the Python reference
//! (`benches/ingest_reference.py`, mcap + mcap-ros2-support + numpy + Pillow) runs in the same
//! process tree, found as `$RIGCAL_PYTHON` (default `python3`). Results go to stdout as a
//! Markdown table for BENCHMARKS.md.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use rayon::prelude::*;
use rigcal::calib::SensorKind;
use rigcal::log::container::McapContainer;
use rigcal::log::decode::Codec;
use rigcal::log::pointcloud;
use rigcal::log::types::Decoded;
use rigcal::log::{Drive, DriveOptions};

#[derive(Default, Clone, Copy, Debug)]
struct Work {
    messages: usize,
    points: usize,
    pixels: usize,
}

/// Level "messages": scan every message, decode it, unpack clouds.
fn messages(path: &Path) -> Work {
    let container = McapContainer::open(path).unwrap();
    let (kept, problems) = container.scan(|_, ch, payload| {
        let mut w = Work {
            messages: 1,
            ..Work::default()
        };
        if let Some(codec) = Codec::for_channel(ch)
            && let Ok(decoded) = codec.decode(payload)
            && let Decoded::PointCloud(cloud) = decoded
        {
            w.points = pointcloud::to_sweep(&cloud).unwrap().len();
        }
        Some(w)
    });
    assert!(problems.is_empty(), "{problems:?}");
    kept.iter().fold(Work::default(), |a, (_, w)| Work {
        messages: a.messages + w.messages,
        points: a.points + w.points,
        pixels: 0,
    })
}

/// Level "full": open the indexed drive, decode every sweep and every image to pixels.
fn full(path: &Path) -> Work {
    let drive = Drive::open_with(
        path,
        &DriveOptions {
            image_cache_bytes: 1,
            ..DriveOptions::default()
        },
    )
    .unwrap();
    let jobs: Vec<(String, SensorKind, usize)> = drive
        .rig
        .sensors
        .iter()
        .filter_map(|s| {
            drive
                .stream(&s.name)
                .map(|st| (s.name.clone(), st.kind, st.frames.len()))
        })
        .flat_map(|(name, kind, n)| (0..n).map(move |i| (name.clone(), kind, i)))
        .collect();
    jobs.par_iter()
        .map(|(name, kind, i)| match kind {
            SensorKind::Lidar => Work {
                messages: 1,
                points: drive.load_sweep(name, *i).unwrap().len(),
                pixels: 0,
            },
            SensorKind::Camera => {
                let img = drive.load_image(name, *i).unwrap();
                Work {
                    messages: 1,
                    points: 0,
                    pixels: (img.width() * img.height()) as usize,
                }
            }
        })
        .reduce(Work::default, |a, b| Work {
            messages: a.messages + b.messages,
            points: a.points + b.points,
            pixels: a.pixels + b.pixels,
        })
}

fn best_of<F: Fn() -> Work + Sync>(threads: usize, reps: usize, f: F) -> (f64, Work) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let mut best = f64::INFINITY;
    let mut work = Work::default();
    for _ in 0..reps {
        let t0 = Instant::now();
        work = pool.install(&f);
        best = best.min(t0.elapsed().as_secs_f64());
    }
    (best, work)
}

fn python(path: &Path) -> Option<serde_json::Value> {
    let exe = std::env::var("RIGCAL_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/ingest_reference.py");
    let out = Command::new(&exe)
        .arg(&script)
        .arg(path)
        .arg("3")
        .output()
        .ok()?;
    if !out.status.success() {
        eprintln!(
            "python reference failed ({exe}): {}\n(pip install mcap mcap-ros2-support numpy pillow; set RIGCAL_PYTHON)",
            String::from_utf8_lossy(&out.stderr)
        );
        return None;
    }
    serde_json::from_slice(&out.stdout).ok()
}

fn main() {
    let path: PathBuf = std::env::args()
        .skip(1)
        .find(|a| a.ends_with(".mcap"))
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../shared/data/pandaset-002/pandaset-002.mcap")
        });
    let mb = std::fs::metadata(&path).unwrap().len() as f64 / 1e6;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!("file: {} ({mb:.1} MB), {cores} cores", path.display());
    let py = python(&path);
    println!(
        "| level | reader | threads | time (s) | MB/s | messages | points | pixels | vs Python |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for level in ["messages", "full"] {
        let py_secs = py.as_ref().and_then(|v| v[level]["secs"].as_f64());
        if let (Some(secs), Some(v)) = (py_secs, py.as_ref()) {
            let r = &v[level];
            println!(
                "| {level} | Python mcap + mcap-ros2-support | 1 | {secs:.3} | {:.0} | {} | {} | {} | 1.0× |",
                mb / secs,
                r["messages"],
                r["points"],
                r["pixels"]
            );
        }
        for threads in [1, cores] {
            let (secs, w) = match level {
                "messages" => best_of(threads, 3, || messages(&path)),
                _ => best_of(threads, 3, || full(&path)),
            };
            let ratio = py_secs.map_or("n/a".into(), |p| format!("{:.1}×", p / secs));
            println!(
                "| {level} | rigcal | {threads} | {secs:.3} | {:.0} | {} | {} | {} | {ratio} |",
                mb / secs,
                w.messages,
                w.points,
                w.pixels
            );
        }
    }
}
