//! The studio's session on disk: what it holds (the log, the calibration, edits and their
//! history, the view), saved and restored on request, autosaved when it changes and on exit.

use super::*;

impl Studio {
    /// The session as it stands.
    pub fn session(&self) -> Session {
        let mut s = Session::new();
        // An absolute path: a session restored from another directory still finds its log.
        s.log = self
            .drive
            .as_ref()
            .map(|d| std::path::absolute(d.path()).unwrap_or_else(|_| d.path().to_path_buf()));
        s.segments_nanos = self.segments.iter().map(|&(a, b)| [a, b]).collect();
        s.set_rigs(&self.initial, &self.current, self.optimiser.best.as_ref());
        s.locks = self.locks.clone();
        s.camera = self.camera;
        s.frame = self.frame;
        s.history = self.optimiser.history.clone();
        let o = &self.overlay;
        s.view = Some(crate::session::SessionView {
            grid: self.grid,
            color_by: match o.color_by {
                ColorBy::Range => "range",
                ColorBy::Intensity => "intensity",
                ColorBy::Height => "height",
                ColorBy::Lidar => "lidar",
            }
            .into(),
            extrinsics: self.view.label().into(),
            accumulate: o.accumulate,
            occlusion: o.occlusion,
            point_size: o.point_size,
            max_range_m: o.max_range_m,
            tab: match self.tab {
                Tab::Optimise => "optimise",
                Tab::Checks => "checks",
                Tab::Export => "export",
            }
            .into(),
            export_format: self
                .export
                .format
                .map(|f| f.name().to_string())
                .unwrap_or_default(),
            optimiser_method: self.optimiser.method.key().into(),
            camera_readout_ms: self.camera_readout_ms.map(|(a, b)| [a, b]),
        });
        s
    }

    pub fn save_session(&mut self, path: &Path) {
        match self.session().save(path) {
            Ok(()) => self
                .status
                .push(format!("saved session {}", path.display())),
            Err(e) => self.status.push(format!("error: {e}")),
        }
    }

    /// Restore a session: open its log, then its rigs, segments, locks and history. Anything
    /// wrong is an error in the status line; what was open stays open.
    pub fn restore_session(&mut self, path: &Path) {
        let session = match Session::load(path) {
            Ok(s) => s,
            Err(e) => {
                self.status.push(format!("error: {e}"));
                return;
            }
        };
        self.apply_session(&session, path);
    }

