//! Which vector instruction sets the core's loops may use. The engine's step loop and
//! the expressions' sin and cos are compiled for several x86-64 feature sets, and the
//! widest the CPU runs is chosen at run time; a shell may lower that ceiling (`kea`
//! does for `KEA_NO_SIMD` and `KEA_NO_AVX512`), so that tests and benchmarks can compare
//! the builds. Every build gives the same bits. The core reads no environment: the
//! ceiling is what [`set_limit`] was given, once, before the first run.

use std::sync::atomic::{AtomicU8, Ordering};

/// The widest instruction set the core may use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Limit {
    /// Whatever the CPU runs (AVX-512 F + VL, else AVX2 + FMA, else the baseline).
    Widest,
    /// At most AVX2 + FMA.
    Avx2,
    /// The portable baseline (SSE2 on x86-64).
    Baseline,
}

impl Limit {
    /// The ceiling that two switches ask for: `baseline` the portable build, else
    /// `no_avx512` at most AVX2 (the switches `KEA_NO_SIMD` and `KEA_NO_AVX512`).
    pub fn from_switches(baseline: bool, no_avx512: bool) -> Limit {
        if baseline {
            Limit::Baseline
        } else if no_avx512 {
            Limit::Avx2
        } else {
            Limit::Widest
        }
    }
}

static LIMIT: AtomicU8 = AtomicU8::new(0);

/// Lower (or raise back) the ceiling for the runs that follow. The expressions' sin
/// and cos take it at their first use, so a shell sets it once, at its start.
pub fn set_limit(limit: Limit) {
    let code = match limit {
        Limit::Widest => 0,
        Limit::Avx2 => 1,
        Limit::Baseline => 2,
    };
    LIMIT.store(code, Ordering::Relaxed);
}

/// The ceiling set by [`set_limit`] ([`Limit::Widest`] unless lowered).
pub fn limit() -> Limit {
    match LIMIT.load(Ordering::Relaxed) {
        0 => Limit::Widest,
        1 => Limit::Avx2,
        _ => Limit::Baseline,
    }
}
