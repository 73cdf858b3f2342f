//! Studio sessions: what a user had open and had done, saved atomically and restored.
//!
//! A session file (JSON, `rigcal_session: 1`) names the log, the selected time segments, the
//! initial / current / best rigs (as native calibration documents), axis locks, the shown
//! camera and frame, and the optimiser's loss history. The studio autosaves one after every
//! change to [`autosave_path`], so a crash loses nothing; [`RecentFiles`] remembers what was
//! opened. GUI-free, so it is tested headless.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::calib::{CalibrationFile, Rig};

pub const SESSION_VERSION: u32 = 1;

#[derive(Debug, Error)]
pub enum SessionError {
    #[error("{path}: cannot read: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: cannot write: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: not a rigcal session file: {source}")]
    Parse {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error(
        "{path}: session version {found} is not supported (this build reads {SESSION_VERSION})"
    )]
    Version { path: PathBuf, found: u32 },
}

/// Per sensor: which of x, y, z, roll, pitch, yaw are locked against edits and optimisers.
pub type AxisLocks = [bool; 6];

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Session {
    pub rigcal_session: u32,
    pub log: Option<PathBuf>,
    /// Selected time ranges `[start, end]` in nanoseconds (sensor clock).
    #[serde(default)]
    pub segments_nanos: Vec<[i64; 2]>,
    pub initial: Option<CalibrationFile>,
    pub current: Option<CalibrationFile>,
    #[serde(default)]
    pub best: Option<CalibrationFile>,
    #[serde(default)]
    pub locks: BTreeMap<String, AxisLocks>,
    #[serde(default)]
    pub camera: usize,
    #[serde(default)]
    pub frame: usize,
    /// Optimiser loss history: (step, [(term, value)]).
    #[serde(default)]
    pub history: Vec<(usize, Vec<(String, f64)>)>,
    /// How the viewport looked.
    #[serde(default)]
    pub view: Option<SessionView>,
}

/// The viewport's settings, as words and numbers so the file stays readable.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionView {
    /// Every camera at once.
    #[serde(default)]
    pub grid: bool,
    /// range | intensity | height | lidar
    #[serde(default = "default_color_by")]
    pub color_by: String,
    /// initial | current | best | ground truth
    #[serde(default = "default_extrinsics")]
    pub extrinsics: String,
    #[serde(default)]
    pub accumulate: usize,
    #[serde(default = "default_true")]
    pub occlusion: bool,
    #[serde(default = "default_point_size")]
    pub point_size: f32,
    #[serde(default = "default_max_range")]
    pub max_range_m: f32,
    /// The right-hand panel: optimise | checks | export
    #[serde(default)]
    pub tab: String,
    /// The export panel's format (a `rigcal export --format` name; empty: native).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub export_format: String,
    /// The optimiser panel's method (`edge`, `icp`, `mi`, `target`, `pose-graph`,
    /// `unical-lidar`, `unical`; empty: the default).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub optimiser_method: String,
    /// The cameras' rolling-shutter readout set under the image (first and last row, ms after
    /// each image's stamp; the overlay and UniCal's runs use it); absent: a global shutter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_readout_ms: Option<[f64; 2]>,
}

fn default_color_by() -> String {
    "range".into()
}
fn default_extrinsics() -> String {
    "current".into()
}
fn default_true() -> bool {
    true
}
fn default_point_size() -> f32 {
    2.0
}
fn default_max_range() -> f32 {
    80.0
}

impl Session {
    pub fn new() -> Self {
        Self {
            rigcal_session: SESSION_VERSION,
            ..Self::default()
        }
    }

    pub fn set_rigs(&mut self, initial: &Rig, current: &Rig, best: Option<&Rig>) {
        self.initial = Some(CalibrationFile::from_rig(initial));
        self.current = Some(CalibrationFile::from_rig(current));
        self.best = best.map(CalibrationFile::from_rig);
    }

    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    pub fn save(&self, path: &Path) -> Result<(), SessionError> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|source| SessionError::Write {
                path: path.to_path_buf(),
                source,
            })?;
        }
        crate::util::write_atomic(path, self.to_json().as_bytes()).map_err(|source| {
            SessionError::Write {
                path: path.to_path_buf(),
                source,
            }
        })
    }

    pub fn load(path: &Path) -> Result<Self, SessionError> {
        let text = std::fs::read_to_string(path).map_err(|source| SessionError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let session: Session =
            serde_json::from_str(&text).map_err(|source| SessionError::Parse {
                path: path.to_path_buf(),
                source,
            })?;
        if session.rigcal_session != SESSION_VERSION {
            return Err(SessionError::Version {
                path: path.to_path_buf(),
                found: session.rigcal_session,
            });
        }
        Ok(session)
    }
}

