//! Checkerboard corner error: the paper's LiDAR–camera re-projection metric (supplementary
//! A2.3): board corners derived from LiDAR points, projected through the calibration under
//! test, against the same corners detected in the image, in pixels.
//!
//! How it works.
//! - **Boards in LiDAR** ([`boards_in_points`]): points (in a frame whose z is up) above the
//!   ground are clustered on a 15 cm voxel grid; each cluster gets a RANSAC plane (3 cm); a
//!   near-vertical plane whose inliers span the board's known width (and at most its height)
//!   is a board. Its horizontal axis is `up × normal` (boards stand upright, as in the
//!   simulator's checkerboard scene); its centre is the middle of the inliers' extent: vertically
//!   from the rows (1 cm bins of at least 8 points: rings crossing the board, not the stand or
//!   stray noisy returns), horizontally within those rows (rings sample the left and right
//!   edges densely; top and bottom are bounded by the ring spacing). The whole cluster must be no wider than the board, the plane needs 40
//!   points and must hang clear of the ground (boards are on stands). The inner corners follow from the known pattern, centred on the board.
//! - **Corners in the image** ([`saddle_points`]): X-junctions are maxima of the saddle response
//!   `Ixy² − Ixx·Iyy` of the Gaussian-blurred grey image (σ = 1.5 px), refined to sub-pixel by a
//!   quadratic fit, searched only around the projected boards.
//! - **Matching** ([`corner_error`]): the projected LiDAR corners are shifted over ±100 px to
//!   the translation that lands most of them within 2.5 px of a detected corner (a one-square
//!   shift matches fewer); each corner's error is then its distance to that detected corner,
//!   *without* the shift. A board counts when all its corners project inside the image and at
//!   least half of them are found there.

use crate::error::RunError;
use std::collections::{HashMap, HashSet};

use glam::{DVec2, DVec3};
use image::RgbImage;

use crate::features::chessboard::{grey_levels as gray, saddle_points};
use crate::geometry::Rigid;
use crate::geometry::camera::CameraIntrinsics;

/// A checkerboard target: squares and a white margin around them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoardSpec {
    pub squares_u: u32,
    pub squares_v: u32,
    pub square_m: f64,
    pub margin_m: f64,
}

impl Default for BoardSpec {
    /// The simulator's boards: 8 × 6 squares of 10 cm with an 8 cm margin.
    fn default() -> Self {
        Self {
            squares_u: 8,
            squares_v: 6,
            square_m: 0.10,
            margin_m: 0.08,
        }
    }
}

impl BoardSpec {
    /// Outer size (width along u, height along v) in metres.
    pub fn size_m(&self) -> (f64, f64) {
        (
            self.squares_u as f64 * self.square_m + 2.0 * self.margin_m,
            self.squares_v as f64 * self.square_m + 2.0 * self.margin_m,
        )
    }

    /// Inner corners relative to the board centre, (u, v) in metres.
    pub fn inner_corners(&self) -> Vec<DVec2> {
        let (su, sv, sq) = (self.squares_u as f64, self.squares_v as f64, self.square_m);
        let mut out = Vec::new();
        for j in 1..self.squares_v {
            for i in 1..self.squares_u {
                out.push(DVec2::new(
                    (i as f64 - su / 2.0) * sq,
                    (j as f64 - sv / 2.0) * sq,
                ));
            }
        }
        out
    }
}

/// A board found in LiDAR points, in the points' frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoardPose {
    pub center: DVec3,
    /// Horizontal in-plane axis.
    pub u: DVec3,
    /// In-plane axis pointing down.
    pub v: DVec3,
    pub normal: DVec3,
    pub inliers: usize,
}

impl BoardPose {
    pub fn inner_corners(&self, spec: &BoardSpec) -> Vec<DVec3> {
        spec.inner_corners()
            .into_iter()
            .map(|c| self.center + self.u * c.x + self.v * c.y)
            .collect()
    }
}

const VOXEL_M: f64 = 0.15;
const PLANE_M: f64 = 0.03;
const GROUND_CLEARANCE_M: f64 = 0.3;
const MIN_INLIERS: usize = 40;
const ROW_POINTS: usize = 8;

