//! Checkerboards in images without OpenCV: the inner corners of every board of a known pattern,
//! ordered row by row, to sub-pixel accuracy.
//!
//! How it works.
//! - **X-junctions** ([`saddle_points`]): maxima of the saddle response `Ixy² − Ixx·Iyy` of the
//!   Gaussian-blurred grey image (σ = 1.5 px) that have four alternating dark and bright sectors
//!   around them (L- and T-junctions at a board's border have two).
//! - **Grids** ([`find_chessboards`]): from each unused junction, the nearest neighbour and the
//!   nearest one roughly perpendicular to it give two lattice steps; the grid then grows
//!   breadth-first, predicting each neighbour from the spacing of the grid's own nearest known
//!   corners in that direction (which follows perspective), accepting the nearest junction within
//!   35 % of a step. A grid of exactly `cols × rows` (either way round) is a board. Its order is
//!   made canonical: the first index runs along the longer side, the handedness is that of the
//!   board seen from the front (x right, y down), and of the two orders left (a board is
//!   symmetric under a half turn) the one whose rows run rightwards.
//! - **Sub-pixel refinement** ([`refine_corner`]): at a corner q, every pixel p nearby either
//!   sits in a flat region (gradient zero) or on an edge through q (gradient ⟂ p − q), so
//!   `Σ w g gᵀ (p − q) = 0`: q is solved from that 2 × 2 system and the solve repeated (the
//!   principle of OpenCV's `cornerSubPix`), over a Gaussian window smaller than half a square.

use std::collections::{HashMap, VecDeque};

use glam::DVec2;

pub use super::grey::grey_levels;

/// Checkerboard X-junctions inside `roi` = (x0, y0, x1, y1) of a `w × h` grey image, with
/// sub-pixel positions.
pub fn saddle_points(
    gray: &[f32],
    w: usize,
    h: usize,
    roi: (usize, usize, usize, usize),
) -> Vec<DVec2> {
    let (x0, y0) = (roi.0.min(w), roi.1.min(h));
    let (x1, y1) = (roi.2.min(w), roi.3.min(h));
    if x1 < x0 + 12 || y1 < y0 + 12 {
        return Vec::new();
    }
    let (rw, rh) = (x1 - x0, y1 - y0);
    // Separable Gaussian blur, σ = 1.5 px.
    let kernel: Vec<f32> = (-4..=4)
        .map(|i: i32| (-(i * i) as f32 / (2.0 * 1.5 * 1.5)).exp())
        .collect();
    let ksum: f32 = kernel.iter().sum();
    let at = |x: isize, y: isize| {
        gray[(y.clamp(0, h as isize - 1) as usize) * w + x.clamp(0, w as isize - 1) as usize]
    };
    let mut tmp = vec![0.0f32; rw * rh];
    for y in 0..rh {
        for x in 0..rw {
            let mut s = 0.0;
            for (k, c) in kernel.iter().enumerate() {
                s += c * at((x0 + x) as isize + k as isize - 4, (y0 + y) as isize);
            }
            tmp[y * rw + x] = s / ksum;
        }
    }
    let mut blur = vec![0.0f32; rw * rh];
    for y in 0..rh {
        for x in 0..rw {
            let mut s = 0.0;
            for (k, c) in kernel.iter().enumerate() {
                let yy = (y as isize + k as isize - 4).clamp(0, rh as isize - 1) as usize;
                s += c * tmp[yy * rw + x];
            }
            blur[y * rw + x] = s / ksum;
        }
    }
    let b = |x: usize, y: usize| blur[y * rw + x];
    let mut response = vec![0.0f32; rw * rh];
    for y in 1..rh - 1 {
        for x in 1..rw - 1 {
            let ixx = b(x + 1, y) - 2.0 * b(x, y) + b(x - 1, y);
            let iyy = b(x, y + 1) - 2.0 * b(x, y) + b(x, y - 1);
            let ixy = (b(x + 1, y + 1) - b(x - 1, y + 1) - b(x + 1, y - 1) + b(x - 1, y - 1)) / 4.0;
            response[y * rw + x] = (ixy * ixy - ixx * iyy).max(0.0);
        }
    }
    let max = response.iter().copied().fold(0.0f32, f32::max);
    if max <= 0.0 {
        return Vec::new();
    }
    let threshold = 0.15 * max;
    let r = |x: usize, y: usize| response[y * rw + x];
    let mut out = Vec::new();
    for y in 3..rh - 3 {
        for x in 3..rw - 3 {
            let v = r(x, y);
            if v < threshold {
                continue;
            }
            let mut is_max = true;
            'nms: for dy in -3i32..=3 {
                for dx in -3i32..=3 {
                    if (dx, dy) != (0, 0) {
                        let q = r((x as i32 + dx) as usize, (y as i32 + dy) as usize);
                        if q > v || (q == v && (dy, dx) < (0, 0)) {
                            is_max = false;
                            break 'nms;
                        }
                    }
                }
            }
            if !is_max || !x_junction(&blur, rw, rh, x, y) {
                continue;
            }
            // Quadratic fit over the 3×3 neighbourhood: offset = −H⁻¹ g.
            let gx = (r(x + 1, y) - r(x - 1, y)) / 2.0;
            let gy = (r(x, y + 1) - r(x, y - 1)) / 2.0;
            let hxx = r(x + 1, y) - 2.0 * v + r(x - 1, y);
            let hyy = r(x, y + 1) - 2.0 * v + r(x, y - 1);
            let hxy = (r(x + 1, y + 1) - r(x - 1, y + 1) - r(x + 1, y - 1) + r(x - 1, y - 1)) / 4.0;
            let det = hxx * hyy - hxy * hxy;
            let (mut dx, mut dy) = (0.0, 0.0);
            if det.abs() > 1e-12 {
                dx = -(hyy * gx - hxy * gy) / det;
                dy = -(hxx * gy - hxy * gx) / det;
            }
            out.push(DVec2::new(
                (x0 + x) as f64 + dx.clamp(-1.0, 1.0) as f64,
                (y0 + y) as f64 + dy.clamp(-1.0, 1.0) as f64,
            ));
        }
    }
    out
}

