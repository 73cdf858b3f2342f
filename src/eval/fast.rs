//! FAST-9 corner detection (Rosten & Drummond): a pixel is a corner when at least 9 contiguous
//! pixels of the 16 on a radius-3 circle are all brighter than it by `threshold`, or all darker.
//! Corners are kept when they are the strongest in their 3×3 neighbourhood.

const CIRCLE: [(i32, i32); 16] = [
    (0, -3),
    (1, -3),
    (2, -2),
    (3, -1),
    (3, 0),
    (3, 1),
    (2, 2),
    (1, 3),
    (0, 3),
    (-1, 3),
    (-2, 2),
    (-3, 1),
    (-3, 0),
    (-3, -1),
    (-2, -2),
    (-1, -3),
];

/// Corner pixels (x, y) with their score.
pub fn fast9(gray: &[u8], w: usize, h: usize, threshold: u8) -> Vec<(u32, u32, u32)> {
    let t = threshold as i32;
    let mut score = vec![0u32; w * h];
    for y in 3..h.saturating_sub(3) {
        for x in 3..w.saturating_sub(3) {
            let p = gray[y * w + x] as i32;
            let ring: [i32; 16] = CIRCLE.map(|(dx, dy)| {
                gray[(y as i32 + dy) as usize * w + (x as i32 + dx) as usize] as i32
            });
            // Quick rejection with the four compass points: a 9-arc covers at least two of them.
            let compass = [ring[0], ring[4], ring[8], ring[12]];
            let bright = compass.iter().filter(|&&v| v > p + t).count();
            let dark = compass.iter().filter(|&&v| v < p - t).count();
            if bright < 2 && dark < 2 {
                continue;
            }
            for sign in [1, -1] {
                let mut run = 0;
                let mut best = 0;
                for k in 0..32 {
                    let v = ring[k % 16];
                    if sign * (v - p) > t {
                        run += 1;
                        best = best.max(run);
                    } else {
                        run = 0;
                    }
                }
                if best >= 9 {
                    let s: i32 = ring.iter().map(|v| (sign * (v - p) - t).max(0)).sum();
                    score[y * w + x] = score[y * w + x].max(s as u32);
                }
            }
        }
    }
    let mut out = Vec::new();
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let s = score[y * w + x];
            if s == 0 {
                continue;
            }
            let is_max = (-1i32..=1).all(|dy| {
                (-1i32..=1).all(|dx| {
                    let o = score[(y as i32 + dy) as usize * w + (x as i32 + dx) as usize];
                    (dx == 0 && dy == 0) || o < s || (o == s && (dy, dx) > (0, 0))
                })
            });
            if is_max {
                out.push((x as u32, y as u32, s));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_corners_of_a_bright_square() {
        let (w, h) = (40, 40);
        let mut g = vec![20u8; w * h];
        for y in 10..30 {
            for x in 10..30 {
                g[y * w + x] = 220;
            }
        }
        let c = fast9(&g, w, h, 40);
        assert!(c.len() >= 4 && c.len() <= 8, "{c:?}");
        for (x, y) in [(10, 10), (29, 10), (10, 29), (29, 29)] {
            assert!(
                c.iter()
                    .any(|(cx, cy, _)| (*cx as i32 - x).abs() <= 1 && (*cy as i32 - y).abs() <= 1),
                "({x},{y}) {c:?}"
            );
        }
        assert!(fast9(&vec![100u8; w * h], w, h, 20).is_empty());
    }
}