/// Boards among `points` (a frame whose +z is up, e.g. the vehicle or world frame).
pub fn boards_in_points(points: &[DVec3], spec: &BoardSpec) -> Vec<BoardPose> {
    boards_with_points(points, spec)
        .into_iter()
        .map(|(pose, _)| pose)
        .collect()
}

/// [`boards_in_points`] with each board's plane inliers (the board's own returns, its stand
/// excluded).
pub fn boards_with_points(points: &[DVec3], spec: &BoardSpec) -> Vec<(BoardPose, Vec<DVec3>)> {
    if points.len() < 20 {
        return Vec::new();
    }
    // Ground: everything within 30 cm of the 5th percentile height.
    let mut zs: Vec<f64> = points.iter().map(|p| p.z).collect();
    let k = zs.len() / 20;
    let (_, ground, _) = zs.select_nth_unstable_by(k, f64::total_cmp);
    let ground = *ground;
    let above: Vec<DVec3> = points
        .iter()
        .copied()
        .filter(|p| p.z > ground + GROUND_CLEARANCE_M && p.is_finite())
        .collect();
    let (w, h) = spec.size_m();
    let mut boards = Vec::new();
    for cluster in voxel_clusters(&above) {
        if cluster.len() < 15 {
            continue;
        }
        let pts: Vec<DVec3> = cluster.iter().map(|&i| above[i]).collect();
        let Some((normal, inliers)) = ransac_plane(&pts) else {
            continue;
        };
        if normal.z.abs() > 0.5 || inliers.len() < MIN_INLIERS {
            continue;
        }
        let u = DVec3::Z.cross(normal).normalize_or_zero();
        let mut v = normal.cross(u).normalize_or_zero();
        if v.z > 0.0 {
            v = -v;
        }
        let mean = inliers.iter().map(|&i| pts[i]).sum::<DVec3>() / inliers.len() as f64;
        let coords: Vec<(f64, f64)> = inliers
            .iter()
            .map(|&i| {
                let d = pts[i] - mean;
                (d.dot(u), d.dot(v))
            })
            .collect();
        // Vertical extent from rows: 1 cm bins of v holding at least ROW_POINTS points (a ring
        // across the board has dozens; a stand or a noisy stray return has a few).
        let mut rows: HashMap<i64, usize> = HashMap::new();
        for (_, b) in &coords {
            *rows.entry((b / 0.01).floor() as i64).or_default() += 1;
        }
        let full: Vec<i64> = rows
            .iter()
            .filter(|(_, n)| **n >= ROW_POINTS)
            .map(|(k, _)| *k)
            .collect();
        let (Some(&r0), Some(&r1)) = (full.iter().min(), full.iter().max()) else {
            continue;
        };
        let (b0, b1) = (r0 as f64 * 0.01, (r1 + 1) as f64 * 0.01);
        let (mut a0, mut a1) = (f64::MAX, f64::MIN);
        for (a, b) in &coords {
            if *b >= b0 - 0.01 && *b <= b1 + 0.01 {
                a0 = a0.min(*a);
                a1 = a1.max(*a);
            }
        }
        let (ext_u, ext_v) = (a1 - a0, b1 - b0);
        // The whole cluster (stand included) must be no wider than the board: a board-sized
        // patch of a car or a wall is not a board.
        let (c0, c1) = pts.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
            let a = (*p - mean).dot(u);
            (lo.min(a), hi.max(a))
        });
        if c1 - c0 > 1.3 * w {
            continue;
        }
        // Boards hang clear of the ground: a plane cut off by the ground filter is an object
        // standing on the ground.
        let lowest = inliers.iter().map(|&i| pts[i].z).fold(f64::MAX, f64::min);
        if lowest < ground + GROUND_CLEARANCE_M + 0.05 {
            continue;
        }
        if !(0.9 * w..=1.1 * w).contains(&ext_u) || !(0.6 * h..=1.1 * h).contains(&ext_v) {
            continue;
        }
        // The board's own returns: within its rows and columns (a stand crossing the board's
        // extended plane below it is not the board).
        let board_points = inliers
            .iter()
            .zip(&coords)
            .filter(|(_, (a, b))| {
                *a >= a0 - 0.01 && *a <= a1 + 0.01 && *b >= b0 - 0.01 && *b <= b1 + 0.01
            })
            .map(|(&i, _)| pts[i])
            .collect();
        boards.push((
            BoardPose {
                center: mean + u * (a0 + a1) / 2.0 + v * (b0 + b1) / 2.0,
                u,
                v,
                normal,
                inliers: inliers.len(),
            },
            board_points,
        ));
    }
    boards
}

