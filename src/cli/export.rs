//! `rigcal export`: write a calibration in another tool's format ([`crate::interop`]), refusing
//! an output that would overwrite the calibration being exported.

use std::path::PathBuf;

use anyhow::Context;

use crate::interop;

// What `rigcal export` takes (a plain comment: clap would take a doc comment for the
// subcommand's description).
#[derive(Clone, Debug, clap::Args)]
pub struct ExportArgs {
    /// The native calibration file.
    pub calibration: PathBuf,
    /// native | camera-info | mcap | urdf | ros2-static-tf | ros2-launch | autoware | opencv
    /// | kalibr | kitti | nuscenes
    #[arg(long)]
    pub format: interop::ExportFormat,
    /// The file to write; for camera-info and opencv a directory (one file per camera).
    #[arg(long)]
    pub out: PathBuf,
    /// Only these sensors, comma-separated (default: all).
    #[arg(long, value_delimiter = ',')]
    pub sensors: Vec<String>,
    /// opencv, kitti: the reference LiDAR (default: the first).
    #[arg(long)]
    pub lidar: Option<String>,
    /// kitti, kalibr: the reference camera, cam0 (default: the first).
    #[arg(long)]
    pub camera: Option<String>,
}

/// Export `args.calibration` and say, on standard error, every file written.
pub fn run(args: &ExportArgs) -> anyhow::Result<()> {
    // The library's errors already name the file and the cause: print them once.
    let doc = crate::calib::CalibrationFile::load(&args.calibration)
        .map_err(|e| anyhow::Error::msg(e.to_string()))?;
    let options = interop::ExportOptions {
        sensors: args.sensors.clone(),
        lidar: args.lidar.clone(),
        camera: args.camera.clone(),
    };
    let export = interop::export(&doc, args.format, &options)
        .with_context(|| format!("cannot export {}", args.calibration.display()))?;
    if let Some(p) = interop::paths(&export, &args.out)
        .iter()
        .find(|p| crate::util::same_file(&args.calibration, p))
    {
        anyhow::bail!(
            "--out {}: the export would overwrite the calibration being exported ({}); choose another path",
            args.out.display(),
            p.display()
        );
    }
    for path in interop::write(&export, &args.out)? {
        // On stderr: the export itself may be going to stdout.
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
