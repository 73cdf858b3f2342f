//! Drivable vehicle trajectories for the simulator: the shapes of the paper's trajectory study
//! (straight path, circular loop, S curve, ∞ loop, flower loop; method.md §14.2, supplementary
//! §A4.5 and Fig. A8) and standing still.
//!
//! How it works: every shape is a closed loop built from segments whose curvature is a function of
//! arc length: straights, circular arcs and quintic "smootherstep" ramps between curvatures, so
//! curvature (and therefore yaw rate) never jumps. Heading is the analytic integral of curvature;
//! position is the integral of the heading, by Gauss–Legendre quadrature over pieces at most 2 m
//! long. The loops close by construction (a symmetric loop profile, or a half that is repeated),
//! which is what keeps any drive within ±120 m of the origin: a drive longer than the feature it
//! shows goes round the loop again.
//!
//! The vehicle follows the path at a smooth speed `v(t)`: a rolling start at half the cruise speed
//! that eases up over the first seconds, with gentle, seeded variations. Yaw is always the path
//! heading (no side-slip); the vehicle frame is x forward, y left, z up, with its origin on the
//! ground (`z = 0` of the world). If the drive reaches a curve, cruise speed is capped so that
//! the tightest curve of the shape stays within a car's yaw rate (0.5 rad/s) and lateral
//! acceleration (4 m/s²); above ~9 m/s the shape grows first, as far as the ±120 m box allows,
//! and the speed is lowered only after that. A drive that stays on a straight keeps its speed.

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};
use std::fmt;
use std::str::FromStr;

use glam::{DQuat, DVec2, DVec3};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::geometry::Rigid;

/// The driving patterns of the paper's trajectory study, plus standing still.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
pub enum TrajectoryKind {
    /// A straight run (the loop's return leg is only reached on long drives).
    #[serde(rename = "straight")]
    Straight,
    /// A circular loop of radius ~25 m.
    #[serde(rename = "circle")]
    Circle,
    /// Two opposite arcs between straights.
    #[serde(rename = "s-curve")]
    SCurve,
    /// An ∞ loop: two ~25 m lobes joined by straights that cross at the origin.
    #[default]
    #[serde(rename = "figure8")]
    Figure8,
    /// A three-petal rose: loops out from a centre and back through it.
    #[serde(rename = "flower")]
    Flower,
    /// Standing still at the origin.
    #[serde(rename = "stationary")]
    Stationary,
}

impl TrajectoryKind {
    pub const ALL: [TrajectoryKind; 6] = [
        TrajectoryKind::Straight,
        TrajectoryKind::Circle,
        TrajectoryKind::SCurve,
        TrajectoryKind::Figure8,
        TrajectoryKind::Flower,
        TrajectoryKind::Stationary,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            TrajectoryKind::Straight => "straight",
            TrajectoryKind::Circle => "circle",
            TrajectoryKind::SCurve => "s-curve",
            TrajectoryKind::Figure8 => "figure8",
            TrajectoryKind::Flower => "flower",
            TrajectoryKind::Stationary => "stationary",
        }
    }
}

impl fmt::Display for TrajectoryKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[error(
    "unknown trajectory '{0}'; expected one of: straight, circle, s-curve, figure8, flower, stationary"
)]
pub struct UnknownTrajectory(pub String);

impl FromStr for TrajectoryKind {
    type Err = UnknownTrajectory;

    /// The names of [`TrajectoryKind::as_str`], case-insensitive, plus a few spellings people
    /// type (`scurve`, `s_curve`, `figure-8`, `infinity`, `still`, ...).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let name = s.trim().to_ascii_lowercase();
        Ok(match name.as_str() {
            "straight" | "line" => TrajectoryKind::Straight,
            "circle" | "circular" => TrajectoryKind::Circle,
            "s-curve" | "scurve" | "s_curve" => TrajectoryKind::SCurve,
            "figure8" | "figure-8" | "figure_8" | "figure-eight" | "eight" | "infinity" | "∞" => {
                TrajectoryKind::Figure8
            }
            "flower" | "rose" => TrajectoryKind::Flower,
            "stationary" | "still" | "static" | "parked" => TrajectoryKind::Stationary,
            _ => return Err(UnknownTrajectory(s.to_string())),
        })
    }
}

