//! Camera–LiDAR calibration with checkerboards by edges and planes (the paper's "Edge and
//! Plane" baseline, supplementary A2.1; Zhou et al., IROS 2018): `vehicle_from_camera` against a
//! reference LiDAR from boards seen by both.
//!
//! How it works, per frame (a LiDAR sweep and the camera image nearest in time):
//! - **Camera side**: every board of the known pattern is found in the image with ordered,
//!   sub-pixel inner corners ([`crate::features::chessboard`]); planar PnP through the full
//!   camera model gives `camera_from_board` ([`crate::geometry::pnp`]), with the board frame at
//!   the centre of its squares, x along its longer side, z along its normal.
//! - **LiDAR side**: the sweep is moved into the vehicle frame at the image's time (per-point
//!   firing times through the trajectory), boards are found as planar clusters of the board's
//!   size ([`crate::eval::checkerboard::boards_with_points`]) and each board's returns are split
//!   into scan rings by elevation from the LiDAR; the two ends of each ring, pushed outwards by
//!   half the ring's point spacing, lie on the board's border.
//! - **Association**: a LiDAR board and a camera board are the same when the initial guess puts
//!   their centres within `association_m`.
//! - **Solve**: Levenberg–Marquardt over `camera_from_vehicle` (six parameters perturbing it on
//!   the right) of, per board, the plane residuals (a return's distance to the camera's board
//!   plane), the border residuals (a ring end's in-plane distance to the nearest border of the
//!   board's rectangle) and, for returns clearly outside the rectangle, their distance to it
//!   (what holds the direction along the borders when the top and bottom edges are not sampled).
//!   Several starts are refined (the guess and the closed-form pose of each board) and the best
//!   continued: the nearest-border assignment switches as the pose moves and has local minima.
//!   Each board's plane and border terms are means, so a board counts once whatever its number
//!   of returns; a Huber kernel (`huber_m`) keeps stray returns from dominating. `JᵀJ` at the
//!   solution is the result's information matrix (for pose graphs).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use glam::{DVec2, DVec3};

use crate::calib::Rig;
use crate::eval::checkerboard::{BoardSpec, boards_with_points};
use crate::features::chessboard::{find_chessboards, grey_levels};
use crate::geometry::Rigid;
use crate::geometry::camera::CameraIntrinsics;
use crate::geometry::pnp::planar_pose;
use crate::geometry::spd::solve6;
use crate::log::Drive;
use crate::optim::edge_align::{AlignError, points_in_vehicle_at, sweep_image_pairs};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TargetConfig {
    pub spec: BoardSpec,
    /// Sweep–image pairs per camera.
    pub frames: usize,
    /// Largest distance between a LiDAR board and a camera board under the initial guess.
    pub association_m: f64,
    pub huber_m: f64,
    /// Iterations of the solve.
    pub iterations: usize,
}

impl Default for TargetConfig {
    fn default() -> Self {
        Self {
            spec: BoardSpec::default(),
            frames: 10,
            association_m: 1.0,
            huber_m: 0.03,
            iterations: 30,
        }
    }
}

/// One board seen by the camera and the LiDAR in one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct BoardView {
    pub camera_from_board: Rigid,
    /// RMS pixel error of the board's PnP.
    pub pnp_rms_px: f64,
    /// The board's returns and the ring ends on its border, in the vehicle frame at the image's
    /// time.
    pub plane_points: Vec<DVec3>,
    pub border_points: Vec<DVec3>,
    /// The board as the LiDAR sees it (vehicle frame; x horizontal, y down the board, z = x × y):
    /// with `camera_from_board` it gives a closed-form guess of the camera, up to the four
    /// symmetries of a rectangle.
    pub vehicle_from_lidar_board: Rigid,
}

/// One camera against the reference LiDAR.
#[derive(Clone, Debug)]
pub struct TargetProblem {
    pub camera: String,
    pub lidar: String,
    pub spec: BoardSpec,
    pub views: Vec<BoardView>,
    pub huber_m: f64,
}