/// Connected components of points on a voxel grid (26-neighbourhood).
fn voxel_clusters(points: &[DVec3]) -> Vec<Vec<usize>> {
    let key = |p: DVec3| {
        (
            (p.x / VOXEL_M).floor() as i64,
            (p.y / VOXEL_M).floor() as i64,
            (p.z / VOXEL_M).floor() as i64,
        )
    };
    let mut voxels: HashMap<(i64, i64, i64), Vec<usize>> = HashMap::new();
    for (i, p) in points.iter().enumerate() {
        voxels.entry(key(*p)).or_default().push(i);
    }
    let mut seen: HashSet<(i64, i64, i64)> = HashSet::new();
    let mut clusters = Vec::new();
    let mut keys: Vec<_> = voxels.keys().copied().collect();
    keys.sort_unstable();
    for start in keys {
        if !seen.insert(start) {
            continue;
        }
        let mut stack = vec![start];
        let mut members = Vec::new();
        while let Some(k) = stack.pop() {
            if let Some(ids) = voxels.get(&k) {
                members.extend_from_slice(ids);
            }
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let n = (k.0 + dx, k.1 + dy, k.2 + dz);
                        if voxels.contains_key(&n) && seen.insert(n) {
                            stack.push(n);
                        }
                    }
                }
            }
        }
        clusters.push(members);
    }
    clusters
}

/// RANSAC plane (deterministic sampling), refined by least squares on the inliers: the unit
/// normal and the inlier indices.
fn ransac_plane(pts: &[DVec3]) -> Option<(DVec3, Vec<usize>)> {
    let n = pts.len();
    if n < 3 {
        return None;
    }
    let mut state = 0x9E37_79B9_7F4A_7C15u64 ^ n as u64;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 33) as usize) % n
    };
    let mut best: Option<(DVec3, f64, usize)> = None;
    for _ in 0..200 {
        let (a, b, c) = (pts[next()], pts[next()], pts[next()]);
        let normal = (b - a).cross(c - a);
        if normal.length() < 1e-6 {
            continue;
        }
        let normal = normal.normalize_or_zero();
        let d = normal.dot(a);
        let count = pts
            .iter()
            .filter(|p| (normal.dot(**p) - d).abs() < PLANE_M)
            .count();
        if best.is_none_or(|b| count > b.2) {
            best = Some((normal, d, count));
        }
    }
    let (normal, d, _) = best?;
    let inliers: Vec<usize> = (0..n)
        .filter(|&i| (normal.dot(pts[i]) - d).abs() < PLANE_M)
        .collect();
    // Least-squares normal: the smallest-variance direction of the inliers (power iteration on
    // the inverse is overkill here; use the covariance's cross-product trick).
    let mean = inliers.iter().map(|&i| pts[i]).sum::<DVec3>() / inliers.len().max(1) as f64;
    let mut cov = [[0.0f64; 3]; 3];
    for &i in &inliers {
        let q = (pts[i] - mean).to_array();
        for r in 0..3 {
            for c in 0..3 {
                cov[r][c] += q[r] * q[c];
            }
        }
    }
    let rows = cov.map(DVec3::from_array);
    let candidates = [
        rows[0].cross(rows[1]),
        rows[0].cross(rows[2]),
        rows[1].cross(rows[2]),
    ];
    let refined = candidates
        .into_iter()
        .max_by(|a, b| a.length_squared().total_cmp(&b.length_squared()))
        .map(|v| v.normalize_or_zero())
        .filter(|v| *v != DVec3::ZERO && v.dot(normal).abs() > 0.9)
        .map_or(normal, |v| if v.dot(normal) < 0.0 { -v } else { v });
    Some((refined, inliers))
}

