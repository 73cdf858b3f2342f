//! `rigcal synth`: simulate a drive with known ground truth ([`crate::sim::synth`]) and write it
//! as a ROS 2 MCAP, with the true extrinsics beside it.

use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::sim::{rigs, synth, trajectories::TrajectoryKind, world::SceneKind};

// What `rigcal synth` takes (a plain comment: clap would take a doc comment for the
// subcommand's description).
#[derive(Clone, Debug, clap::Args)]
pub struct SynthArgs {
    /// urban | parking-lot | featureless | checkerboard
    #[arg(long, default_value = "urban")]
    pub scene: String,
    /// pandaset | truck | kitti, or a native calibration file
    #[arg(long, default_value = "pandaset")]
    pub rig: String,
    /// straight | circle | s-curve | figure8 | flower | stationary
    #[arg(long, default_value = "figure8")]
    pub trajectory: String,
    /// Length of the drive (seconds).
    #[arg(long, default_value_t = 8.0)]
    pub seconds: f64,
    /// Seed of the scene's layout and textures, the trajectory's variation and the
    /// perturbation of the initial guess.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Rotation error of the initial guess written to /tf_static, per sensor (degrees).
    #[arg(long, default_value_t = 0.0)]
    pub perturb_deg: f64,
    /// Translation error of the initial guess, per sensor (centimetres).
    #[arg(long, default_value_t = 0.0)]
    pub perturb_cm: f64,
    /// Image size factor, e.g. 0.5 for half-size images.
    #[arg(long, default_value_t = 1.0)]
    pub scale: f64,
    /// Camera frame rate (Hz); LiDARs run at their own rate.
    #[arg(long, default_value_t = 10.0)]
    pub camera_hz: f64,
    /// The drive to write (ROS 2 MCAP; /tf_static holds the initial guess).
    #[arg(long)]
    pub out: PathBuf,
    /// The true extrinsics, as a native calibration file.
    #[arg(long)]
    pub ground_truth: PathBuf,
}

/// Simulate and write the drive, with a progress bar and what was written on standard error.
pub fn run(args: &SynthArgs) -> anyhow::Result<()> {
    let scene: SceneKind = args.scene.parse().map_err(anyhow::Error::msg)?;
    let trajectory: TrajectoryKind = args.trajectory.parse().map_err(anyhow::Error::msg)?;
    let rig = &args.rig;
    let sim_rig = match rig.parse::<rigs::RigPreset>() {
        Ok(preset) => rigs::SimRig::preset(preset),
        Err(_) => rigs::SimRig::from_calibration_file(Path::new(rig)).with_context(|| {
            format!(
                "--rig '{rig}' is neither a preset (pandaset, truck, kitti) nor a readable calibration file"
            )
        })?,
    };
    let mut cfg = synth::SynthConfig::new(scene, sim_rig, trajectory, args.seconds, args.seed);
    cfg.perturb_deg = args.perturb_deg;
    cfg.perturb_cm = args.perturb_cm;
    cfg.scale = args.scale;
    cfg.camera_rate_hz = args.camera_hz;
    let started = std::time::Instant::now();
    let mut bar = super::progress::Progress::new("synth", 1);
    let result = synth::synthesize(&cfg, &args.out, &args.ground_truth, &mut |done, total| {
        bar.report(done, total)
    })
    .with_context(|| format!("cannot synthesize {}", args.out.display()))?;
    bar.finish();
    eprintln!(
        "wrote {} ({} sweeps, {} images) and {} in {:.1} s",
        args.out.display(),
        result.sweeps,
        result.images,
        args.ground_truth.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
