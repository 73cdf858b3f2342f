//! A log far larger than memory once its chunks are decompressed, for the bounded-memory figure
//! in BENCHMARKS.md: GIGABYTES of point clouds (100 000 zero points, 2 MB each, so one chunk
//! apiece; zstd keeps the file small) at 10 Hz with a trajectory and a LiDAR on `/tf_static`.
//!
//!     cargo run --release --no-default-features --example big_log -- OUT.mcap GIGABYTES
//!     /usr/bin/time -v rigcal inspect OUT.mcap

use rigcal::geometry::Rigid;
use rigcal::sim::writer::Ros2McapWriter;

const POINTS: usize = 100_000;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [out, gigabytes] = args.as_slice() else {
        eprintln!("usage: big_log OUT.mcap GIGABYTES");
        std::process::exit(2);
    };
    let gigabytes: f64 = gigabytes.parse()?;
    let clouds = (gigabytes * 1e9 / (POINTS * 20) as f64).ceil() as i64;
    let mut w = Ros2McapWriter::create(out.as_ref())?;
    w.write_tf_static(0, &[("base_link".into(), "lidar".into(), Rigid::IDENTITY)])?;
    let (points, zeros) = (vec![[0.0f32; 3]; POINTS], vec![0.0f32; POINTS]);
    for i in 0..clouds {
        let stamp = i * 100_000_000;
        let pose = Rigid::new(glam::DQuat::IDENTITY, glam::DVec3::new(i as f64, 0.0, 0.0));
        w.write_tf(stamp, "map", "base_link", pose)?;
        w.write_pointcloud("/lidar/points", stamp, "lidar", &points, &zeros, &zeros)?;
        if i % 1000 == 999 {
            eprintln!("{} of {clouds} clouds", i + 1);
        }
    }
    w.finish()?;
    println!(
        "wrote {out}: {clouds} clouds, {:.1} GB of point data",
        clouds as f64 * (POINTS * 20) as f64 / 1e9
    );
    Ok(())
}
