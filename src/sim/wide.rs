//! Run-time CPU dispatch for the hot loops of the simulator and of UniCal's field
//! ([`crate::unical::gemm`], [`crate::unical::hash_grid`]).
//!
//! The crate is built for baseline x86-64 (SSE2), which has no rounding instruction and no
//! 64-bit vector multiply, so the floors and SplitMix64 hashes behind every procedural texture
//! and every pixel's sensor noise run one at a time. The texture, sky and tone code is therefore
//! compiled three times: for the baseline, for AVX2 (with SSE4.1's rounding) and for AVX-512
//! (F, DQ, VL, BW: eight 64-bit hashes in one `vpmullq`), and `dispatch_wide!` runs the best
//! copy the CPU has. The wide copies take `WIDE = true`, which switches to forms written for
//! vectors (fBm octaves side by side, batched noise lanes, `floor` by rounding); all copies do
//! the same IEEE operations in the same order (Rust never contracts a multiply and an add into
//! an FMA), so the images are bit-identical whichever runs. Tests hold that.
//!
//! `RIGCAL_WIDE=baseline` or `RIGCAL_WIDE=avx2` caps the level (to compare them on one machine).

use std::sync::OnceLock;

/// The instruction sets a wide copy may use on this CPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    Baseline,
    Avx2,
    Avx512,
}

/// The best level this CPU has, capped by `RIGCAL_WIDE` (checked once per process).
pub fn level() -> Level {
    static LEVEL: OnceLock<Level> = OnceLock::new();
    *LEVEL.get_or_init(|| {
        let cap = match std::env::var("RIGCAL_WIDE").as_deref() {
            Ok("baseline") | Ok("off") => Level::Baseline,
            Ok("avx2") => Level::Avx2,
            _ => Level::Avx512,
        };
        detect().min(cap)
    })
}

#[cfg(target_arch = "x86_64")]
fn detect() -> Level {
    use std::arch::is_x86_feature_detected as has;
    if has!("avx512f") && has!("avx512dq") && has!("avx512vl") && has!("avx512bw") {
        Level::Avx512
    } else if has!("avx2") && has!("fma") && has!("sse4.1") {
        Level::Avx2
    } else {
        Level::Baseline
    }
}

#[cfg(not(target_arch = "x86_64"))]
fn detect() -> Level {
    Level::Baseline
}

/// `fn name(args) -> ret` running `inner::<WIDE>(args)` compiled for the best [`Level`] the CPU
/// has (`inner` must be `#[inline(always)]`, as must everything it calls that should be
/// compiled with the wider instruction sets). Type parameters, if any, follow `WIDE`:
/// `fn name<G: Bound>(args) -> ret => inner` runs `inner::<WIDE, G>(args)`.
macro_rules! dispatch_wide {
    ($(#[$attr:meta])* $vis:vis fn $name:ident $(<$($g:ident: $bound:path),+>)? ($($arg:ident: $ty:ty),* $(,)?) -> $ret:ty => $inner:ident) => {
        $(#[$attr])*
        $vis fn $name $(<$($g: $bound),+>)? ($($arg: $ty),*) -> $ret {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
                fn avx512 $(<$($g: $bound),+>)? ($($arg: $ty),*) -> $ret {
                    $inner::<true $($(, $g)+)?>($($arg),*)
                }
                #[target_feature(enable = "avx2,fma,sse4.1")]
                fn avx2 $(<$($g: $bound),+>)? ($($arg: $ty),*) -> $ret {
                    $inner::<true $($(, $g)+)?>($($arg),*)
                }
                match $crate::sim::wide::level() {
                    // SAFETY (both arms): `level` checked at run time that the CPU has every
                    // feature the copy is compiled with.
                    #[allow(unsafe_code)]
                    $crate::sim::wide::Level::Avx512 => return unsafe { avx512 $(::<$($g),+>)? ($($arg),*) },
                    #[allow(unsafe_code)]
                    $crate::sim::wide::Level::Avx2 => return unsafe { avx2 $(::<$($g),+>)? ($($arg),*) },
                    $crate::sim::wide::Level::Baseline => {}
                }
            }
            $inner::<false $($(, $g)+)?>($($arg),*)
        }
    };
}
pub(crate) use dispatch_wide;