/// rigcal's per-user state folder: `$XDG_CACHE_HOME/rigcal` or `~/.cache/rigcal`.
pub fn state_dir() -> PathBuf {
    crate::sim::demo::demo_dir()
}

/// Where the studio autosaves its session after every change.
pub fn autosave_path() -> PathBuf {
    state_dir().join(AUTOSAVE_NAME)
}

const AUTOSAVE_NAME: &str = "autosave.rigcal-session.json";
const PREVIOUS_NAME: &str = "previous.rigcal-session.json";

/// The autosave of the previous run, set aside at start-up (File ▸ Restore last session).
pub fn previous_session_path() -> PathBuf {
    state_dir().join(PREVIOUS_NAME)
}

/// How many runs' autosaves are kept before the previous one's (`previous-1` … `previous-5`).
pub const EARLIER_SESSIONS_KEPT: usize = 5;

/// The name of the autosave set aside `n` runs before the previous one (`n` from 1).
fn earlier_session_name(n: usize) -> String {
    format!("previous-{n}.rigcal-session.json")
}

/// At start-up: the autosave becomes the previous run's session, and the sessions before it
/// move one place back (the oldest of [`EARLIER_SESSIONS_KEPT`] is dropped). A run that never
/// restores its predecessor so does not cost a crashed run's work at the next start.
pub fn set_autosave_aside() -> std::io::Result<()> {
    set_autosave_aside_in(&state_dir())
}

fn set_autosave_aside_in(dir: &Path) -> std::io::Result<()> {
    let (autosave, previous) = (dir.join(AUTOSAVE_NAME), dir.join(PREVIOUS_NAME));
    if !autosave.exists() {
        return Ok(());
    }
    for n in (1..EARLIER_SESSIONS_KEPT).rev() {
        let from = dir.join(earlier_session_name(n));
        if from.exists() {
            std::fs::rename(&from, dir.join(earlier_session_name(n + 1)))?;
        }
    }
    if previous.exists() {
        std::fs::rename(&previous, dir.join(earlier_session_name(1)))?;
    }
    std::fs::rename(&autosave, previous)
}