/// What to drive.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TrajectoryConfig {
    pub kind: TrajectoryKind,
    /// Length of the drive; poses cover `[0, duration_secs]`.
    pub duration_secs: f64,
    /// Pose rate; values below 100 Hz are raised to 100 Hz.
    pub rate_hz: f64,
    /// Cruise speed (m/s). Lowered if the shape's tightest curve could not be driven at it.
    pub speed_mps: f64,
    /// Seeds the small variations of size and speed; the same seed gives the same drive.
    pub seed: u64,
}

impl Default for TrajectoryConfig {
    fn default() -> Self {
        Self {
            kind: TrajectoryKind::Figure8,
            duration_secs: 20.0,
            rate_hz: 100.0,
            speed_mps: 8.0,
            seed: 0,
        }
    }
}

/// Lowest pose rate [`generate`] produces.
pub const MIN_RATE_HZ: f64 = 100.0;
/// Largest yaw rate (rad/s) and lateral acceleration (m/s²) the cruise speed is capped to.
pub const MAX_YAW_RATE: f64 = 0.5;
pub const MAX_LATERAL_ACCEL: f64 = 4.0;
/// Every drive stays within this distance of the origin along x and y (m).
pub const MAX_EXTENT_M: f64 = 115.0;
/// How far the road of [`path_polyline`] runs past the start and the end of the drive (m).
pub const ROAD_MARGIN_M: f64 = 30.0;

/// The drive: `(nanoseconds from the start, world_from_vehicle)` at `rate_hz` (at least 100 Hz),
/// from 0 to `duration_secs` inclusive. Deterministic for a given config.
pub fn generate(cfg: &TrajectoryConfig) -> Vec<(i64, Rigid)> {
    let plan = Plan::new(cfg);
    let rate = effective_rate(cfg.rate_hz);
    let samples = sample_count(cfg.duration_secs, rate);
    let mut out = Vec::with_capacity(samples);
    let mut distance = 0.0;
    let mut previous_t = 0.0;
    for i in 0..samples {
        let t = i as f64 / rate;
        distance += plan.speed.distance_between(previous_t, t);
        previous_t = t;
        let stamp_nanos = (i as f64 * 1e9 / rate).round() as i64;
        out.push((stamp_nanos, plan.pose_at_distance(distance)));
    }
    out
}

/// The road under the drive, as points at most `spacing_m` apart (at least 5 cm) on the ground:
/// the driven path plus [`ROAD_MARGIN_M`] before and after, or the whole loop once (its last
/// point equal to its first) when the drive and its margins would go all the way round. For a
/// stationary drive, a straight road ±30 m around the vehicle along its x axis.
pub fn path_polyline(cfg: &TrajectoryConfig, spacing_m: f64) -> Vec<DVec3> {
    let spacing = if spacing_m.is_finite() {
        spacing_m.max(0.05)
    } else {
        1.0
    };
    let plan = Plan::new(cfg);
    let Some(shape) = &plan.shape else {
        return spaced(-ROAD_MARGIN_M, ROAD_MARGIN_M, spacing, |d| {
            DVec3::new(d, 0.0, 0.0)
        });
    };
    let driven = plan.speed.distance_between(0.0, plan.duration_secs);
    let lap = shape.lap_length();
    let at = |d: f64| shape.position(d).extend(0.0);
    if driven + 2.0 * ROAD_MARGIN_M < lap {
        return spaced(-ROAD_MARGIN_M, driven + ROAD_MARGIN_M, spacing, at);
    }
    let mut road = spaced(0.0, lap, spacing, at);
    if let (Some(first), Some(last)) = (road.first().copied(), road.last_mut()) {
        *last = first;
    }
    road
}