/// An X-junction has four alternating dark and bright sectors around it: on a circle of radius
/// 4 px the grey level crosses its mean exactly four times (L- and T-junctions at a board's
/// border cross twice).
fn x_junction(blur: &[f32], w: usize, h: usize, x: usize, y: usize) -> bool {
    const N: usize = 24;
    const R: f32 = 4.0;
    if x < 5 || y < 5 || x + 5 >= w || y + 5 >= h {
        return false;
    }
    let ring: Vec<f32> = (0..N)
        .map(|k| {
            let a = k as f32 / N as f32 * std::f32::consts::TAU;
            let (fx, fy) = (x as f32 + R * a.cos(), y as f32 + R * a.sin());
            let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
            let (tx, ty) = (fx - x0 as f32, fy - y0 as f32);
            let p = |xx: usize, yy: usize| blur[yy * w + xx];
            (p(x0, y0) * (1.0 - tx) + p(x0 + 1, y0) * tx) * (1.0 - ty)
                + (p(x0, y0 + 1) * (1.0 - tx) + p(x0 + 1, y0 + 1) * tx) * ty
        })
        .collect();
    let mean = ring.iter().sum::<f32>() / N as f32;
    let (lo, hi) = ring
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    if hi - lo < 20.0 {
        return false;
    }
    let crossings = (0..N)
        .filter(|&k| (ring[k] > mean) != (ring[(k + 1) % N] > mean))
        .count();
    crossings == 4
}

/// A checkerboard found in an image: its inner corners row by row, `cols` per row.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageBoard {
    pub cols: usize,
    pub rows: usize,
    pub corners: Vec<DVec2>,
}

