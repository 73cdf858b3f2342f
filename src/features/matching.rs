//! Descriptor matching: brute-force Hamming nearest neighbours kept when they are mutual, pass
//! Lowe's ratio test (best < ratio × second best) and are closer than an absolute bound.

use super::orb::{Keypoint, hamming};

/// Index pairs (in `a`, in `b`) of matched keypoints.
pub fn match_mutual(
    a: &[Keypoint],
    b: &[Keypoint],
    ratio: f32,
    max_bits: u32,
) -> Vec<(usize, usize)> {
    let nearest = |from: &[Keypoint], to: &[Keypoint]| -> Vec<Option<(usize, u32, u32)>> {
        from.iter()
            .map(|k| {
                let (mut best, mut second) = ((usize::MAX, u32::MAX), u32::MAX);
                for (j, m) in to.iter().enumerate() {
                    let d = hamming(&k.descriptor, &m.descriptor);
                    if d < best.1 {
                        second = best.1;
                        best = (j, d);
                    } else if d < second {
                        second = d;
                    }
                }
                (best.0 != usize::MAX).then_some((best.0, best.1, second))
            })
            .collect()
    };
    let ab = nearest(a, b);
    let ba = nearest(b, a);
    ab.iter()
        .enumerate()
        .filter_map(|(i, m)| {
            let (j, d1, d2) = (*m)?;
            let mutual = ba[j].is_some_and(|(back, _, _)| back == i);
            let distinct = (d1 as f32) < ratio * d2 as f32;
            (mutual && distinct && d1 <= max_bits).then_some((i, j))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(bits: [u64; 4]) -> Keypoint {
        Keypoint {
            x: 0.0,
            y: 0.0,
            angle_rad: 0.0,
            response: 0.0,
            descriptor: bits,
        }
    }

    #[test]
    fn only_mutual_distinct_close_pairs_match() {
        let a = vec![
            key([0, 0, 0, 0]),
            key([u64::MAX, 0, 0, 0]),
            key([0xFFFF, 0xFFFF, 0, 0]),
        ];
        let b = vec![
            key([u64::MAX, 1, 0, 0]),    // a1 (1 bit off)
            key([1, 0, 0, 0]),           // a0 (1 bit off)
            key([0xFFFF, 0xFFFF, 1, 0]), // a2, 1 bit off
            key([0xFFFF, 0xFFFF, 0, 1]), // a2 again, as close: a2's ratio test fails
        ];
        let m = match_mutual(&a, &b, 0.8, 64);
        assert_eq!(m, vec![(0, 1), (1, 0)]);
        assert!(match_mutual(&a, &b, 0.8, 0).is_empty(), "absolute bound");
        assert!(match_mutual(&a, &[], 0.8, 64).is_empty());
    }
}