/// Points of `at(d)` for `d` from `start` to `end`, evenly, at most `spacing` apart.
fn spaced(start: f64, end: f64, spacing: f64, at: impl Fn(f64) -> DVec3) -> Vec<DVec3> {
    let count = ((end - start) / spacing).ceil().max(1.0) as usize;
    (0..=count)
        .map(|i| at(start + (end - start) * i as f64 / count as f64))
        .collect()
}

fn effective_rate(rate_hz: f64) -> f64 {
    if rate_hz.is_finite() {
        rate_hz.max(MIN_RATE_HZ)
    } else {
        MIN_RATE_HZ
    }
}

fn finite_duration(duration_secs: f64) -> f64 {
    if duration_secs.is_finite() {
        duration_secs.max(0.0)
    } else {
        0.0
    }
}

fn sample_count(duration_secs: f64, rate: f64) -> usize {
    (finite_duration(duration_secs) * rate + 1e-6).floor() as usize + 1
}

/// A shape placed in the world, the speed along it, or nothing for a vehicle standing still.
struct Plan {
    shape: Option<Shape>,
    speed: SpeedProfile,
    /// The config's duration, made finite and non-negative.
    duration_secs: f64,
}

impl Plan {
    fn new(cfg: &TrajectoryConfig) -> Self {
        let mut rng = SplitMix64::new(cfg.seed);
        let size_factor = 1.0 + 0.04 * rng.symmetric();
        let speed_factor = 1.0 + 0.04 * rng.symmetric();
        let mut speed = SpeedProfile::seeded(&mut rng);
        let requested = if cfg.speed_mps.is_finite() {
            cfg.speed_mps.max(0.0)
        } else {
            TrajectoryConfig::default().speed_mps
        };
        speed.cruise_mps = requested * speed_factor;
        let duration = finite_duration(cfg.duration_secs);
        let shape = match cfg.kind {
            TrajectoryKind::Stationary => {
                speed.cruise_mps = 0.0;
                None
            }
            kind => Some(Shape::new(kind, size_factor, &mut speed, duration)),
        };
        Self {
            shape,
            speed,
            duration_secs: duration,
        }
    }

    fn pose_at_distance(&self, distance: f64) -> Rigid {
        match &self.shape {
            None => Rigid::IDENTITY,
            Some(shape) => {
                let (position, heading) = shape.position_heading(distance);
                Rigid::new(DQuat::from_rotation_z(heading), position.extend(0.0))
            }
        }
    }
}

/// A closed loop, scaled and placed in the world.
struct Shape {
    path: Path,
    scale: f64,
    /// The point of the design placed on the world origin, and the design's yaw in the world.
    origin: DVec2,
    world_yaw: f64,
    /// Design distance the drive is centred on, when the drive is short enough.
    feature_centre: f64,
    /// Path distance (world metres) where the drive starts.
    start_distance: f64,
}

impl Shape {
    /// The shape of `kind` at `size_factor` times its nominal size, with the drive of
    /// `duration` seconds centred on its feature. If the drive reaches a curve too tight for
    /// `speed`, the shape grows (as far as [`MAX_EXTENT_M`] allows) and then `speed` is lowered.
    fn new(
        kind: TrajectoryKind,
        size_factor: f64,
        speed: &mut SpeedProfile,
        duration: f64,
    ) -> Self {
        let design = Design::of(kind);
        let mut shape = Self {
            path: Path::new(&design.segments),
            scale: size_factor,
            origin: design.origin,
            world_yaw: design.world_yaw,
            feature_centre: design.feature_centre,
            start_distance: 0.0,
        };
        let driven = speed.distance_between(0.0, duration);
        shape.centre_drive(driven);
        if shape.max_curvature_between(shape.start_distance, shape.start_distance + driven) == 0.0 {
            // Straight road only: any speed will do.
            return shape;
        }
        let kappa = shape.path.max_abs_curvature();
        let extent = shape
            .path
            .max_abs_coordinate(design.origin, design.world_yaw);
        let peak = speed.peak_factor();
        let needed = |v: f64| (kappa * v / MAX_YAW_RATE).max(kappa * v * v / MAX_LATERAL_ACCEL);
        let largest = (MAX_EXTENT_M / extent).max(size_factor);
        shape.scale = needed(speed.cruise_mps * peak)
            .max(size_factor)
            .min(largest);
        let allowed_peak = (MAX_YAW_RATE * shape.scale / kappa)
            .min((MAX_LATERAL_ACCEL * shape.scale / kappa).sqrt());
        speed.cruise_mps = speed.cruise_mps.min(allowed_peak / peak);
        shape.centre_drive(speed.distance_between(0.0, duration));
        shape
    }

