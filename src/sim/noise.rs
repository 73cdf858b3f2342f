//! Seeded hash noise for procedural textures: integer hashing, value noise and fBm.
//!
//! fBm comes in two forms with bit-identical results: [`fbm2`] walks the octaves one at a time
//! and skips those finer than the pixel's footprint; [`fbm2_wide`] evaluates eight octaves side
//! by side (every lane, faded or not) so that code compiled with wide vectors hashes them all
//! at once (`sim::wide`). [`fbm2_in`] picks one by a const flag.

/// A well-mixed 64-bit hash (SplitMix64 finaliser).
#[inline(always)]
pub fn hash64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// Uniform in [0, 1) from integer coordinates and a seed.
#[inline(always)]
pub fn hash3(x: i32, y: i32, z: i32, seed: u64) -> f32 {
    let h =
        hash64(seed ^ (x as u32 as u64) ^ ((y as u32 as u64) << 21) ^ ((z as u32 as u64) << 42));
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// `x as i32` (Rust's saturating cast: NaN → 0, out of range → the nearest bound) in a form
/// that vectorises: Rust's cast compiles to a scalar conversion and compare-and-move fix-ups per
/// value, this to one vector conversion and two selects.
#[inline(always)]
pub fn saturating_i32(x: f32) -> i32 {
    // The largest float below 2^31 (the next one up converts to i32::MAX by saturation).
    const BELOW_2_POW_31: f32 = 2_147_483_520.0;
    let v = if x.is_nan() {
        0.0
    } else {
        x.clamp(i32::MIN as f32, BELOW_2_POW_31)
    };
    // SAFETY: `v` is finite and within [i32::MIN, 2^31), so its truncation is an i32.
    #[allow(unsafe_code)]
    let r = unsafe { v.to_int_unchecked::<i32>() };
    if x >= 2_147_483_648.0 { i32::MAX } else { r }
}

/// `x.floor()` without a libm call (the baseline x86-64 target has no rounding instruction).
#[inline(always)]
pub fn floor(x: f32) -> f32 {
    if x.abs() >= 8_388_608.0 || x.is_nan() {
        return x; // already integral (or NaN)
    }
    let t = x as i32 as f32;
    if t > x { t - 1.0 } else { t }
}

/// [`floor`] where `WIDE` code (compiled with AVX-512, `sim::wide`) has a rounding
/// instruction: `x.floor() + 0.0` is one instruction and the same bits (adding +0 turns the -0
/// that `floor` never returns into +0).
#[inline(always)]
pub fn floor_in<const WIDE: bool>(x: f32) -> f32 {
    if WIDE { x.floor() + 0.0 } else { floor(x) }
}

/// `x.rem_euclid(period)` for a positive period, without libm's `fmod`: in [0, period).
#[inline(always)]
pub fn wrap(x: f32, period: f32) -> f32 {
    wrap_in::<false>(x, period)
}

/// [`wrap`] with [`floor_in`].
#[inline(always)]
pub fn wrap_in<const WIDE: bool>(x: f32, period: f32) -> f32 {
    let r = x - floor_in::<WIDE>(x / period) * period;
    // Rounding can land exactly on the period for tiny negative x.
    if r >= period { 0.0 } else { r }
}

#[inline(always)]
fn smooth(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

/// 2D value noise in [0, 1).
#[inline(always)]
pub fn value2(x: f32, y: f32, seed: u64) -> f32 {
    value2_in::<false>(x, y, seed)
}

/// [`value2`] with [`floor_in`].
#[inline(always)]
pub fn value2_in<const WIDE: bool>(x: f32, y: f32, seed: u64) -> f32 {
    let (xi, yi) = (floor_in::<WIDE>(x), floor_in::<WIDE>(y));
    let (fx, fy) = (smooth(x - xi), smooth(y - yi));
    let (xi, yi) = if WIDE {
        (saturating_i32(xi), saturating_i32(yi))
    } else {
        (xi as i32, yi as i32)
    };
    let a = hash3(xi, yi, 0, seed);
    let b = hash3(xi + 1, yi, 0, seed);
    let c = hash3(xi, yi + 1, 0, seed);
    let d = hash3(xi + 1, yi + 1, 0, seed);
    let top = a + (b - a) * fx;
    let bottom = c + (d - c) * fx;
    top + (bottom - top) * fy
}

/// Fractal sum of value noise; octaves finer than `footprint` (same units as x, y) fade out,
/// which band-limits the texture to the pixel size (anti-aliasing for free).
pub fn fbm2(x: f32, y: f32, base_scale: f32, octaves: u32, footprint: f32, seed: u64) -> f32 {
    let mut sum = 0.0;
    let mut norm = 0.0;
    let mut amp = 1.0;
    let mut scale = base_scale;
    // 1 / scale, halved with every octave (exactly the reciprocal: powers of two scale exactly).
    let mut feature = 1.0 / base_scale;
    let inv_footprint = 1.0 / (2.0 * footprint.max(1e-6));
    for o in 0..octaves {
        // Feature size of this octave is 1/scale; fade when it drops below two footprints.
        let fade = (feature * inv_footprint).clamp(0.0, 1.0);
        // A faded octave is its mean; so are all finer ones (cheap far away).
        let v = if fade > 0.0 {
            value2(x * scale, y * scale, seed.wrapping_add(o as u64 * 1013))
        } else {
            0.5
        };
        sum += amp * (fade * v + (1.0 - fade) * 0.5);
        norm += amp;
        amp *= 0.5;
        scale *= 2.0;
        feature *= 0.5;
    }
    sum / norm
}

/// The most octaves [`fbm2_wide`] evaluates at once.
pub const WIDE_OCTAVES: usize = 8;

/// [`fbm2`] with every octave evaluated, side by side in lanes, and faded ones then replaced
/// by their mean exactly as [`fbm2`] does: the same result, bit for bit, for up to
/// [`WIDE_OCTAVES`] octaves (more fall back to [`fbm2`]). Slower than [`fbm2`] one lane at a
/// time; faster where the lanes run as one vector.
#[inline(always)]
pub fn fbm2_wide(x: f32, y: f32, base_scale: f32, octaves: u32, footprint: f32, seed: u64) -> f32 {
    match octaves {
        0..=4 => fbm2_lanes::<4>(x, y, base_scale, octaves, footprint, seed),
        5..=8 => fbm2_lanes::<WIDE_OCTAVES>(x, y, base_scale, octaves, footprint, seed),
        _ => fbm2(x, y, base_scale, octaves, footprint, seed),
    }
}

/// [`fbm2_wide`] in `L` lanes, for at most `L` octaves: a [`NoiseBatch`] holding only its
/// octaves (the lanes past them are evaluated and unused).
#[inline(always)]
fn fbm2_lanes<const L: usize>(
    x: f32,
    y: f32,
    base_scale: f32,
    octaves: u32,
    footprint: f32,
    seed: u64,
) -> f32 {
    let mut batch = NoiseBatch::<L>::default();
    let lanes = batch.fbm2(x, y, base_scale, octaves as usize, footprint, seed);
    lanes.finish(&batch.eval())
}

/// Several value noises and fBm octaves gathered into `L` lanes and evaluated side by side:
/// one pass of wide hashing for all the noise a surface needs, instead of one per call. Each
/// lane is `value2(x, y, seed)`; an fBm takes one lane per octave and is finished by
/// [`FbmLanes::finish`], so every result is bit for bit that of [`value2`] and [`fbm2`].
pub struct NoiseBatch<const L: usize> {
    xs: [f32; L],
    ys: [f32; L],
    seeds: [u64; L],
    used: usize,
}

/// Where an fBm's octaves sit in a [`NoiseBatch`] and how much each is faded.
#[derive(Clone, Copy, Debug)]
pub struct FbmLanes {
    first: usize,
    octaves: usize,
    fade: [f32; WIDE_OCTAVES],
}

impl<const L: usize> Default for NoiseBatch<L> {
    fn default() -> Self {
        Self {
            xs: [0.0; L],
            ys: [0.0; L],
            seeds: [0; L],
            used: 0,
        }
    }
}

impl<const L: usize> NoiseBatch<L> {
    /// A lane for `value2(x, y, seed)`. Panics beyond `L` lanes (a programming error: the
    /// batches are laid out by hand).
    #[inline(always)]
    pub fn value2(&mut self, x: f32, y: f32, seed: u64) -> usize {
        let lane = self.used;
        (self.xs[lane], self.ys[lane], self.seeds[lane]) = (x, y, seed);
        self.used += 1;
        lane
    }

    /// Lanes for the octaves of `fbm2(x, y, base_scale, octaves, footprint, seed)` (at most
    /// [`WIDE_OCTAVES`]).
    #[inline(always)]
    pub fn fbm2(
        &mut self,
        x: f32,
        y: f32,
        base_scale: f32,
        octaves: usize,
        footprint: f32,
        seed: u64,
    ) -> FbmLanes {
        let first = self.used;
        let mut fade = [0.0f32; WIDE_OCTAVES];
        // The same per-octave scales and fades as `fbm2`.
        let (mut scale, mut feature) = (base_scale, 1.0 / base_scale);
        let inv_footprint = 1.0 / (2.0 * footprint.max(1e-6));
        for (o, fade) in fade.iter_mut().enumerate().take(octaves) {
            *fade = (feature * inv_footprint).clamp(0.0, 1.0);
            self.value2(x * scale, y * scale, seed.wrapping_add(o as u64 * 1013));
            scale *= 2.0;
            feature *= 0.5;
        }
        FbmLanes {
            first,
            octaves,
            fade,
        }
    }

    /// Every lane's value noise, computed side by side.
    #[inline(always)]
    pub fn eval(&self) -> [f32; L] {
        let mut v = [0.0f32; L];
        for i in 0..L {
            v[i] = value2_in::<true>(self.xs[i], self.ys[i], self.seeds[i]);
        }
        v
    }
}

impl FbmLanes {
    /// The fBm from its octaves' values: the same sum, in the same order, as [`fbm2`].
    #[inline(always)]
    pub fn finish(&self, values: &[f32]) -> f32 {
        let (mut sum, mut norm, mut amp) = (0.0, 0.0, 1.0);
        for o in 0..self.octaves {
            let fade = self.fade[o];
            let v = if fade > 0.0 {
                values[self.first + o]
            } else {
                0.5
            };
            sum += amp * (fade * v + (1.0 - fade) * 0.5);
            norm += amp;
            amp *= 0.5;
        }
        sum / norm
    }
}

/// [`fbm2_wide`] when `WIDE` (code compiled with wide vectors), [`fbm2`] otherwise.
#[inline(always)]
pub fn fbm2_in<const WIDE: bool>(
    x: f32,
    y: f32,
    base_scale: f32,
    octaves: u32,
    footprint: f32,
    seed: u64,
) -> f32 {
    if WIDE {
        fbm2_wide(x, y, base_scale, octaves, footprint, seed)
    } else {
        fbm2(x, y, base_scale, octaves, footprint, seed)
    }
}

/// A box-filtered square wave: fraction of [x - w/2, x + w/2] inside stripes of width `duty`
/// (in periods) repeating every 1. Anti-aliased stripes, dashes and grids.
#[inline(always)]
pub fn stripe(x: f32, duty: f32, w: f32) -> f32 {
    stripe_in::<false>(x, duty, w)
}

/// [`stripe`] with [`floor_in`].
#[inline(always)]
pub fn stripe_in<const WIDE: bool>(x: f32, duty: f32, w: f32) -> f32 {
    let integral = |t: f32| {
        let f = floor_in::<WIDE>(t);
        f * duty + (t - f).min(duty)
    };
    if w < 1e-6 {
        return if x - floor_in::<WIDE>(x) < duty {
            1.0
        } else {
            0.0
        };
    }
    ((integral(x + 0.5 * w) - integral(x - 0.5 * w)) / w).clamp(0.0, 1.0)
}

/// Box-filtered indicator of |x| < half_width with filter width w.
#[inline(always)]
pub fn band(x: f32, half_width: f32, w: f32) -> f32 {
    let w = w.max(1e-6);
    // Overlap of [x - w/2, x + w/2] with [-h, h], divided by w.
    let a = (x - 0.5 * w).max(-half_width);
    let b = (x + 0.5 * w).min(half_width);
    ((b - a) / w).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_bounded_and_seeded() {
        for i in 0..1000 {
            let v = value2(i as f32 * 0.37, i as f32 * 0.11, 3);
            assert!((0.0..1.0).contains(&v));
        }
        assert_eq!(value2(1.3, 2.7, 5), value2(1.3, 2.7, 5));
        assert_ne!(value2(1.3, 2.7, 5), value2(1.3, 2.7, 6));
    }

    #[test]
    fn wide_fbm_is_bit_identical_to_the_octave_walk() {
        let mut k = 0u64;
        for octaves in 1..=9 {
            for footprint in [1e-4f32, 0.003, 0.02, 0.1, 0.7, 5.0] {
                for base in [0.04f32, 0.3, 0.6, 2.0] {
                    for _ in 0..40 {
                        k += 1;
                        let x = (hash3(k as i32, 1, 0, 5) - 0.5) * 400.0;
                        let y = (hash3(k as i32, 2, 0, 5) - 0.5) * 400.0;
                        let a = fbm2(x, y, base, octaves, footprint, k);
                        let b = fbm2_wide(x, y, base, octaves, footprint, k);
                        assert_eq!(
                            a.to_bits(),
                            b.to_bits(),
                            "{x} {y} {base} {octaves} {footprint}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn a_noise_batch_gives_each_noise_bit_for_bit() {
        for k in 0..500u64 {
            let x = (hash3(k as i32, 1, 0, 9) - 0.5) * 300.0;
            let y = (hash3(k as i32, 2, 0, 9) - 0.5) * 300.0;
            let footprint = 0.001 + hash3(k as i32, 3, 0, 9) * 0.2;
            let mut batch = NoiseBatch::<16>::default();
            let a = batch.fbm2(x, y, 0.6, 6, footprint, k);
            let b = batch.value2(x * 25.0, y * 25.0, k ^ 16);
            let c = batch.fbm2(x, y, 0.05, 3, footprint, k ^ 12);
            let values = batch.eval();
            assert_eq!(
                a.finish(&values).to_bits(),
                fbm2(x, y, 0.6, 6, footprint, k).to_bits()
            );
            assert_eq!(
                values[b].to_bits(),
                value2(x * 25.0, y * 25.0, k ^ 16).to_bits()
            );
            assert_eq!(
                c.finish(&values).to_bits(),
                fbm2(x, y, 0.05, 3, footprint, k ^ 12).to_bits()
            );
        }
    }

    #[test]
    fn saturating_i32_matches_the_cast() {
        let mut xs = vec![
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -0.0,
            0.99,
            -0.99,
            2_147_483_520.0,
            2_147_483_648.0,
            -2_147_483_648.0,
            -2_147_483_904.0,
            3e9,
            -3e9,
            8_388_607.5,
            -8_388_608.5,
            f32::MAX,
            f32::MIN,
        ];
        xs.extend((0..2000).map(|k| (hash3(k, 0, 0, 1) - 0.5) * 1e4 * (k % 7) as f32));
        for x in xs {
            assert_eq!(saturating_i32(x), x as i32, "{x}");
        }
    }

    #[test]
    fn rounding_floor_is_bit_identical_to_the_fast_floor() {
        let mut xs = vec![
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -0.0,
            -1e-45,
            1e-45,
            -0.5,
            0.5,
        ];
        xs.extend([
            8_388_607.5f32,
            -8_388_607.5,
            8_388_608.0,
            3e9,
            -3e9,
            1e30,
            -1e30,
        ]);
        xs.extend((0..5000).map(|k| (hash3(k, 7, 0, 3) - 0.5) * 10f32.powi(k % 9 - 3)));
        for x in xs {
            assert_eq!(floor_in::<true>(x).to_bits(), floor(x).to_bits(), "{x}");
            assert_eq!(floor_in::<false>(x).to_bits(), floor(x).to_bits(), "{x}");
        }
    }

    #[test]
    fn fast_floor_matches_floor() {
        for x in [
            -3.5f32,
            -3.0,
            -0.2,
            -0.0,
            0.0,
            0.7,
            2.0,
            1e9,
            -1e9,
            8_388_607.5,
            -2.5e-8,
        ] {
            assert_eq!(floor(x), x.floor(), "{x}");
        }
        assert!(floor(f32::NAN).is_nan());
    }

    #[test]
    fn wrap_matches_rem_euclid() {
        for x in [
            -250.3f32, -11.0, -1e-7, 0.0, 0.4, 10.99, 11.0, 119.5, 3000.25,
        ] {
            for period in [1.0f32, 1.8, 2.4, 11.0, 120.0] {
                let (a, b) = (wrap(x, period), x.rem_euclid(period));
                assert!((0.0..period).contains(&a), "{x} {period} {a}");
                assert!(
                    (a - b).abs() < 1e-3 || (a - b).abs() > period - 1e-3,
                    "{x} {period}"
                );
            }
        }
    }

    #[test]
    fn filtered_stripes_average_to_duty() {
        assert!((stripe(0.3, 0.5, 10.0) - 0.5).abs() < 0.06);
        assert_eq!(stripe(0.25, 0.5, 0.0), 1.0);
        assert_eq!(stripe(0.75, 0.5, 0.0), 0.0);
        assert!((band(0.0, 1.0, 0.1) - 1.0).abs() < 1e-6);
        assert!(band(2.0, 1.0, 0.1) < 1e-6);
        assert!((band(1.0, 1.0, 0.2) - 0.5).abs() < 1e-6);
    }
}
