//! The studio: an egui/eframe desktop app over the library.
//!
//! The app only draws state and sends commands; everything it shows comes from the library
//! ([`crate::log::Drive`], [`crate::geometry::projection`]). `run` opens a window; the state
//! lives in [`state::Studio`], panels are `*_ui` functions in their own files.

pub mod checks;
pub mod demo;
pub mod export;
pub mod gpu_overlay;
pub mod optimiser;
mod overlay;
pub mod profile;
mod sensors;
pub mod state;
pub mod trajectory;
mod window;

use std::path::PathBuf;

pub use state::Studio;

/// Everything waiting in `rx`, and whether its sender is gone (a worker that ended, normally
/// or by panicking): a panel that waits for a worker's last message checks the second so it
/// never waits forever.
pub(crate) fn drain<T>(rx: &std::sync::mpsc::Receiver<T>) -> (Vec<T>, bool) {
    let mut messages = Vec::new();
    loop {
        match rx.try_recv() {
            Ok(m) => messages.push(m),
            Err(std::sync::mpsc::TryRecvError::Empty) => return (messages, false),
            Err(std::sync::mpsc::TryRecvError::Disconnected) => return (messages, true),
        }
    }
}

/// Open the studio window (blocks until it is closed).
pub fn run(
    log: Option<PathBuf>,
    calibration: Option<PathBuf>,
    session: Option<PathBuf>,
) -> anyhow::Result<()> {
    let launch = std::time::Instant::now();
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_inner_size([1600.0, 1000.0])
            .with_title("rigcal studio"),
        ..Default::default()
    };
    eframe::run_native(
        "rigcal studio",
        options,
        Box::new(move |cc| {
            // A session names its own log: open that instead of the demo.
            let log = log.or_else(|| {
                session
                    .as_deref()
                    .and_then(|p| crate::session::Session::load(p).ok())
                    .and_then(|s| s.log)
            });
            let mut studio = new_studio(cc, log, calibration);
            studio.enable_persistence();
            if let Some(path) = session {
                studio.restore_session(&path);
            }
            studio.profile = profile::Profile::from_env(launch);
            Ok(Box::new(studio))
        }),
    )
    .map_err(|e| anyhow::anyhow!("cannot open the studio window: {e} (is there a display? set DISPLAY or WAYLAND_DISPLAY, or use the CLI subcommands)"))
}

/// The studio as the window creates it: GPU overlay installed when there is a wgpu renderer,
/// then the log (or the demo drive) and an optional calibration. Tests build it the same way.
pub fn new_studio(
    cc: &eframe::CreationContext<'_>,
    log: Option<PathBuf>,
    calibration: Option<PathBuf>,
) -> Studio {
    let mut studio = bare_studio(cc);
    match log {
        Some(path) => studio.open_log(&path),
        None => demo::start(&mut studio),
    }
    if let Some(path) = calibration {
        studio.load_calibration(&path);
    }
    studio
}

/// The studio with its GPU overlay installed and nothing open (tests open what they need).
pub fn bare_studio(cc: &eframe::CreationContext<'_>) -> Studio {
    Studio {
        gpu: gpu_overlay::install(cc.wgpu_render_state.as_ref()),
        ..Studio::default()
    }
}