    /// Start a drive of `driven` metres so that it is centred on the shape's feature (the
    /// middle of the straight, the inflection of the S), as far as the shape allows.
    fn centre_drive(&mut self, driven: f64) {
        let centre = self.feature_centre * self.scale;
        self.start_distance = (centre - 0.5 * driven).clamp(0.0, centre);
    }

    /// Largest |curvature| (1/m, world) between two path distances, sampled every 25 cm.
    fn max_curvature_between(&self, start: f64, end: f64) -> f64 {
        let count = ((end - start) / 0.25).ceil().max(1.0) as usize;
        (0..=count)
            .map(|i| {
                let s = start + (end - start) * i as f64 / count as f64;
                self.path.curvature(s / self.scale).abs() / self.scale
            })
            .fold(0.0, f64::max)
    }

    fn lap_length(&self) -> f64 {
        self.path.length * self.scale
    }

    /// Position and heading `distance` metres along the path from the drive's start.
    fn position_heading(&self, distance: f64) -> (DVec2, f64) {
        let (p, heading) = self
            .path
            .position_heading((self.start_distance + distance) / self.scale);
        let rotation = DVec2::from_angle(self.world_yaw);
        (
            rotation.rotate(p - self.origin) * self.scale,
            heading + self.world_yaw,
        )
    }

    fn position(&self, distance: f64) -> DVec2 {
        self.position_heading(distance).0
    }
}

/// A shape at its nominal size: the segments of one lap from the origin heading +x, the point of
/// that frame placed on the world origin and the yaw that lays the shape out in the world, and
/// the distance along the lap (m) a drive is centred on.
struct Design {
    segments: Vec<Segment>,
    origin: DVec2,
    world_yaw: f64,
    feature_centre: f64,
}

/// Length (m) over which curvature eases in and out of loops and turns.
const RAMP_M: f64 = 10.0;