impl ImageBoard {
    pub fn corner(&self, col: usize, row: usize) -> DVec2 {
        self.corners[row * self.cols + col]
    }

    /// The same board in the other order a half turn allows (last corner first).
    pub fn half_turn(&self) -> ImageBoard {
        let mut corners = self.corners.clone();
        corners.reverse();
        ImageBoard {
            corners,
            ..self.clone()
        }
    }
}

/// Step to the nearest junction within 35 % of the predicted spacing.
const ACCEPT: f64 = 0.35;

/// Every board with `pattern = (cols, rows)` inner corners (cols ≥ rows, e.g. (7, 5) for 8 × 6
/// squares) inside `roi = (x0, y0, x1, y1)` of a `w × h` grey image, corners refined to
/// sub-pixel accuracy.
pub fn find_chessboards(
    grey: &[f32],
    w: usize,
    h: usize,
    pattern: (usize, usize),
    roi: (usize, usize, usize, usize),
) -> Vec<ImageBoard> {
    let (cols, rows) = (pattern.0.max(pattern.1), pattern.0.min(pattern.1));
    if cols < 2 || rows < 2 || grey.len() < w * h {
        return Vec::new();
    }
    let pts = saddle_points(grey, w, h, roi);
    let mut used = vec![false; pts.len()];
    let mut boards = Vec::new();
    for seed in 0..pts.len() {
        if used[seed] {
            continue;
        }
        let Some(grid) = grow_grid(&pts, &used, seed) else {
            continue;
        };
        let Some(board) = as_board(&pts, &grid, cols, rows) else {
            continue;
        };
        for idx in grid.values() {
            used[*idx] = true;
        }
        let spacing = mean_spacing(&board);
        let radius = (0.4 * spacing).clamp(2.0, 6.0);
        let corners = board
            .corners
            .iter()
            .map(|c| refine_corner(grey, w, h, *c, radius))
            .collect();
        boards.push(ImageBoard { corners, ..board });
    }
    boards
}

/// The lattice grown from `seed` over unused junctions: grid index → junction index.
fn grow_grid(pts: &[DVec2], used: &[bool], seed: usize) -> Option<HashMap<(i32, i32), usize>> {
    let p0 = pts[seed];
    let mut near: Vec<usize> = (0..pts.len()).filter(|&k| k != seed && !used[k]).collect();
    near.sort_by(|&a, &b| (pts[a] - p0).length().total_cmp(&(pts[b] - p0).length()));
    let &first = near.first()?;
    let a = pts[first] - p0;
    let b = near
        .iter()
        .skip(1)
        .take(8)
        .map(|&k| pts[k] - p0)
        .find(|v| {
            let cos = v.dot(a) / (v.length() * a.length()).max(1e-9);
            cos.abs() < 0.5 && (0.5..2.0).contains(&(v.length() / a.length().max(1e-9)))
        })?;
    let mut grid: HashMap<(i32, i32), usize> = HashMap::new();
    let mut taken: HashMap<usize, (i32, i32)> = HashMap::new();
    grid.insert((0, 0), seed);
    taken.insert(seed, (0, 0));
    let mut queue = VecDeque::from([(0i32, 0i32)]);
    while let Some((i, j)) = queue.pop_front() {
        let p = pts[grid[&(i, j)]];
        for (di, dj) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
            let next = (i + di, j + dj);
            if grid.contains_key(&next) {
                continue;
            }
            // The spacing in this direction from the grid's own corners: the step just behind
            // (extrapolating perspective), else the one across, else the seed's.
            let at = |i: i32, j: i32| grid.get(&(i, j)).map(|&k| pts[k]);
            let step = at(i - di, j - dj)
                .map(|q| p - q)
                .or_else(|| {
                    let (pi, pj) = (dj, di);
                    let side = |s: i32| {
                        let q0 = at(i + s * pi, j + s * pj)?;
                        let q1 = at(i + s * pi + di, j + s * pj + dj)?;
                        Some(q1 - q0)
                    };
                    side(1).or_else(|| side(-1))
                })
                .unwrap_or(if di != 0 {
                    a * di as f64
                } else {
                    b * dj as f64
                });
            let predicted = p + step;
            let tolerance = ACCEPT * step.length();
            let found = (0..pts.len())
                .filter(|&k| !used[k] && !taken.contains_key(&k))
                .map(|k| (k, (pts[k] - predicted).length()))
                .filter(|(_, d)| *d < tolerance)
                .min_by(|x, y| x.1.total_cmp(&y.1));
            if let Some((k, _)) = found {
                grid.insert(next, k);
                taken.insert(k, next);
                queue.push_back(next);
            }
        }
    }
    Some(grid)
}

