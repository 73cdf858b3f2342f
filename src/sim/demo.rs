//! The studio's embedded demo drive: a short simulated urban drive with a perturbed initial
//! guess, generated on first start and cached (`$XDG_CACHE_HOME/rigcal` or `~/.cache/rigcal`).
//!
//! Half-size images and cameras at 2.5 Hz keep the first start to well under a minute on two
//! cores; the files are written atomically, so an interrupted generation leaves no half-drive.

use std::path::{Path, PathBuf};

use super::rigs::{RigPreset, SimRig};
use super::synth::{SimError, SynthConfig, synthesize};
use super::trajectories::TrajectoryKind;
use super::world::SceneKind;

/// Bump when the demo's content changes so caches regenerate.
pub const DEMO_VERSION: u32 = 1;

/// The demo's recipe.
pub fn demo_config() -> SynthConfig {
    let mut cfg = SynthConfig::new(
        SceneKind::Urban,
        SimRig::preset(RigPreset::Pandaset),
        TrajectoryKind::Figure8,
        4.0,
        7,
    );
    cfg.scale = 0.5;
    cfg.camera_rate_hz = 2.5;
    cfg.perturb_deg = 1.5;
    cfg.perturb_cm = 5.0;
    cfg
}

/// Where the demo is cached.
pub fn demo_dir() -> PathBuf {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir);
    base.join("rigcal")
}

/// Paths of the demo drive and its ground truth in `dir`.
pub fn demo_paths(dir: &Path) -> (PathBuf, PathBuf) {
    (
        dir.join(format!("demo-v{DEMO_VERSION}.mcap")),
        dir.join(format!("demo-v{DEMO_VERSION}-ground-truth.yaml")),
    )
}

/// The demo drive in `dir`, generated first if it is not there (progress: done, total).
pub fn ensure_demo(
    dir: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(PathBuf, PathBuf), SimError> {
    ensure_drive(dir, &demo_config(), progress)
}

/// [`ensure_demo`] with another recipe (tests use a smaller drive).
pub fn ensure_drive(
    dir: &Path,
    config: &SynthConfig,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(PathBuf, PathBuf), SimError> {
    let (mcap, gt) = demo_paths(dir);
    if mcap.is_file() && gt.is_file() {
        return Ok((mcap, gt));
    }
    std::fs::create_dir_all(dir).map_err(|e| {
        SimError::Config(format!(
            "cannot create the cache folder {}: {e}",
            dir.display()
        ))
    })?;
    synthesize(config, &mcap, &gt, progress)?;
    Ok((mcap, gt))
}
