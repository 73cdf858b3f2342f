//! Run-time CPU dispatch for the simulator's hot loops.
//!
//! The crate is built for baseline x86-64 (SSE2), whose vectors have no 64-bit multiply, so the
//! SplitMix64 hashes behind every procedural texture and every pixel's sensor noise run one at a
//! time. Where the CPU has AVX-512 (F, DQ, VL, BW) the texture and tone code is compiled a second
//! time with those features, written so the compiler hashes eight lanes at once (`vpmullq`). Both
//! copies do the same IEEE operations in the same order (Rust never contracts a multiply and an
//! add into one FMA), so the images are bit-identical whichever copy runs; a test holds that.
//!
//! `RIGCAL_NO_WIDE=1` forces the baseline copy (for comparing the two on one machine).

use std::sync::OnceLock;

/// Whether the AVX-512 copies may run on this CPU (checked once per process).
pub fn available() -> bool {
    static AVAILABLE: OnceLock<bool> = OnceLock::new();
    *AVAILABLE.get_or_init(|| {
        let forced_off = std::env::var_os("RIGCAL_NO_WIDE").is_some_and(|v| v != "0");
        !forced_off && detect()
    })
}

#[cfg(target_arch = "x86_64")]
fn detect() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512dq")
        && std::arch::is_x86_feature_detected!("avx512vl")
        && std::arch::is_x86_feature_detected!("avx512bw")
}

#[cfg(not(target_arch = "x86_64"))]
fn detect() -> bool {
    false
}