/// The grid as a `cols × rows` board in canonical order, if it is one.
fn as_board(
    pts: &[DVec2],
    grid: &HashMap<(i32, i32), usize>,
    cols: usize,
    rows: usize,
) -> Option<ImageBoard> {
    if grid.len() != cols * rows {
        return None;
    }
    let (i0, i1) = grid
        .keys()
        .fold((i32::MAX, i32::MIN), |(a, b), k| (a.min(k.0), b.max(k.0)));
    let (j0, j1) = grid
        .keys()
        .fold((i32::MAX, i32::MIN), |(a, b), k| (a.min(k.1), b.max(k.1)));
    let (ni, nj) = ((i1 - i0 + 1) as usize, (j1 - j0 + 1) as usize);
    let transposed = match (ni, nj) {
        (c, r) if c == cols && r == rows => false,
        (r, c) if c == cols && r == rows => true,
        _ => return None,
    };
    let at = |c: usize, r: usize| -> Option<DVec2> {
        let key = if transposed {
            (i0 + r as i32, j0 + c as i32)
        } else {
            (i0 + c as i32, j0 + r as i32)
        };
        grid.get(&key).map(|&k| pts[k])
    };
    let mut corners = Vec::with_capacity(cols * rows);
    for r in 0..rows {
        for c in 0..cols {
            corners.push(at(c, r)?);
        }
    }
    let mut board = ImageBoard {
        cols,
        rows,
        corners,
    };
    // Handedness of a board seen from the front (x right, y down): u × v > 0.
    let u = board.corner(cols - 1, 0) - board.corner(0, 0);
    let v = board.corner(0, rows - 1) - board.corner(0, 0);
    if u.perp_dot(v) < 0.0 {
        let flipped: Vec<DVec2> = (0..rows)
            .rev()
            .flat_map(|r| board.corners[r * cols..(r + 1) * cols].to_vec())
            .collect();
        board.corners = flipped;
    }
    // Of the two orders a half turn leaves, rows run rightwards.
    if board.corner(cols - 1, 0).x < board.corner(0, 0).x {
        board = board.half_turn();
    }
    Some(board)
}

fn mean_spacing(board: &ImageBoard) -> f64 {
    let mut sum = 0.0;
    let mut n = 0;
    for r in 0..board.rows {
        for c in 0..board.cols - 1 {
            sum += (board.corner(c + 1, r) - board.corner(c, r)).length();
            n += 1;
        }
    }
    sum / n.max(1) as f64
}