/// Returns may scatter this far past a board's border (range noise at a slant) before they
/// count as outside it.
const OUTSIDE_SLACK_M: f64 = 0.05;

/// The board's square region in its own frame (x along the longer side), half extents of the
/// whole board (margins included).
fn half_size(spec: &BoardSpec) -> DVec2 {
    let (w, h) = spec.size_m();
    DVec2::new(w.max(h), w.min(h)) * 0.5
}

/// The inner corners in the board frame, row by row as the detector orders them.
fn board_corners(spec: &BoardSpec) -> Vec<DVec2> {
    let (long, short) = (
        spec.squares_u.max(spec.squares_v) as f64,
        spec.squares_u.min(spec.squares_v) as f64,
    );
    let sq = spec.square_m;
    let mut out = Vec::new();
    for r in 1..short as usize {
        for c in 1..long as usize {
            out.push(DVec2::new(
                (c as f64 - long / 2.0) * sq,
                (r as f64 - short / 2.0) * sq,
            ));
        }
    }
    out
}

/// Boards found in a drive's images, kept by (camera, image index) so that calibrating one
/// camera against several LiDARs (the pose graph) reads and searches each image once. One
/// cache serves one drive and one board pattern.
#[derive(Debug, Default)]
pub struct BoardCache {
    found: Mutex<HashMap<(String, usize), Arc<Vec<(Rigid, f64)>>>>,
}

impl BoardCache {
    /// The boards of `camera`'s image `index`: found now or remembered.
    pub fn boards(
        &self,
        drive: &Drive,
        camera: &str,
        index: usize,
        intrinsics: &CameraIntrinsics,
        spec: &BoardSpec,
    ) -> Result<Arc<Vec<(Rigid, f64)>>, AlignError> {
        let key = (camera.to_owned(), index);
        if let Some(found) = self.found.lock().ok().and_then(|m| m.get(&key).cloned()) {
            return Ok(found);
        }
        // An image that does not decode shows no board (the drive reports it).
        let found = Arc::new(match drive.image_or_skip(camera, index) {
            Some(image) => camera_boards(&image, intrinsics, spec),
            None => Vec::new(),
        });
        if let Ok(mut m) = self.found.lock() {
            m.insert(key, found.clone());
        }
        Ok(found)
    }
}

/// Boards found in one image, as `camera_from_board` with their PnP RMS.
pub fn camera_boards(
    image: &image::RgbImage,
    intrinsics: &CameraIntrinsics,
    spec: &BoardSpec,
) -> Vec<(Rigid, f64)> {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let grey = grey_levels(image);
    let pattern = (
        (spec.squares_u.max(spec.squares_v) - 1) as usize,
        (spec.squares_u.min(spec.squares_v) - 1) as usize,
    );
    let model = board_corners(spec);
    find_chessboards(&grey, w, h, pattern, (0, 0, w, h))
        .into_iter()
        .filter_map(|b| planar_pose(intrinsics, &model, &b.corners))
        .map(|p| (p.camera_from_target, p.rms_px))
        .collect()
}