    pub(crate) fn apply_session(&mut self, session: &Session, path: &Path) {
        // A run owns the rig; restoring half a session beside it would mislead.
        if self.optimiser_owns_the_rig() {
            return;
        }
        let Some(log) = &session.log else {
            self.status.push(format!(
                "error: {}: the session names no log",
                path.display()
            ));
            return;
        };
        let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
        let opened_before = self.drive.as_ref().map(|d| absolute(d.path()));
        if opened_before != Some(absolute(log)) {
            let n = self.status.len();
            self.open_log(log);
            if self.status[n..].iter().any(|s| s.starts_with("error")) {
                return;
            }
        }
        // A rig the session holds but that does not validate is named, not silently skipped.
        let mut unusable = Vec::new();
        let mut rig = |which: &str, doc: &Option<CalibrationFile>| match doc {
            Some(d) => d
                .to_rig(path)
                .map_err(|e| unusable.push(format!("its {which} rig: {e}")))
                .ok(),
            None => None,
        };
        let (initial, current, best) = (
            rig("initial", &session.initial),
            rig("current", &session.current),
            rig("best", &session.best),
        );
        for what in unusable {
            self.status.push(format!("error: {what}"));
        }
        if let Some(r) = initial {
            self.initial = self.merged(&r);
        }
        if let Some(r) = current {
            let merged = self.merged(&r);
            self.edit(merged);
        }
        self.optimiser.best = best.map(|r| self.merged(&r));
        // Segments in order and within the drive (its sensors' and its trajectory's span);
        // others are dropped with a word.
        let range = self.drive.as_ref().and_then(|d| {
            [d.time_range_nanos(), d.trajectory.time_range_nanos()]
                .into_iter()
                .flatten()
                .reduce(|(a0, a1), (b0, b1)| (a0.min(b0), a1.max(b1)))
        });
        let (segments, dropped): (Vec<(i64, i64)>, Vec<(i64, i64)>) = session
            .segments_nanos
            .iter()
            .map(|s| (s[0], s[1]))
            .partition(|&(a, b)| a <= b && range.is_some_and(|(t0, t1)| a >= t0 && b <= t1));
        if !dropped.is_empty() {
            self.status.push(format!(
                "error: {}: {} segment(s) outside the drive or reversed were dropped",
                path.display(),
                dropped.len()
            ));
        }
        self.segments = segments;
        self.locks = session.locks.clone();
        self.camera = session.camera;
        self.frame = session.frame;
        self.optimiser.history = session.history.clone();
        if let Some(v) = &session.view {
            self.grid = v.grid;
            self.overlay.color_by = match v.color_by.as_str() {
                "intensity" => ColorBy::Intensity,
                "height" => ColorBy::Height,
                "lidar" => ColorBy::Lidar,
                _ => ColorBy::Range,
            };
            self.view = [
                ExtrinsicsView::Initial,
                ExtrinsicsView::Current,
                ExtrinsicsView::Best,
                ExtrinsicsView::GroundTruth,
            ]
            .into_iter()
            .find(|x| x.label() == v.extrinsics)
            .unwrap_or(ExtrinsicsView::Current);
            self.overlay.accumulate = v.accumulate.min(30);
            self.overlay.occlusion = v.occlusion;
            self.overlay.point_size = v.point_size.clamp(0.5, 6.0);
            self.overlay.max_range_m = v.max_range_m.clamp(1.0, 300.0);
            self.tab = match v.tab.as_str() {
                "checks" => Tab::Checks,
                "export" => Tab::Export,
                _ => Tab::Optimise,
            };
            self.export.format = v.export_format.parse().ok();
            if let Some(m) = crate::app::optimiser::Method::from_key(&v.optimiser_method) {
                self.optimiser.method = m;
            }
            // Only what the panel could have set: finite, within ±1000 ms.
            self.camera_readout_ms = v
                .camera_readout_ms
                .filter(|r| r.iter().all(|v| v.is_finite() && v.abs() <= 1000.0))
                .map(|[a, b]| (a, b));
        }
        self.overlays.clear();
        self.status
            .push(format!("restored session {}", path.display()));
    }

    /// The cameras' readout ([`Self::camera_readout_ms`]) as row times.
    pub fn readout(&self) -> crate::geometry::RowTimes {
        self.camera_readout_ms
            .map_or(crate::geometry::RowTimes::GLOBAL, |(first, last)| {
                crate::geometry::RowTimes::from_millis(first, last)
            })
    }

    /// This drive's rig with the extrinsics/intrinsics of `other`'s matching sensors.
    pub(super) fn merged(&self, other: &Rig) -> Rig {
        let mut out = self.current.clone();
        for s in &other.sensors {
            if let Some(t) = out.sensor_mut(&s.name) {
                t.vehicle_from_sensor = s.vehicle_from_sensor;
                if s.camera.is_some() {
                    t.camera = s.camera.clone();
                }
            }
        }
        out
    }

    /// Write the autosave when the session changed, checking at most once a second. Not while
    /// an optimiser is running; its result is saved when it ends.
    pub fn autosave_if_changed(&mut self) {
        let Some(path) = self.autosave.clone() else {
            return;
        };
        if self.drive.is_none() || self.optimiser.run.is_some() {
            return;
        }
        // Building the session clones the rigs and the loss history: not on every frame.
        let now = std::time::Instant::now();
        if self
            .autosave_checked
            .is_some_and(|t| now.duration_since(t).as_secs_f64() < 1.0)
        {
            return;
        }
        self.autosave_checked = Some(now);
        let session = self.session();
        if self.saved_session.as_ref() == Some(&session) {
            return;
        }
        // A failed write (a full disk) is said once and retried every second; the status
        // line shows that autosave is failing until a write succeeds again.
        match session.save(&path) {
            Ok(()) => {
                self.saved_session = Some(session);
                if std::mem::take(&mut self.autosave_failing) {
                    self.status.push("autosave works again".into());
                }
            }
            Err(e) => {
                if !self.autosave_failing {
                    self.status.push(format!("error: autosave: {e}"));
                }
                self.autosave_failing = true;
            }
        }
    }

    /// On closing the window: write the autosave now, whatever the one-second throttle or a
    /// running optimiser (whose live extrinsics are saved as the current rig).
    pub fn autosave_on_exit(&mut self) {
        self.autosave_checked = None;
        self.optimiser.run = None;
        self.autosave_if_changed();
    }
}
