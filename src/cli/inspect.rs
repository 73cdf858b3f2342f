//! `rigcal inspect LOG.mcap`: sensors, topics, counts, rates, time range, TF tree, problems and
//! what is missing for calibration, as plain text.

use std::fmt::Write;
use std::path::PathBuf;

use crate::calib::SensorKind;
use crate::log::{Drive, StampSource};

// What `rigcal inspect` takes (a plain comment: clap would take a doc comment for the
// subcommand's description).
#[derive(Clone, Debug, clap::Args)]
pub struct InspectArgs {
    /// The log (MCAP, ROS 2 or Foxglove schemas).
    pub log: PathBuf,
    /// Fixed frame of the trajectory (default: the parent of the densest /tf edge).
    #[arg(long)]
    pub fixed_frame: Option<String>,
    /// The vehicle frame (default: the child of that edge).
    #[arg(long)]
    pub vehicle_frame: Option<String>,
}

/// `rigcal inspect`: open the log with the frames asked for and print its report.
pub fn run(args: &InspectArgs) -> anyhow::Result<()> {
    use anyhow::Context;
    let options = crate::log::DriveOptions {
        fixed_frame: args.fixed_frame.clone(),
        vehicle_frame: args.vehicle_frame.clone(),
        ..Default::default()
    };
    let drive = Drive::open_with(&args.log, &options)
        .with_context(|| format!("cannot inspect {}", args.log.display()))?;
    super::print_stdout(&report(&drive))
}

fn secs(nanos: i64) -> f64 {
    nanos as f64 * 1e-9
}

/// The report as text (the binary prints it).
pub fn report(drive: &Drive) -> String {
    let mut o = String::new();
    let c = drive.container();
    let _ = writeln!(o, "file: {}", drive.path().display());
    let _ = writeln!(
        o,
        "container: {} bytes, {} chunks, {} channels, index: {}, profile: {}, library: {}",
        c.file_len,
        c.chunks.len(),
        c.channels.len(),
        if c.used_summary {
            "summary + chunk indexes"
        } else {
            "none (read linearly)"
        },
        c.profile.as_deref().unwrap_or("?"),
        c.library.as_deref().unwrap_or("?"),
    );
    if let Some((lo, hi)) = drive.time_range_nanos() {
        let _ = writeln!(
            o,
            "sensor time range: {:.3} .. {:.3} s ({:.2} s)",
            secs(lo),
            secs(hi),
            secs(hi - lo)
        );
    }

    let _ = writeln!(o, "\ntopics:");
    let _ = writeln!(
        o,
        "  {:<40} {:<36} {:<9} {:>7} {:>8}  status",
        "topic", "schema", "encoding", "count", "rate Hz"
    );
    for t in &drive.topics {
        let status = match (t.understood, t.failed) {
            (false, _) => "not used".to_string(),
            (true, 0) => "ok".to_string(),
            (true, n) => format!("{n} failed to decode"),
        };
        let _ = writeln!(
            o,
            "  {:<40} {:<36} {:<9} {:>7} {:>8.2}  {status}",
            t.topic,
            t.schema_name,
            t.message_encoding,
            t.count,
            t.rate_hz()
        );
    }

    let _ = writeln!(o, "\ntrajectory: {}", drive.trajectory_source);
    if let Some((lo, hi)) = drive.trajectory.time_range_nanos() {
        let _ = writeln!(
            o,
            "  covers {:.3} .. {:.3} s; extrapolates up to {:.0} ms",
            secs(lo),
            secs(hi),
            drive.trajectory.max_extrapolation_nanos as f64 * 1e-6
        );
    }

    let _ = writeln!(
        o,
        "\nsensors (vehicle frame '{}'):",
        drive.rig.vehicle_frame
    );
    for s in &drive.rig.sensors {
        let stream = drive.stream(&s.name);
        let frames = stream.map_or(0, |st| st.frames.len());
        let stamp = match stream.map(|st| st.stamp_source) {
            Some(StampSource::Header) => "header stamps",
            Some(StampSource::LogTime) => "LOG TIME (headers empty)",
            None => "-",
        };
        let (outside, extrapolated) = stream.map_or((0, 0), |st| {
            let range = drive.trajectory.time_range_nanos();
            let mut outside = 0;
            let mut extra = 0;
            for f in &st.frames {
                match (drive.trajectory.world_from_vehicle(f.stamp_nanos), range) {
                    (Err(_), _) => outside += 1,
                    (Ok(_), Some((lo, hi))) if f.stamp_nanos < lo || f.stamp_nanos > hi => {
                        extra += 1
                    }
                    _ => {}
                }
            }
            (outside, extra)
        });
        let t = s.vehicle_from_sensor.translation;
        let rpy = s.vehicle_from_sensor.roll_pitch_yaw_rad();
        let _ = writeln!(
            o,
            "  {:<16} {:<6} frames {:>5} ({stamp}) topic {}",
            s.name,
            s.kind.as_str(),
            frames,
            s.topics.join(", ")
        );
        let _ = writeln!(
            o,
            "      vehicle_from_sensor t = [{:.3}, {:.3}, {:.3}] m, rpy = [{:.2}, {:.2}, {:.2}] deg",
            t.x,
            t.y,
            t.z,
            rpy[0].to_degrees(),
            rpy[1].to_degrees(),
            rpy[2].to_degrees()
        );
        if let Some(c) = &s.camera {
            let _ = writeln!(
                o,
                "      {}×{} {} fx {:.1} fy {:.1} cx {:.1} cy {:.1}",
                c.width,
                c.height,
                c.model.as_str(),
                c.fx,
                c.fy,
                c.cx,
                c.cy
            );
        }
        if extrapolated > 0 {
            let _ = writeln!(
                o,
                "      {extrapolated} frames lie just outside the trajectory (extrapolated)"
            );
        }
        if outside > 0 {
            let _ = writeln!(
                o,
                "      {outside} frames lie outside the trajectory and cannot be used"
            );
        }
    }

    let _ = writeln!(o, "\nTF tree:");
    for (child, (parent, _)) in &drive.tf.static_edges {
        let _ = writeln!(o, "  {parent} → {child} (static)");
    }
    for ((parent, child), series) in &drive.tf.dynamic_edges {
        let _ = writeln!(
            o,
            "  {parent} → {child} (dynamic, {} samples)",
            series.len()
        );
    }

    let mut missing = Vec::new();
    if drive.trajectory.is_empty() {
        missing.push("a trajectory (dynamic /tf, odometry or poses)".to_string());
    }
    if drive.rig.lidars().count() == 0 {
        missing.push("any LiDAR point cloud topic".to_string());
    }
    if drive.rig.cameras().count() == 0 {
        missing.push("any camera image topic".to_string());
    }
    for s in drive
        .rig
        .sensors
        .iter()
        .filter(|s| s.kind == SensorKind::Camera && s.camera.is_none())
    {
        missing.push(format!("camera info for {}", s.name));
    }
    let _ = writeln!(
        o,
        "\nready for calibration: {}",
        if missing.is_empty() {
            "yes".to_string()
        } else {
            format!("no — missing {}", missing.join("; "))
        }
    );
    if !drive.problems.is_empty() {
        let _ = writeln!(o, "\nproblems ({}):", drive.problems.total());
        for p in drive.problems.iter().take(50) {
            let _ = writeln!(o, "  - {p}");
        }
        if drive.problems.total() > 50 {
            let _ = writeln!(o, "  … and {} more", drive.problems.total() - 50);
        }
    }
    o
}