/// A board's returns (vehicle frame) split into scan rings by their elevation in the LiDAR's own
/// frame (`vehicle_from_lidar`; gaps over 0.08°, where a beam's elevation is constant), and
/// each ring's two ends pushed outwards by half its median point spacing.
pub fn ring_ends(points: &[DVec3], vehicle_from_lidar: Rigid) -> Vec<DVec3> {
    let lidar_from_vehicle = vehicle_from_lidar.inverse();
    let lidar_origin = vehicle_from_lidar.translation;
    let mut by_elevation: Vec<(f64, f64, DVec3)> = points
        .iter()
        .map(|p| {
            let d = lidar_from_vehicle.transform_point(*p);
            (d.z.atan2(d.truncate().length()), d.y.atan2(d.x), *p)
        })
        .collect();
    by_elevation.sort_by(|a, b| a.0.total_cmp(&b.0));
    let gap = 0.08f64.to_radians();
    let mut rings: Vec<Vec<(f64, DVec3)>> = Vec::new();
    let mut last = f64::NEG_INFINITY;
    for (elevation, azimuth, p) in by_elevation {
        if elevation - last > gap || rings.is_empty() {
            rings.push(Vec::new());
        }
        last = elevation;
        if let Some(ring) = rings.last_mut() {
            ring.push((azimuth, p));
        }
    }
    let mut out = Vec::new();
    for mut ring in rings.into_iter().filter(|r| r.len() >= 4) {
        // Azimuth (sensor frame) unwrapped around the ring's mean direction.
        let mean = ring
            .iter()
            .map(|(_, p)| lidar_from_vehicle.transform_vector(*p - lidar_origin))
            .sum::<DVec3>();
        let centre = mean.y.atan2(mean.x);
        let wrap = |a: f64| (a - centre + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU);
        ring.sort_by(|a, b| wrap(a.0).total_cmp(&wrap(b.0)));
        let mut steps: Vec<f64> = ring
            .windows(2)
            .map(|w| (w[1].1 - w[0].1).length())
            .collect();
        steps.sort_by(f64::total_cmp);
        let half_step = 0.5 * steps[steps.len() / 2];
        let n = ring.len();
        for (end, inward) in [(ring[0].1, ring[1].1), (ring[n - 1].1, ring[n - 2].1)] {
            let outward = (end - inward).try_normalize().unwrap_or(DVec3::ZERO);
            out.push(end + outward * half_step);
        }
    }
    out
}

/// The solve's result.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TargetSolution {
    pub vehicle_from_camera: Rigid,
    /// RMS plane and border residuals (m) at the solution.
    pub plane_rms_m: f64,
    pub border_rms_m: f64,
    /// `JᵀJ` of the normalised residuals (row-major, tangent of `camera_from_vehicle` on the
    /// right: rotation, then translation).
    pub information: [f64; 36],
    pub iterations: usize,
}

impl TargetProblem {
    /// Prepare `camera` against `lidar` from up to `config.frames` sweep–image pairs of the log
    /// (within `segments_nanos`; empty: the whole log), associating boards with the rig's
    /// current guess. The camera's boards are taken from (and added to) `boards`, so several
    /// LiDARs search each image once.
    pub fn from_drive(
        drive: &Drive,
        rig: &Rig,
        camera: &str,
        lidar: &str,
        segments_nanos: &[(i64, i64)],
        config: &TargetConfig,
        boards: &BoardCache,
    ) -> Result<Self, AlignError> {
        let setup = |what: String| AlignError::Setup(what);
        let cam = rig
            .sensor(camera)
            .ok_or_else(|| setup(format!("no sensor '{camera}' in the rig")))?;
        let intrinsics = cam
            .camera
            .clone()
            .ok_or_else(|| setup(format!("'{camera}' is not a camera with intrinsics")))?;
        let camera_from_vehicle = cam.vehicle_from_sensor.inverse();
        let vehicle_from_lidar = rig
            .sensor(lidar)
            .ok_or_else(|| setup(format!("no sensor '{lidar}' in the rig")))?
            .vehicle_from_sensor;
        let mut views = Vec::new();
        for pair in sweep_image_pairs(drive, camera, lidar, config.frames, segments_nanos)? {
            let seen = boards.boards(drive, camera, pair.image_index, &intrinsics, &config.spec)?;
            if seen.is_empty() {
                continue;
            }
            let all: Vec<usize> = (0..pair.sweep.len()).collect();
            let points = points_in_vehicle_at(
                &pair.sweep,
                &all,
                &drive.trajectory,
                vehicle_from_lidar,
                pair.image_stamp_nanos,
            )?;
            for (board, plane_points) in boards_with_points(&points, &config.spec) {
                let predicted = camera_from_vehicle.transform_point(board.center);
                let nearest = seen
                    .iter()
                    .map(|(b, rms)| (b, *rms, (b.translation - predicted).length()))
                    .min_by(|a, b| a.2.total_cmp(&b.2));
                let Some((camera_from_board, pnp_rms_px, d)) = nearest else {
                    continue;
                };
                if d > config.association_m {
                    continue;
                }
                let z = board.u.cross(board.v);
                let vehicle_from_lidar_board = Rigid::new(
                    glam::DQuat::from_mat3(&glam::DMat3::from_cols(board.u, board.v, z))
                        .normalize(),
                    board.center,
                );
                views.push(BoardView {
                    camera_from_board: *camera_from_board,
                    vehicle_from_lidar_board,
                    pnp_rms_px,
                    border_points: ring_ends(&plane_points, vehicle_from_lidar),
                    plane_points,
                });
            }
        }
        if views.is_empty() {
            return Err(setup(format!(
                "no checkerboard seen by both '{camera}' and '{lidar}'"
            )));
        }
        Ok(Self {
            camera: camera.to_string(),
            lidar: lidar.to_string(),
            spec: config.spec,
            views,
            huber_m: config.huber_m,
        })
    }