/// The corner error of one image against LiDAR boards.
#[derive(Clone, Debug, PartialEq)]
pub struct CornerError {
    /// Boards whose corners were found in the image.
    pub boards: usize,
    pub corners: usize,
    /// Mean distance (px) between projected LiDAR-derived corners and image corners.
    pub mean_px: f64,
    /// Per found board: its mean error (px).
    pub per_board_px: Vec<f64>,
}

const SEARCH_PX: i32 = 100;
const MATCH_PX: f64 = 2.5;

/// Project each board's LiDAR-derived inner corners with `camera_from_points` and measure them
/// against the image's checkerboard corners. `None` when no board is found in the image.
pub fn corner_error(
    image: &RgbImage,
    intrinsics: &CameraIntrinsics,
    camera_from_points: Rigid,
    boards: &[BoardPose],
    spec: &BoardSpec,
) -> Option<CornerError> {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let g = gray(image);
    let mut per_board = Vec::new();
    let mut all = Vec::new();
    for board in boards {
        let predicted: Vec<DVec2> = board
            .inner_corners(spec)
            .into_iter()
            .filter_map(|p| {
                let q = camera_from_points.transform_point(p);
                (q.z > 0.3).then(|| intrinsics.project(q)).flatten()
            })
            .collect();
        // Only boards wholly inside the image: a partial grid can match one square off.
        let margin = 8.0;
        if predicted.len() < spec.inner_corners().len()
            || predicted.iter().any(|p| {
                p.x < margin || p.y < margin || p.x > w as f64 - margin || p.y > h as f64 - margin
            })
        {
            continue;
        }
        let (mut lo, mut hi) = (DVec2::splat(f64::MAX), DVec2::splat(f64::MIN));
        for p in &predicted {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        let pad = SEARCH_PX as f64 + 10.0;
        if hi.x + pad < 0.0 || hi.y + pad < 0.0 || lo.x - pad > w as f64 || lo.y - pad > h as f64 {
            continue;
        }
        let roi = (
            (lo.x - pad).max(0.0) as usize,
            (lo.y - pad).max(0.0) as usize,
            (hi.x + pad).max(0.0) as usize,
            (hi.y + pad).max(0.0) as usize,
        );
        let saddles = saddle_points(&g, w, h, roi);
        if saddles.is_empty() {
            continue;
        }
        // Hit grid: saddles dilated by MATCH_PX, in the ROI.
        let (gx0, gy0) = (roi.0 as i32, roi.1 as i32);
        let (gw, gh) = ((roi.2 - roi.0).max(1) as i32, (roi.3 - roi.1).max(1) as i32);
        let mut hit = vec![false; (gw * gh) as usize];
        let rr = MATCH_PX.ceil() as i32;
        for s in &saddles {
            let (sx, sy) = (s.x.round() as i32, s.y.round() as i32);
            for dy in -rr..=rr {
                for dx in -rr..=rr {
                    let (x, y) = (sx + dx - gx0, sy + dy - gy0);
                    if x >= 0
                        && y >= 0
                        && x < gw
                        && y < gh
                        && ((dx * dx + dy * dy) as f64) <= MATCH_PX * MATCH_PX
                    {
                        hit[(y * gw + x) as usize] = true;
                    }
                }
            }
        }
        let mut best = (0usize, i32::MAX, (0i32, 0i32));
        for ty in -SEARCH_PX..=SEARCH_PX {
            for tx in -SEARCH_PX..=SEARCH_PX {
                let count = predicted
                    .iter()
                    .filter(|p| {
                        let (x, y) = (p.x.round() as i32 + tx - gx0, p.y.round() as i32 + ty - gy0);
                        x >= 0 && y >= 0 && x < gw && y < gh && hit[(y * gw + x) as usize]
                    })
                    .count();
                let norm = tx * tx + ty * ty;
                if count > best.0 || (count == best.0 && norm < best.1) {
                    best = (count, norm, (tx, ty));
                }
            }
        }
        if best.0 < predicted.len().div_ceil(2) {
            continue;
        }
        let shift = DVec2::new(best.2.0 as f64, best.2.1 as f64);
        let errors: Vec<f64> = predicted
            .iter()
            .filter_map(|p| {
                let target = *p + shift;
                saddles
                    .iter()
                    .map(|s| (s.distance(target), *s))
                    .filter(|(d, _)| *d <= MATCH_PX + 1.0)
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .map(|(_, s)| s.distance(*p))
            })
            .collect();
        if errors.is_empty() {
            continue;
        }
        per_board.push(errors.iter().sum::<f64>() / errors.len() as f64);
        all.extend(errors);
    }
    if all.is_empty() {
        return None;
    }
    Some(CornerError {
        boards: per_board.len(),
        corners: all.len(),
        mean_px: all.iter().sum::<f64>() / all.len() as f64,
        per_board_px: per_board,
    })
}

/// The corner error of one camera–LiDAR pair of a drive under `rig`, on up to `frames` images
/// spread over the drive (each with the sweep nearest in time, moved into the world frame with
/// the trajectory; boards are found there, world +z up).
pub fn pair_corner_error(
    drive: &crate::log::Drive,
    rig: &crate::calib::Rig,
    camera: &str,
    lidar: &str,
    frames: usize,
    spec: &BoardSpec,
) -> Result<Option<CornerError>, RunError> {
    use crate::geometry::projection::world_points;
    let cam = rig
        .sensor(camera)
        .ok_or_else(|| RunError::no_sensor("camera", camera))?;
    let intr = cam
        .camera
        .as_ref()
        .ok_or_else(|| RunError::Invalid(format!("'{camera}' has no intrinsics")))?;
    let vehicle_from_lidar = rig
        .sensor(lidar)
        .ok_or_else(|| RunError::no_sensor("LiDAR", lidar))?
        .vehicle_from_sensor;
    let images = &drive
        .stream(camera)
        .ok_or_else(|| RunError::NotEnoughData(format!("no images of '{camera}'")))?
        .frames;
    let sweeps = &drive
        .stream(lidar)
        .ok_or_else(|| RunError::NotEnoughData(format!("no sweeps of '{lidar}'")))?
        .frames;
    if images.is_empty() || sweeps.is_empty() {
        return Ok(None);
    }
    let all: Vec<usize> = (0..images.len()).collect();
    let mut parts = Vec::new();
    for i in crate::log::spread_evenly(&all, frames) {
        let stamp = images[i].stamp_nanos;
        let Some(j) = (0..sweeps.len()).min_by_key(|&j| (sweeps[j].stamp_nanos - stamp).abs())
        else {
            continue;
        };
        let Ok(world_from_vehicle) = drive.trajectory.world_from_vehicle(stamp) else {
            continue;
        };
        let Some(sweep) = drive.sweep_or_skip(lidar, j) else {
            continue;
        };
        let view = sweep.view();
        let Ok(points) = world_points(&view, &drive.trajectory, vehicle_from_lidar, 1) else {
            continue;
        };
        let boards = boards_in_points(&points, spec);
        let Some(image) = drive.image_or_skip(camera, i) else {
            continue;
        };
        let camera_from_world = (world_from_vehicle * cam.vehicle_from_sensor).inverse();
        if let Some(e) = corner_error(&image, intr, camera_from_world, &boards, spec) {
            parts.push(e);
        }
    }
    if parts.is_empty() {
        return Ok(None);
    }
    let corners: usize = parts.iter().map(|p| p.corners).sum();
    Ok(Some(CornerError {
        boards: parts.iter().map(|p| p.boards).sum(),
        corners,
        mean_px: parts
            .iter()
            .map(|p| p.mean_px * p.corners as f64)
            .sum::<f64>()
            / corners as f64,
        per_board_px: parts.into_iter().flat_map(|p| p.per_board_px).collect(),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An anti-aliased checkerboard drawn analytically: 8 × 6 squares of `sq` px from `origin`,
    /// rotated by `angle`.
    fn board_image(w: u32, h: u32, origin: DVec2, sq: f64, angle: f64) -> (RgbImage, Vec<DVec2>) {
        let (c, s) = (angle.cos(), angle.sin());
        let to_board = |p: DVec2| {
            let d = p - origin;
            DVec2::new(c * d.x + s * d.y, -s * d.x + c * d.y) / sq
        };
        let img = RgbImage::from_fn(w, h, |x, y| {
            let mut acc = 0.0;
            for (ox, oy) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
                let b = to_board(DVec2::new(x as f64 + ox - 0.5, y as f64 + oy - 0.5));
                let inside = b.x >= 0.0 && b.y >= 0.0 && b.x < 8.0 && b.y < 6.0;
                let dark = inside && ((b.x.floor() + b.y.floor()) as i64) % 2 == 0;
                acc += if dark { 20.0 } else { 230.0 };
            }
            let v = (acc / 4.0) as u8;
            image::Rgb([v, v, v])
        });
        let mut corners = Vec::new();
        for j in 1..6 {
            for i in 1..8 {
                let b = DVec2::new(i as f64, j as f64) * sq;
                corners.push(origin + DVec2::new(c * b.x - s * b.y, s * b.x + c * b.y));
            }
        }
        (img, corners)
    }

    #[test]
    fn saddles_sit_on_the_corners_to_sub_pixel() {
        let (img, truth) = board_image(320, 240, DVec2::new(60.3, 50.7), 24.0, 0.2);
        let g = gray(&img);
        let found = saddle_points(&g, 320, 240, (0, 0, 320, 240));
        let mut worst: f64 = 0.0;
        for t in &truth {
            let d = found
                .iter()
                .map(|f| f.distance(*t))
                .fold(f64::MAX, f64::min);
            worst = worst.max(d);
        }
        assert!(worst < 0.35, "worst corner {worst} px");
        assert!(
            found.len() >= truth.len() && found.len() <= truth.len() + 4,
            "{}",
            found.len()
        );
    }

    /// A vertical board 7 m ahead sampled by horizontal "rings", plus ground and a wall.
    fn lidar_scene(center: DVec3, yaw: f64) -> Vec<DVec3> {
        let spec = BoardSpec::default();
        let (w, h) = spec.size_m();
        let normal = DVec3::new(-yaw.cos(), -yaw.sin(), 0.0);
        let u = DVec3::Z.cross(normal).normalize_or_zero();
        let v = -DVec3::Z;
        let mut pts = Vec::new();
        let mut z = center.z - h / 2.0 + 0.013;
        while z < center.z + h / 2.0 {
            let mut a = -w / 2.0 + 0.004;
            while a < w / 2.0 {
                pts.push(center + u * a + v * (center.z - z));
                a += 0.024;
            }
            z += 0.021;
        }
        for i in 0..2000 {
            let (x, y) = ((i % 50) as f64 * 0.4 - 10.0, (i / 50) as f64 * 0.4 - 8.0);
            pts.push(DVec3::new(x, y, 0.0));
        }
        for i in 0..400 {
            pts.push(DVec3::new(
                15.0,
                (i % 40) as f64 * 0.2 - 4.0,
                (i / 40) as f64 * 0.3,
            ));
        }
        pts
    }

    #[test]
    fn a_board_is_found_in_lidar_points_with_its_centre() {
        let center = DVec3::new(7.0, 1.0, 1.5);
        let boards = boards_in_points(&lidar_scene(center, 0.3), &BoardSpec::default());
        assert_eq!(boards.len(), 1, "{boards:?}");
        let b = boards[0];
        assert!(b.center.distance(center) < 0.02, "{:?}", b.center);
        assert!(
            b.normal
                .dot(DVec3::new(-(0.3f64).cos(), -(0.3f64).sin(), 0.0))
                .abs()
                > 0.999
        );
    }
}