/// Where the session of `log` is kept when another log is opened over its edits: named by the
/// log's file stem and a hash of its whole path (two logs with one name keep two files).
pub fn set_aside_path(log: &Path) -> PathBuf {
    use std::hash::{Hash, Hasher};
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    std::path::absolute(log)
        .unwrap_or_else(|_| log.to_path_buf())
        .hash(&mut hasher);
    let stem: String = log
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
        .chars()
        .map(|c| {
            if c.is_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    state_dir().join(format!(
        "set-aside-{stem}-{:08x}.rigcal-session.json",
        hasher.finish() as u32
    ))
}

/// Most recently opened files, newest first, kept in a small text file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RecentFiles {
    pub paths: Vec<PathBuf>,
}

const RECENT_MAX: usize = 10;

impl RecentFiles {
    pub fn default_path() -> PathBuf {
        state_dir().join("recent.txt")
    }

    /// Read the list; a missing or unreadable file is an empty list.
    pub fn load(path: &Path) -> Self {
        let paths = std::fs::read_to_string(path)
            .map(|t| {
                t.lines()
                    .filter(|l| !l.trim().is_empty())
                    .map(PathBuf::from)
                    .take(RECENT_MAX)
                    .collect()
            })
            .unwrap_or_default();
        Self { paths }
    }

    pub fn push(&mut self, file: &Path) {
        let file = std::fs::canonicalize(file).unwrap_or_else(|_| file.to_path_buf());
        self.paths.retain(|p| *p != file);
        self.paths.insert(0, file);
        self.paths.truncate(RECENT_MAX);
    }

    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        let text: String = self
            .paths
            .iter()
            .map(|p| format!("{}\n", p.display()))
            .collect();
        crate::util::write_atomic(path, text.as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::{Sensor, SensorKind};
    use crate::geometry::Rigid;
    use glam::{DQuat, DVec3};

    /// Seven start-ups, each after a run that autosaved: the last run's session is the
    /// previous one and the five before it are kept, newest first.
    #[test]
    fn start_ups_keep_the_last_runs_sessions() {
        let dir = tempfile::tempdir().unwrap();
        for run in 0..7 {
            std::fs::write(dir.path().join(AUTOSAVE_NAME), format!("run {run}")).unwrap();
            set_autosave_aside_in(dir.path()).unwrap();
        }
        let read = |name: String| std::fs::read_to_string(dir.path().join(name)).ok();
        assert_eq!(read(PREVIOUS_NAME.into()).as_deref(), Some("run 6"));
        for n in 1..=EARLIER_SESSIONS_KEPT {
            assert_eq!(
                read(earlier_session_name(n)),
                Some(format!("run {}", 6 - n))
            );
        }
        assert_eq!(read(earlier_session_name(EARLIER_SESSIONS_KEPT + 1)), None);
        assert!(!dir.path().join(AUTOSAVE_NAME).exists());
        // A start-up after a run that saved nothing moves nothing.
        set_autosave_aside_in(dir.path()).unwrap();
        assert_eq!(read(PREVIOUS_NAME.into()).as_deref(), Some("run 6"));
    }

    fn rig(yaw: f64) -> Rig {
        Rig {
            vehicle_frame: "base_link".into(),
            sensors: vec![Sensor {
                name: "lidar".into(),
                kind: SensorKind::Lidar,
                frame_id: "lidar".into(),
                topics: vec!["/lidar".into()],
                camera: None,
                vehicle_from_sensor: Rigid::new(
                    DQuat::from_rotation_z(yaw),
                    DVec3::new(1.0, 0.0, 2.0),
                ),
            }],
        }
    }

    /// A scratch folder, removed when dropped.
    fn tmp() -> tempfile::TempDir {
        tempfile::Builder::new()
            .prefix("rigcal-session-")
            .tempdir()
            .unwrap()
    }

    #[test]
    fn a_session_round_trips() {
        let mut s = Session::new();
        s.log = Some("/data/drive.mcap".into());
        s.segments_nanos = vec![[1, 5_000_000_000], [7_000_000_000, 9_000_000_000]];
        s.set_rigs(&rig(0.0), &rig(0.01), Some(&rig(0.02)));
        s.locks
            .insert("lidar".into(), [true, false, false, false, false, true]);
        s.camera = 2;
        s.frame = 17;
        s.history = vec![
            (0, vec![("edge".into(), 3.5)]),
            (1, vec![("edge".into(), 2.5)]),
        ];
        let dir = tmp();
        let path = dir.path().join("a.json");
        s.save(&path).unwrap();
        let back = Session::load(&path).unwrap();
        assert_eq!(back, s);
        let r = back.current.unwrap().to_rig(&path).unwrap();
        assert!(
            r.sensors[0]
                .vehicle_from_sensor
                .difference(rig(0.01).sensors[0].vehicle_from_sensor)
                .0
                < 1e-12
        );
    }

    #[test]
    fn bad_session_files_are_errors_naming_the_file() {
        let dir = tmp();
        let path = dir.path().join("bad.json");
        std::fs::write(&path, "{ not json").unwrap();
        let e = Session::load(&path).unwrap_err().to_string();
        assert!(
            e.contains("bad.json") && e.contains("not a rigcal session"),
            "{e}"
        );
        std::fs::write(
            &path,
            r#"{"rigcal_session": 99, "log": null, "initial": null, "current": null}"#,
        )
        .unwrap();
        let e = Session::load(&path).unwrap_err().to_string();
        assert!(e.contains("version 99"), "{e}");
        let e = Session::load(&dir.path().join("missing.json"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("missing.json") && e.contains("cannot read"),
            "{e}"
        );
    }

    #[test]
    fn recent_files_keep_the_newest_first_without_duplicates() {
        let dir = tmp();
        let path = dir.path().join("recent.txt");
        let mut r = RecentFiles::default();
        for i in 0..12 {
            r.push(Path::new(&format!("/nonexistent/{i}.mcap")));
        }
        r.push(Path::new("/nonexistent/5.mcap"));
        assert_eq!(r.paths.len(), RECENT_MAX);
        assert_eq!(r.paths[0], PathBuf::from("/nonexistent/5.mcap"));
        assert_eq!(r.paths.iter().filter(|p| p.ends_with("5.mcap")).count(), 1);
        r.save(&path).unwrap();
        assert_eq!(RecentFiles::load(&path), r);
        assert!(
            RecentFiles::load(&dir.path().join("none.txt"))
                .paths
                .is_empty()
        );
    }
}