    /// Distinct boards among the views (centres more than 0.5 m apart). With one board the
    /// camera's position along the board's own vertical is not observed (its top and bottom
    /// edges are between scan rings).
    pub fn distinct_boards(&self) -> usize {
        let mut centres: Vec<DVec3> = Vec::new();
        for v in &self.views {
            let c = v.vehicle_from_lidar_board.translation;
            if centres.iter().all(|k| (*k - c).length() > 0.5) {
                centres.push(c);
            }
        }
        centres.len()
    }

    /// Normalised residuals (each board's terms divided by the square root of their count, so
    /// that each term is a mean) and the plane and border sums of squares.
    fn residuals(&self, camera_from_vehicle: Rigid) -> (Vec<f64>, f64, usize, f64, usize) {
        let half = half_size(&self.spec);
        let mut out = Vec::new();
        let (mut plane_sq, mut plane_n, mut border_sq, mut border_n) = (0.0, 0, 0.0, 0);
        for view in &self.views {
            let board_from_vehicle = view.camera_from_board.inverse() * camera_from_vehicle;
            let np = (view.plane_points.len().max(1) as f64).sqrt();
            for p in &view.plane_points {
                let q = board_from_vehicle.transform_point(*p);
                out.push(q.z / np);
                plane_sq += q.z * q.z;
                plane_n += 1;
                // Clearly outside the rectangle (beyond the range noise seen at a slant):
                // distance to it, in the plane.
                let outside = DVec2::new(q.x.abs() - half.x, q.y.abs() - half.y)
                    - DVec2::splat(OUTSIDE_SLACK_M);
                out.push(outside.max(DVec2::ZERO).length() / np);
            }
            // Each ring end against the nearest border of the rectangle (on a tilted board the
            // top and bottom rings can leave through the top or bottom border).
            let nb = (view.border_points.len().max(1) as f64).sqrt();
            for p in &view.border_points {
                let q = board_from_vehicle.transform_point(*p);
                let (dx, dy) = (half.x - q.x.abs(), half.y - q.y.abs());
                let r = if dx.abs() < dy.abs() { dx } else { dy };
                out.push(r / nb);
                border_sq += r * r;
                border_n += 1;
            }
        }
        (out, plane_sq, plane_n, border_sq, border_n)
    }

    fn robust_cost(&self, camera_from_vehicle: Rigid) -> f64 {
        let (r, ..) = self.residuals(camera_from_vehicle);
        r.iter().map(|v| huber(*v, self.huber_m)).sum()
    }

    /// Solve from `start` (a `vehicle_from_camera`).
    pub fn solve(&self, start: Rigid, iterations: usize) -> TargetSolution {
        let mut state = TargetSearch::new(self, start);
        for _ in 0..iterations {
            if !state.step(self) {
                break;
            }
        }
        state.solution(self)
    }
}