/// A corner near `start` refined to sub-pixel accuracy over a Gaussian window of `radius` px:
/// `q = (Σ w g gᵀ)⁻¹ Σ w g gᵀ p`, repeated until it moves less than 0.005 px. The start is kept
/// when the system is singular or the solution wanders more than `radius` away.
pub fn refine_corner(grey: &[f32], w: usize, h: usize, start: DVec2, radius: f64) -> DVec2 {
    let r = radius.ceil() as i64;
    let sigma2 = (0.5 * radius).powi(2).max(1e-6);
    let at = |x: i64, y: i64| {
        grey[(y.clamp(0, h as i64 - 1) as usize) * w + x.clamp(0, w as i64 - 1) as usize] as f64
    };
    let mut q = start;
    for _ in 0..20 {
        let (cx, cy) = (q.x.round() as i64, q.y.round() as i64);
        if cx - r < 1 || cy - r < 1 || cx + r + 1 >= w as i64 || cy + r + 1 >= h as i64 {
            return start;
        }
        let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
        let mut rhs = DVec2::ZERO;
        for y in cy - r..=cy + r {
            for x in cx - r..=cx + r {
                let p = DVec2::new(x as f64, y as f64);
                let d2 = (p - q).length_squared();
                if d2 > radius * radius {
                    continue;
                }
                let wgt = (-d2 / (2.0 * sigma2)).exp();
                let gx = (at(x + 1, y) - at(x - 1, y)) * 0.5;
                let gy = (at(x, y + 1) - at(x, y - 1)) * 0.5;
                let (gxx, gxy, gyy) = (wgt * gx * gx, wgt * gx * gy, wgt * gy * gy);
                a += gxx;
                b += gxy;
                c += gyy;
                rhs += DVec2::new(gxx * p.x + gxy * p.y, gxy * p.x + gyy * p.y);
            }
        }
        let det = a * c - b * b;
        if det.abs() < 1e-9 * (a + c).powi(2).max(1e-12) {
            return start;
        }
        let next = DVec2::new((c * rhs.x - b * rhs.y) / det, (a * rhs.y - b * rhs.x) / det);
        if (next - start).length() > radius {
            return start;
        }
        let moved = (next - q).length();
        q = next;
        if moved < 0.005 {
            break;
        }
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::RgbImage;

    /// A `w × h` image of boards: each is (homography from board squares to pixels, squares u,
    /// squares v), rendered with 4 × 4 supersampling on a mid-grey background, pixel centres at
    /// integer coordinates; returns the image and each board's inner corners in pixels.
    fn render(w: u32, h: u32, boards: &[([f64; 9], u32, u32)]) -> (RgbImage, Vec<Vec<DVec2>>) {
        let map = |hm: &[f64; 9], u: f64, v: f64| {
            let x = hm[0] * u + hm[1] * v + hm[2];
            let y = hm[3] * u + hm[4] * v + hm[5];
            let z = hm[6] * u + hm[7] * v + hm[8];
            DVec2::new(x / z, y / z)
        };
        let inverse = |m: &[f64; 9]| {
            let det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6])
                + m[2] * (m[3] * m[7] - m[4] * m[6]);
            [
                (m[4] * m[8] - m[5] * m[7]) / det,
                (m[2] * m[7] - m[1] * m[8]) / det,
                (m[1] * m[5] - m[2] * m[4]) / det,
                (m[5] * m[6] - m[3] * m[8]) / det,
                (m[0] * m[8] - m[2] * m[6]) / det,
                (m[2] * m[3] - m[0] * m[5]) / det,
                (m[3] * m[7] - m[4] * m[6]) / det,
                (m[1] * m[6] - m[0] * m[7]) / det,
                (m[0] * m[4] - m[1] * m[3]) / det,
            ]
        };
        let inverses: Vec<[f64; 9]> = boards.iter().map(|(m, _, _)| inverse(m)).collect();
        let img = RgbImage::from_fn(w, h, |x, y| {
            let mut sum = 0.0;
            for sy in 0..4 {
                for sx in 0..4 {
                    let px = x as f64 + (sx as f64 + 0.5) / 4.0 - 0.5;
                    let py = y as f64 + (sy as f64 + 0.5) / 4.0 - 0.5;
                    let mut v = 120.0;
                    for (inv, (_, su, sv)) in inverses.iter().zip(boards) {
                        let b = map(inv, px, py);
                        // A white margin of half a square around the squares.
                        if b.x >= -0.5
                            && b.y >= -0.5
                            && b.x < *su as f64 + 0.5
                            && b.y < *sv as f64 + 0.5
                        {
                            v = if b.x < 0.0 || b.y < 0.0 || b.x >= *su as f64 || b.y >= *sv as f64
                            {
                                235.0
                            } else if (b.x.floor() as i64 + b.y.floor() as i64) % 2 == 0 {
                                25.0
                            } else {
                                235.0
                            };
                        }
                    }
                    sum += v;
                }
            }
            let g = (sum / 16.0) as u8;
            image::Rgb([g, g, g])
        });
        let corners = boards
            .iter()
            .map(|(m, su, sv)| {
                (1..*sv)
                    .flat_map(|j| (1..*su).map(move |i| (i, j)))
                    .map(|(i, j)| map(m, i as f64, j as f64))
                    .collect()
            })
            .collect();
        (img, corners)
    }

    /// Mean distance to the truth under the better of the two orders a half turn allows.
    fn error(found: &ImageBoard, truth: &[DVec2]) -> f64 {
        let mean = |b: &ImageBoard| {
            b.corners
                .iter()
                .zip(truth)
                .map(|(a, t)| (*a - *t).length())
                .sum::<f64>()
                / truth.len() as f64
        };
        mean(found).min(mean(&found.half_turn()))
    }

    #[test]
    fn boards_in_perspective_are_found_ordered_and_sub_pixel() {
        // Two boards of 8 × 6 squares, one in strong perspective and rotated.
        let a = [22.0, 3.0, 60.0, -2.0, 21.0, 50.0, 0.0, 0.0, 1.0];
        let b = [18.0, -6.0, 300.0, 7.0, 19.0, 60.0, 0.004, 0.006, 1.0];
        let (img, truth) = render(520, 240, &[(a, 8, 6), (b, 8, 6)]);
        let grey = grey_levels(&img);
        let found = find_chessboards(&grey, 520, 240, (7, 5), (0, 0, 520, 240));
        assert_eq!(found.len(), 2, "{found:?}");
        for t in &truth {
            let best = found.iter().map(|f| error(f, t)).fold(f64::MAX, f64::min);
            assert!(best < 0.05, "mean corner error {best} px");
        }
        for f in &found {
            assert_eq!((f.cols, f.rows, f.corners.len()), (7, 5, 35));
            // Canonical order: rows run rightwards, the board seen from the front.
            let u = f.corner(6, 0) - f.corner(0, 0);
            let v = f.corner(0, 4) - f.corner(0, 0);
            assert!(u.x > 0.0 && u.perp_dot(v) > 0.0);
        }
    }

    #[test]
    fn a_board_of_another_size_or_no_board_gives_nothing() {
        let a = [20.0, 0.0, 40.0, 0.0, 20.0, 40.0, 0.0, 0.0, 1.0];
        let (img, _) = render(260, 200, &[(a, 6, 5)]);
        let grey = grey_levels(&img);
        assert!(find_chessboards(&grey, 260, 200, (7, 5), (0, 0, 260, 200)).is_empty());
        // The 6 × 5 board itself is found with its own pattern, given either way round.
        assert_eq!(
            find_chessboards(&grey, 260, 200, (4, 5), (0, 0, 260, 200)).len(),
            1
        );
        let flat = vec![100.0f32; 260 * 200];
        assert!(find_chessboards(&flat, 260, 200, (7, 5), (0, 0, 260, 200)).is_empty());
    }

    #[test]
    fn refinement_converges_from_a_pixel_away() {
        let a = [24.0, 2.0, 30.5, -1.5, 23.0, 30.25, 0.0, 0.0, 1.0];
        let (img, truth) = render(260, 200, &[(a, 8, 6)]);
        let grey = grey_levels(&img);
        for t in truth[0].iter().take(10) {
            let q = refine_corner(&grey, 260, 200, *t + DVec2::new(0.9, -0.8), 6.0);
            assert!((q - *t).length() < 0.1, "{q} vs {t}");
        }
    }
}