impl Design {
    fn of(kind: TrajectoryKind) -> Self {
        match kind {
            // A long bottom leg centred on the origin; the U-turns only on long drives.
            TrajectoryKind::Straight | TrajectoryKind::Stationary => {
                let leg = 170.0;
                let half = [vec![Segment::straight(leg)], turn(PI, 22.0, 12.0).to_vec()].concat();
                Self {
                    segments: [half.clone(), half].concat(),
                    origin: DVec2::new(0.5 * leg, 0.0),
                    world_yaw: 0.0,
                    feature_centre: 0.5 * leg,
                }
            }
            // Starts at the bottom of a circle centred on the origin, turning left.
            TrajectoryKind::Circle => {
                let radius = 25.0;
                Self {
                    segments: vec![Segment::arc(1.0 / radius, TAU * radius)],
                    origin: DVec2::new(0.0, radius),
                    world_yaw: 0.0,
                    feature_centre: 0.0,
                }
            }
            // Lead-in, left arc, right arc, lead-out, U-turn; the second half repeats the first.
            TrajectoryKind::SCurve => {
                let lead = 35.0;
                let swing = 70f64.to_radians();
                let left = turn(swing, 25.0, RAMP_M);
                let right = turn(-swing, 25.0, RAMP_M);
                let half = [
                    vec![Segment::straight(lead)],
                    left.to_vec(),
                    right.to_vec(),
                    vec![Segment::straight(lead)],
                    turn(PI, 32.0, 12.0).to_vec(),
                ]
                .concat();
                let inflection = lead + left.iter().map(|s| s.length).sum::<f64>();
                let segments = [half.clone(), half].concat();
                Self {
                    origin: Path::new(&segments).position_heading(inflection).0,
                    segments,
                    world_yaw: 0.0,
                    feature_centre: inflection,
                }
            }
            // Two petal loops whose entry and exit lines cross at the origin at 90°, one turning
            // left and one right; the lobes lie along the world x axis.
            TrajectoryKind::Figure8 => {
                let beta = FRAC_PI_2;
                let left = turn(PI + beta, 24.0, RAMP_M);
                let right = turn(-(PI + beta), 24.0, RAMP_M);
                let a = petal_lead(&left, beta);
                Self {
                    segments: [
                        vec![Segment::straight(a)],
                        left.to_vec(),
                        vec![Segment::straight(2.0 * a)],
                        right.to_vec(),
                        vec![Segment::straight(a)],
                    ]
                    .concat(),
                    origin: DVec2::ZERO,
                    world_yaw: -FRAC_PI_4,
                    feature_centre: 0.0,
                }
            }
            // Three petals 60° wide whose axes step by 240°: a three-petal rose, two turns a lap.
            TrajectoryKind::Flower => {
                let beta = 60f64.to_radians();
                let petal = turn(PI + beta, 22.0, RAMP_M);
                let a = petal_lead(&petal, beta);
                let one = [
                    vec![Segment::straight(a)],
                    petal.to_vec(),
                    vec![Segment::straight(a)],
                ]
                .concat();
                Self {
                    segments: [one.clone(), one.clone(), one].concat(),
                    origin: DVec2::ZERO,
                    world_yaw: 0.0,
                    feature_centre: 0.0,
                }
            }
        }
    }
}

/// Distance from the centre at which a petal loop starts (and ends), so that its entry and exit
/// lines both pass through the centre at `beta` to each other. The loop is symmetric, so its
/// chord bisects the turn; see the module docs.
fn petal_lead(loop_segments: &[Segment], beta: f64) -> f64 {
    let chord = Path::new(loop_segments).end_position;
    chord.length() / (2.0 * (0.5 * beta).sin())
}

/// A turn by `angle` (rad, positive = left) with curvature `1 / radius` after a ramp of `ramp`
/// metres, and back to straight after another.
fn turn(angle: f64, radius: f64, ramp: f64) -> [Segment; 3] {
    let kappa = angle.signum() / radius;
    let total = angle.abs() * radius;
    let ramp = ramp.min(total);
    [
        Segment::ramp(0.0, kappa, ramp),
        Segment::arc(kappa, total - ramp),
        Segment::ramp(kappa, 0.0, ramp),
    ]
}

/// A piece of path whose curvature is constant or eases between two values.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Segment {
    length: f64,
    kappa_start: f64,
    kappa_end: f64,
}

impl Segment {
    fn straight(length: f64) -> Self {
        Self::arc(0.0, length)
    }

    fn arc(kappa: f64, length: f64) -> Self {
        Self::ramp(kappa, kappa, length)
    }

    fn ramp(kappa_start: f64, kappa_end: f64, length: f64) -> Self {
        Self {
            length: length.max(0.0),
            kappa_start,
            kappa_end,
        }
    }