/// Huber's ρ with threshold `k`, on residuals already divided by √n (the threshold scales with
/// them only approximately; it bounds single stray returns).
fn huber(r: f64, k: f64) -> f64 {
    let a = r.abs();
    if a <= k {
        0.5 * r * r
    } else {
        k * (a - 0.5 * k)
    }
}

/// How far a closed-form guess from one board may lie from the initial guess.
const CANDIDATE_ROTATION_RAD: f64 = 20.0 * std::f64::consts::PI / 180.0;
const CANDIDATE_TRANSLATION_M: f64 = 1.0;
/// Iterations each start is refined by before the best is chosen.
const START_ITERATIONS: usize = 8;

/// A Levenberg–Marquardt search, one iteration per [`TargetSearch::step`].
#[derive(Clone, Debug)]
pub struct TargetSearch {
    pub camera_from_vehicle: Rigid,
    pub cost: f64,
    lambda: f64,
    pub iterations: usize,
    converged: bool,
}

impl TargetSearch {
    /// Start from the best of `vehicle_from_camera` and the closed-form guesses of every board
    /// view (`camera_from_board · S · board_from_vehicle` for the four symmetries S of a
    /// rectangle, which the LiDAR cannot tell apart), each refined by a few iterations first:
    /// the border terms switch edges as the pose moves and have local minima.
    pub fn new(problem: &TargetProblem, vehicle_from_camera: Rigid) -> Self {
        let symmetries = [
            glam::DQuat::IDENTITY,
            glam::DQuat::from_rotation_x(std::f64::consts::PI),
            glam::DQuat::from_rotation_y(std::f64::consts::PI),
            glam::DQuat::from_rotation_z(std::f64::consts::PI),
        ];
        let mut starts = vec![vehicle_from_camera.inverse()];
        for view in &problem.views {
            for s in symmetries {
                let candidate = view.camera_from_board
                    * Rigid::new(s, DVec3::ZERO)
                    * view.vehicle_from_lidar_board.inverse();
                // Planes and borders cannot tell a camera from its mirror image through the
                // board: the guess disambiguates (within 20° and 1 m of it).
                let (rot, trans) = candidate.inverse().difference(vehicle_from_camera);
                if rot <= CANDIDATE_ROTATION_RAD && trans <= CANDIDATE_TRANSLATION_M {
                    starts.push(candidate);
                }
            }
        }
        let mut best: Option<Self> = None;
        for start in starts {
            let mut search = Self::at(problem, start);
            for _ in 0..START_ITERATIONS {
                if !search.step(problem) {
                    break;
                }
            }
            if best.as_ref().is_none_or(|b| search.cost < b.cost) {
                best = Some(search);
            }
        }
        let mut chosen = best.unwrap_or_else(|| Self::at(problem, vehicle_from_camera.inverse()));
        chosen.converged = false;
        chosen
    }

    fn at(problem: &TargetProblem, camera_from_vehicle: Rigid) -> Self {
        Self {
            cost: problem.robust_cost(camera_from_vehicle),
            camera_from_vehicle,
            lambda: 1e-3,
            iterations: 0,
            converged: false,
        }
    }

    pub fn converged(&self) -> bool {
        self.converged
    }

    fn moved(c: Rigid, x: &[f64; 6]) -> Rigid {
        c.perturbed_right(DVec3::new(x[0], x[1], x[2]), DVec3::new(x[3], x[4], x[5]))
    }

