//! Measuring the real window: with `RIGCAL_PROFILE_FRAMES=N` the studio records the time from
//! launch to the first frame that draws a camera image with its LiDAR overlay, then (after a
//! warm-up of 10 frames) the interval between N continuously repainted frames, prints both with
//! the number of LiDAR points drawn, and closes. `scripts/bench-studio.sh` runs it under Xvfb
//! on Mesa's software Vulkan for BENCHMARKS.md.

use std::time::{Duration, Instant};

const WARMUP_FRAMES: usize = 10;

pub struct Profile {
    launch: Instant,
    wanted: usize,
    first_picture: Option<Duration>,
    since_picture: usize,
    last: Option<Instant>,
    frames_ms: Vec<f64>,
}

impl Profile {
    pub fn from_env(launch: Instant) -> Option<Self> {
        let wanted = std::env::var("RIGCAL_PROFILE_FRAMES")
            .ok()?
            .parse::<usize>()
            .ok()?;
        Some(Self {
            launch,
            wanted: wanted.max(1),
            first_picture: None,
            since_picture: 0,
            last: None,
            frames_ms: Vec::new(),
        })
    }

    /// Call once per frame. Returns the report when enough frames were measured.
    pub fn on_frame(&mut self, pictures: usize, points: usize, tiles: usize) -> Option<String> {
        let now = Instant::now();
        if self.first_picture.is_none() {
            if pictures == 0 {
                return None;
            }
            self.first_picture = Some(now - self.launch);
        }
        self.since_picture += 1;
        if self.since_picture > WARMUP_FRAMES
            && let Some(last) = self.last
        {
            self.frames_ms.push((now - last).as_secs_f64() * 1e3);
        }
        self.last = Some(now);
        if self.frames_ms.len() < self.wanted {
            return None;
        }
        let mut sorted = self.frames_ms.clone();
        sorted.sort_by(f64::total_cmp);
        let mean = sorted.iter().sum::<f64>() / sorted.len() as f64;
        let pct = |q: f64| sorted[((sorted.len() - 1) as f64 * q).round() as usize];
        Some(format!(
            "first picture after {:.2} s\nframes {} (after {WARMUP_FRAMES} warm-up): mean {mean:.1} ms, median {:.1} ms, p95 {:.1} ms, {:.1} fps\nLiDAR points submitted per frame: {points} over {tiles} camera view(s)",
            self.first_picture.unwrap_or_default().as_secs_f64(),
            sorted.len(),
            pct(0.5),
            pct(0.95),
            1e3 / mean
        ))
    }
}