    fn curvature(&self, u: f64) -> f64 {
        let x = if self.length > 0.0 {
            (u / self.length).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let smooth = x * x * x * (10.0 + x * (-15.0 + 6.0 * x));
        self.kappa_start + (self.kappa_end - self.kappa_start) * smooth
    }

    /// Heading change over the first `u` metres: the integral of [`Self::curvature`].
    fn heading_change(&self, u: f64) -> f64 {
        if self.length <= 0.0 {
            return 0.0;
        }
        let u = u.clamp(0.0, self.length);
        let x = u / self.length;
        // ∫₀ˣ (6t⁵ − 15t⁴ + 10t³) dt = x⁶ − 3x⁵ + 2.5x⁴
        let integral = x * x * x * x * (2.5 + x * (-3.0 + x));
        self.kappa_start * u + (self.kappa_end - self.kappa_start) * self.length * integral
    }
}

/// Longest piece (m) over which position is integrated in one go.
const PIECE_M: f64 = 2.0;

/// 5-point Gauss–Legendre nodes and weights on [-1, 1].
const GAUSS: [(f64, f64); 5] = [
    (0.0, 0.568_888_888_888_888_9),
    (-0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (-0.906_179_845_938_664, 0.236_926_885_056_189_08),
    (0.906_179_845_938_664, 0.236_926_885_056_189_08),
];

/// A lap of segments from a start pose, cut into pieces with their start poses precomputed.
#[derive(Clone, Debug)]
struct Path {
    segments: Vec<Segment>,
    /// Heading at the start of each segment.
    segment_heading: Vec<f64>,
    pieces: Vec<Piece>,
    length: f64,
    /// Where and how the lap ends (back at the origin for a closed loop).
    end_position: DVec2,
    end_heading: f64,
}

#[derive(Clone, Copy, Debug)]
struct Piece {
    segment: usize,
    /// Offset of the piece within its segment, its length and its distance along the lap.
    u0: f64,
    length: f64,
    s0: f64,
    position: DVec2,
}

impl Path {
    /// The lap of `segments` from the origin, heading +x.
    fn new(segments: &[Segment]) -> Self {
        let mut segment_heading = Vec::with_capacity(segments.len());
        let mut pieces = Vec::new();
        let (mut heading, mut position, mut s) = (0.0, DVec2::ZERO, 0.0);
        for (index, segment) in segments.iter().enumerate() {
            segment_heading.push(heading);
            let count = (segment.length / PIECE_M).ceil().max(1.0) as usize;
            let step = segment.length / count as f64;
            for k in 0..count {
                let piece = Piece {
                    segment: index,
                    u0: step * k as f64,
                    length: step,
                    s0: s,
                    position,
                };
                position += Self::displacement(segment, heading, piece.u0, step);
                s += step;
                pieces.push(piece);
            }
            heading += segment.heading_change(segment.length);
        }
        Self {
            segments: segments.to_vec(),
            segment_heading,
            pieces,
            length: s,
            end_position: position,
            end_heading: heading,
        }
    }

    /// ∫ (cos ψ, sin ψ) du over `[u0, u0 + du]` of `segment`, which starts at `heading`.
    fn displacement(segment: &Segment, heading: f64, u0: f64, du: f64) -> DVec2 {
        let half = 0.5 * du;
        GAUSS
            .iter()
            .map(|&(x, w)| {
                let psi = heading + segment.heading_change(u0 + half * (1.0 + x));
                DVec2::from_angle(psi) * (w * half)
            })
            .sum()
    }

    /// Position and heading at `s` metres along the loop; any `s` wraps round the lap.
    fn position_heading(&self, s: f64) -> (DVec2, f64) {
        let (Some(piece), du, laps) = self.locate(s) else {
            return (DVec2::ZERO, 0.0);
        };
        let segment = &self.segments[piece.segment];
        let heading0 = self.segment_heading[piece.segment];
        let position = piece.position + Self::displacement(segment, heading0, piece.u0, du);
        let heading = heading0 + segment.heading_change(piece.u0 + du);
        (
            position + self.end_position * laps,
            heading + self.end_heading * laps,
        )
    }

    /// Curvature at `s` metres along the loop; any `s` wraps round the lap.
    fn curvature(&self, s: f64) -> f64 {
        match self.locate(s) {
            (Some(piece), du, _) => self.segments[piece.segment].curvature(piece.u0 + du),
            _ => 0.0,
        }
    }

    /// The piece holding `s` wrapped onto the lap, the offset into it, and the laps wrapped.
    fn locate(&self, s: f64) -> (Option<Piece>, f64, f64) {
        if self.length <= 0.0 || !s.is_finite() {
            return (None, 0.0, 0.0);
        }
        let laps = (s / self.length).floor();
        let s = (s - laps * self.length).clamp(0.0, self.length);
        let index = self.pieces.partition_point(|p| p.s0 <= s).saturating_sub(1);
        match self.pieces.get(index) {
            Some(piece) => (Some(*piece), (s - piece.s0).clamp(0.0, piece.length), laps),
            None => (None, 0.0, laps),
        }
    }

    fn max_abs_curvature(&self) -> f64 {
        self.segments
            .iter()
            .map(|s| s.kappa_start.abs().max(s.kappa_end.abs()))
            .fold(1e-9, f64::max)
    }

    /// Largest |x| or |y| of the lap about `centre`, after rotating it by `yaw`.
    fn max_abs_coordinate(&self, centre: DVec2, yaw: f64) -> f64 {
        let rotation = DVec2::from_angle(yaw);
        let count = (self.length / 0.5).ceil().max(1.0) as usize;
        (0..=count)
            .map(|i| {
                let p = self
                    .position_heading(self.length * i as f64 / count as f64)
                    .0;
                rotation.rotate(p - centre).abs().max_element()
            })
            .fold(1e-9, f64::max)
    }
}

/// `v(t) = cruise · (rolling start) · (1 + two gentle seeded sinusoids)`.
#[derive(Clone, Debug)]
struct SpeedProfile {
    cruise_mps: f64,
    waves: [(f64, f64, f64); 2],
}

/// Speed at t = 0 as a fraction of cruise, and how long (s) the ease up to cruise takes.
const ROLLING_START: f64 = 0.5;
const EASE_SECS: f64 = 6.0;

impl SpeedProfile {
    fn seeded(rng: &mut SplitMix64) -> Self {
        let mut wave = |amplitude: (f64, f64), period: (f64, f64)| {
            (
                amplitude.0 + (amplitude.1 - amplitude.0) * rng.unit(),
                period.0 + (period.1 - period.0) * rng.unit(),
                TAU * rng.unit(),
            )
        };
        let slow = wave((0.02, 0.045), (9.0, 15.0));
        let fast = wave((0.01, 0.02), (4.0, 7.0));
        Self {
            cruise_mps: 0.0,
            waves: [slow, fast],
        }
    }

    /// Upper bound of `v / cruise`.
    fn peak_factor(&self) -> f64 {
        1.0 + self.waves.iter().map(|w| w.0).sum::<f64>()
    }

    fn speed(&self, t: f64) -> f64 {
        let x = (t / EASE_SECS).clamp(0.0, 1.0);
        let ease =
            ROLLING_START + (1.0 - ROLLING_START) * x * x * x * (10.0 + x * (-15.0 + 6.0 * x));
        let wobble: f64 = self
            .waves
            .iter()
            .map(|&(amplitude, period, phase)| amplitude * (TAU * t / period + phase).sin())
            .sum();
        self.cruise_mps * ease * (1.0 + wobble)
    }

    /// Distance driven between `t0` and `t1`, by Gauss–Legendre over steps of at most 10 ms.
    fn distance_between(&self, t0: f64, t1: f64) -> f64 {
        if t0.is_nan() || t1.is_nan() || t1 <= t0 || self.cruise_mps == 0.0 {
            return 0.0;
        }
        let steps = ((t1 - t0) / 0.01).ceil().max(1.0) as usize;
        let dt = (t1 - t0) / steps as f64;
        (0..steps)
            .map(|k| {
                let mid = t0 + dt * (k as f64 + 0.5);
                GAUSS
                    .iter()
                    .map(|&(x, w)| w * self.speed(mid + 0.5 * dt * x))
                    .sum::<f64>()
                    * 0.5
                    * dt
            })
            .sum()
    }
}

/// SplitMix64: a tiny, well-mixed generator so the same seed always gives the same drive.
struct SplitMix64(u64);

impl SplitMix64 {
    fn new(seed: u64) -> Self {
        Self(seed ^ 0x5DEE_CE66_D1CE_4E5B)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [-1, 1).
    fn symmetric(&mut self) -> f64 {
        2.0 * self.unit() - 1.0
    }
}

#[cfg(test)]
mod tests;