    /// Gauss–Newton system of the robust cost at `c` (IRLS weights of the Huber kernel).
    fn system(problem: &TargetProblem, c: Rigid) -> ([f64; 36], [f64; 6]) {
        let (r0, ..) = problem.residuals(c);
        let eps = 1e-6;
        let mut columns = Vec::with_capacity(6);
        for k in 0..6 {
            let mut d = [0.0; 6];
            d[k] = eps;
            let (up, ..) = problem.residuals(Self::moved(c, &d));
            d[k] = -eps;
            let (down, ..) = problem.residuals(Self::moved(c, &d));
            columns.push(
                up.iter()
                    .zip(&down)
                    .map(|(a, b)| (a - b) / (2.0 * eps))
                    .collect::<Vec<f64>>(),
            );
        }
        let mut h = [0.0; 36];
        let mut g = [0.0; 6];
        for (i, r) in r0.iter().enumerate() {
            let w = if r.abs() <= problem.huber_m {
                1.0
            } else {
                problem.huber_m / r.abs()
            };
            for a in 0..6 {
                g[a] -= w * columns[a][i] * r;
                for b in 0..6 {
                    h[a * 6 + b] += w * columns[a][i] * columns[b][i];
                }
            }
        }
        (h, g)
    }

    /// One iteration; false once converged (no improving step, or a negligible one).
    pub fn step(&mut self, problem: &TargetProblem) -> bool {
        if self.converged {
            return false;
        }
        self.iterations += 1;
        let (h, g) = Self::system(problem, self.camera_from_vehicle);
        for _ in 0..10 {
            let mut damped = h;
            for i in 0..6 {
                damped[i * 6 + i] += self.lambda * h[i * 6 + i].max(1e-12);
            }
            let Some(step) = solve6(damped, g) else {
                self.lambda *= 10.0;
                continue;
            };
            let candidate = Self::moved(self.camera_from_vehicle, &step);
            let cost = problem.robust_cost(candidate);
            if cost < self.cost {
                let gain = self.cost - cost;
                self.camera_from_vehicle = candidate;
                self.cost = cost;
                self.lambda = (self.lambda * 0.3).max(1e-9);
                if gain <= 1e-12 * cost.max(1e-30) || step.iter().all(|v| v.abs() < 1e-9) {
                    self.converged = true;
                }
                return !self.converged;
            }
            self.lambda *= 10.0;
        }
        self.converged = true;
        false
    }

