//! One way to load a frame in a run: a sweep or image that does not decode is reported once
//! and skipped.
//!
//! [`Drive::open`](super::Drive::open) decodes headers only, so a cut-short point cloud or a
//! garbled JPEG passes the index and fails when a run loads it. Every calibrator, the pipeline
//! and `eval` load their frames through [`Drive::sweep_or_skip`] and [`Drive::image_or_skip`]:
//! a frame that fails becomes a [`Problem`] (topic, log time, what was wrong; the file is the
//! drive's) in the drive's list of skipped frames, and the caller goes on without it. Messages
//! the open itself found broken (a point cloud cut short) are not in the index at all; they are
//! counted with them. A front end prints [`Drive::skipped_summary`] at the end of a run and
//! records [`Drive::skipped`] in its output. The list is bounded by the drive's frames (one entry per frame, however often
//! it is asked for).

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use image::RgbImage;

use super::error::{LogError, Problem};
use super::{Drive, LidarSweep};

/// The frames a drive's runs skipped, one per (sensor, frame index).
#[derive(Debug, Default)]
pub struct SkippedFrames(Mutex<BTreeMap<(String, usize), Problem>>);

impl SkippedFrames {
    fn record(&self, sensor: &str, index: usize, error: LogError) {
        let problem = match error {
            LogError::Message {
                topic,
                log_time_nanos,
                what,
                ..
            } => Problem {
                topic: Some(topic),
                log_time_nanos: Some(log_time_nanos),
                what: format!("{sensor} frame {index}: {what}"),
            },
            other => Problem::file(format!("{sensor} frame {index}: {other}")),
        };
        if let Ok(mut skipped) = self.0.lock() {
            skipped.entry((sensor.to_owned(), index)).or_insert(problem);
        }
    }
}

impl Drive {
    /// Sweep `index` of a LiDAR, or `None` once its failure is recorded (see the module doc).
    pub fn sweep_or_skip(&self, sensor: &str, index: usize) -> Option<LidarSweep> {
        self.load_sweep(sensor, index)
            .map_err(|e| self.skipped_frames.record(sensor, index, e))
            .ok()
    }

    /// Image `index` of a camera, or `None` once its failure is recorded.
    pub fn image_or_skip(&self, sensor: &str, index: usize) -> Option<Arc<RgbImage>> {
        self.load_image(sensor, index)
            .map_err(|e| self.skipped_frames.record(sensor, index, e))
            .ok()
    }

    /// Every sensor message left out so far: those [`Drive::open`](super::Drive::open)
    /// found broken (a point cloud cut short: left out of the index) and those a run could
    /// not decode, as `(sensor, problem)` in sensor and time order.
    pub fn skipped(&self) -> Vec<(String, Problem)> {
        let mut out: Vec<(String, Problem)> = self
            .problems
            .iter()
            .filter(|p| p.log_time_nanos.is_some())
            .filter_map(|p| {
                let topic = p.topic.as_deref()?;
                let stream = self.streams.iter().find(|s| s.topic == topic)?;
                Some((stream.sensor.clone(), p.clone()))
            })
            .collect();
        if let Ok(skipped) = self.skipped_frames.0.lock() {
            out.extend(skipped.iter().map(|((s, _), p)| (s.clone(), p.clone())));
        }
        out.sort_by(|a, b| (&a.0, a.1.log_time_nanos).cmp(&(&b.0, b.1.log_time_nanos)));
        out
    }

    /// One line for the end of a run: how many frames were left out, per sensor, and the first
    /// one's reason; `None` when none was.
    pub fn skipped_summary(&self) -> Option<String> {
        let skipped = self.skipped();
        let (_, first) = skipped.first()?;
        let mut per_sensor: BTreeMap<&str, usize> = BTreeMap::new();
        for (sensor, _) in &skipped {
            *per_sensor.entry(sensor).or_default() += 1;
        }
        let counts: Vec<String> = per_sensor.iter().map(|(s, n)| format!("{s} {n}")).collect();
        Some(
            format!(
                "skipped {} frame(s) of {} that did not decode ({}); the first: {first}",
                skipped.len(),
                self.path().display(),
                counts.join(", "),
            ) + &match self.problems.dropped() {
                0 => String::new(),
                n => format!(
                    " ({n} more problems of the log were counted but not kept, past the first {})",
                    super::MAX_PROBLEMS
                ),
            },
        )
    }
}