    pub fn solution(&self, problem: &TargetProblem) -> TargetSolution {
        let (_, plane_sq, plane_n, border_sq, border_n) =
            problem.residuals(self.camera_from_vehicle);
        let (information, _) = Self::system(problem, self.camera_from_vehicle);
        TargetSolution {
            vehicle_from_camera: self.camera_from_vehicle.inverse(),
            plane_rms_m: (plane_sq / plane_n.max(1) as f64).sqrt(),
            border_rms_m: (border_sq / border_n.max(1) as f64).sqrt(),
            information,
            iterations: self.iterations,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    /// Boards around a camera at the vehicle origin, sampled by a virtual spinning LiDAR at
    /// `lidar_origin` (rings every 0.2°, 0.2° azimuth steps), as the views a perfect camera
    /// would give under `vehicle_from_camera`.
    fn views(vehicle_from_camera: Rigid, lidar_origin: DVec3) -> Vec<BoardView> {
        let spec = BoardSpec::default();
        let half = half_size(&spec);
        let boards = [
            (DVec3::new(6.0, 0.0, 1.5), 0.0, 0.0),
            (DVec3::new(6.0, 2.5, 1.2), -0.4, 0.2),
            (DVec3::new(5.0, -2.5, 1.8), 0.5, -0.15),
        ];
        boards
            .iter()
            .map(|&(centre, swing, tilt): &(DVec3, f64, f64)| {
                // Board frame: x horizontal, y down, z towards the vehicle.
                let toward = (DVec3::new(0.0, 0.0, 1.5) - centre).normalize_or_zero();
                let yaw = toward.y.atan2(toward.x) + swing;
                let z = DVec3::new(yaw.cos() * tilt.cos(), yaw.sin() * tilt.cos(), tilt.sin());
                let x = DVec3::Z.cross(z).normalize_or_zero();
                let y = z.cross(x);
                let vehicle_from_board =
                    Rigid::new(DQuat::from_mat3(&glam::DMat3::from_cols(x, y, z)), centre);
                // Ray-cast rings against the board rectangle.
                let mut plane_points = Vec::new();
                let d0 = centre - lidar_origin;
                let (el0, az0) = (d0.z.atan2(d0.truncate().length()), d0.y.atan2(d0.x));
                for i in -40..=40 {
                    for j in -60..=60 {
                        let (el, az) = (
                            el0 + (i as f64 * 0.2).to_radians(),
                            az0 + (j as f64 * 0.2).to_radians(),
                        );
                        let dir = DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
                        let den = dir.dot(z);
                        let t = (centre - lidar_origin).dot(z) / den;
                        let hit = lidar_origin + dir * t;
                        let q = vehicle_from_board.inverse().transform_point(hit);
                        if t > 0.0 && q.x.abs() <= half.x && q.y.abs() <= half.y {
                            plane_points.push(hit);
                        }
                    }
                }
                BoardView {
                    camera_from_board: vehicle_from_camera.inverse() * vehicle_from_board,
                    vehicle_from_lidar_board: vehicle_from_board,
                    pnp_rms_px: 0.0,
                    border_points: ring_ends(
                        &plane_points,
                        Rigid::new(DQuat::IDENTITY, lidar_origin),
                    ),
                    plane_points,
                }
            })
            .collect()
    }

    #[test]
    fn edges_and_planes_recover_a_perturbed_camera_from_either_side() {
        let truth = Rigid::new(
            DQuat::from_euler(
                glam::EulerRot::ZYX,
                -std::f64::consts::FRAC_PI_2,
                0.0,
                -std::f64::consts::FRAC_PI_2,
            ),
            DVec3::new(1.5, 0.0, 1.6),
        );
        let lidar_origin = DVec3::new(1.0, 0.0, 1.9);
        let problem = TargetProblem {
            camera: "cam".into(),
            lidar: "lidar".into(),
            spec: BoardSpec::default(),
            views: views(truth, lidar_origin),
            huber_m: 0.03,
        };
        assert!(
            problem
                .views
                .iter()
                .all(|v| v.plane_points.len() > 100 && v.border_points.len() > 20)
        );
        for sign in [1.0, -1.0] {
            let start = truth.perturbed_right(
                DVec3::new(0.02, -0.03, 0.025) * sign,
                DVec3::new(0.15, -0.1, 0.12) * sign,
            );
            let solution = problem.solve(start, 50);
            let (r, t) = truth.difference(solution.vehicle_from_camera);
            // Ring ends sit within half a step of the border: sub-centimetre, not exact.
            assert!(
                r.to_degrees() < 0.05 && t < 0.01,
                "{sign}: {}° {} m",
                r.to_degrees(),
                t
            );
            assert!(solution.plane_rms_m < 1e-3, "{}", solution.plane_rms_m);
            assert!(solution.border_rms_m < 0.01, "{}", solution.border_rms_m);
            let diag: Vec<f64> = (0..6).map(|i| solution.information[i * 6 + i]).collect();
            assert!(diag.iter().all(|d| *d > 0.0), "{diag:?}");
        }
    }

    #[test]
    fn ring_ends_are_pushed_half_a_step_past_the_last_return() {
        // One ring of points 1 cm apart from x = 0 to 0.5 at 10 m: ends at −0.005 and 0.505.
        let pts: Vec<DVec3> = (0..=50)
            .map(|k| DVec3::new(10.0, k as f64 * 0.01, 0.0))
            .collect();
        let ends = ring_ends(&pts, Rigid::IDENTITY);
        assert_eq!(ends.len(), 2);
        let ys: Vec<f64> = ends.iter().map(|p| p.y).collect();
        assert!(
            ys.iter().any(|y| (y + 0.005).abs() < 1e-9)
                && ys.iter().any(|y| (y - 0.505).abs() < 1e-9),
            "{ys:?}"
        );
    }
}
