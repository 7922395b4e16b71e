//! sin and cos of [`LANES`] arguments at once, bit for bit as the `libm` crate's.
//!
//! A time-varying model entry such as `"-0.5 + 0.2*sin(t + 3)"` is evaluated
//! [`LANES`] steps at a time ([`crate::expr::block`]), and `libm::sin` lane by lane was
//! 9 % of the seed's Table 1 workload: a call per lane, each branching on its
//! argument's range. Here every lane goes through the same straight-line code — the
//! argument reduction of every range `libm` distinguishes below 2²⁰·π/2 and both
//! kernels are computed, and each lane selects what `libm` would have computed — so
//! the loop over the lanes is vectorised. The operations, their order and their
//! constants are `libm`'s (`sin.rs`, `cos.rs`, `rem_pio2.rs`, `k_sin.rs`, `k_cos.rs`,
//! from FreeBSD's msun), never fused, so each lane gives `libm`'s bits (tested against
//! it below). Lanes outside that range (|x| ≥ 2²⁰·π/2, inf, NaN) are passed to `libm`.

// The constants as libm (and msun before it) writes them, digit for digit.
#![allow(clippy::excessive_precision, clippy::approx_constant)]

use crate::expr::LANES;

const EPS: f64 = 2.2204460492503131e-16;
const TO_INT: f64 = 1.5 / EPS;
const INV_PIO2: f64 = 6.36619772367581382433e-01;
const PIO2_1: f64 = 1.57079632673412561417e+00;
const PIO2_1T: f64 = 6.07710050650619224932e-11;
const PIO2_2: f64 = 6.07710050630396597660e-11;
const PIO2_2T: f64 = 2.02226624879595063154e-21;
const PIO2_3: f64 = 2.02226624871116645580e-21;
const PIO2_3T: f64 = 8.47842766036889956997e-32;

const S1: f64 = -1.66666666666666324348e-01;
const S2: f64 = 8.33333333332248946124e-03;
const S3: f64 = -1.98412698298579493134e-04;
const S4: f64 = 2.75573137070700676789e-06;
const S5: f64 = -2.50507602534068634195e-08;
const S6: f64 = 1.58969099521155010221e-10;

const C1: f64 = 4.16666666666666019037e-02;
const C2: f64 = -1.38888888888741095749e-03;
const C3: f64 = 2.48015872894767294178e-05;
const C4: f64 = -2.75573143513906633035e-07;
const C5: f64 = 2.08757232129817482790e-09;
const C6: f64 = -1.13596475577881948265e-11;

/// The high word of |x| at and above which `libm` reduces with its large-argument
/// algorithm (|x| ≥ 2²⁰·π/2), or x is inf or NaN: such lanes are left to `libm`.
const LARGE: u64 = 0x413921fb;

/// `$lane` on every lane (one straight-line loop body, written out in the function
/// that uses it so that it is compiled for that function's target features); the
/// lanes it leaves (|x| ≥ 2²⁰·π/2, inf, NaN) then get `$exact`, libm's function.
macro_rules! lanes {
    ($x:expr, $lane:ident, $exact:path) => {{
        let x: [f64; LANES] = $x;
        let mut out = [0.0; LANES];
        let mut large = false;
        for l in 0..LANES {
            let (v, big) = $lane(x[l]);
            out[l] = v;
            large |= big;
        }
        if large {
            finish_large(&x, &mut out, $exact);
        }
        out
    }};
}

/// sin of each lane, equal to `libm::sin` bit for bit.
pub fn sin_lanes(x: [f64; LANES]) -> [f64; LANES] {
    #[cfg(target_arch = "x86_64")]
    match simd() {
        // SAFETY: the CPU has the build's features (`simd`).
        Simd::Avx512 => return unsafe { sin_avx512(x) },
        Simd::Avx2 => return unsafe { sin_avx2(x) },
        Simd::Baseline => {}
    }
    lanes!(x, sin_lane, libm::sin)
}

/// cos of each lane, equal to `libm::cos` bit for bit.
pub fn cos_lanes(x: [f64; LANES]) -> [f64; LANES] {
    #[cfg(target_arch = "x86_64")]
    match simd() {
        // SAFETY: the CPU has the build's features (`simd`).
        Simd::Avx512 => return unsafe { cos_avx512(x) },
        Simd::Avx2 => return unsafe { cos_avx2(x) },
        Simd::Baseline => {}
    }
    lanes!(x, cos_lane, libm::cos)
}

/// The x86-64 builds of the loops: AVX2's 4-lane 64-bit integer compares let LLVM
/// vectorise the selects (SSE2 has none), AVX-512 does 8 lanes at a time. The same
/// operations in every build (never fused), so the same bits.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug, PartialEq)]
enum Simd {
    Avx512,
    Avx2,
    Baseline,
}

/// The widest build this CPU runs (detected once, at the first use), within the
/// ceiling a shell set ([`crate::cpu::limit`]), as for the engine's loops.
#[cfg(target_arch = "x86_64")]
fn simd() -> Simd {
    use crate::cpu::Limit;
    static BUILD: std::sync::OnceLock<Simd> = std::sync::OnceLock::new();
    *BUILD.get_or_init(|| {
        let limit = crate::cpu::limit();
        if limit == Limit::Baseline || !std::arch::is_x86_feature_detected!("avx2") {
            Simd::Baseline
        } else if limit == Limit::Widest && std::arch::is_x86_feature_detected!("avx512f") {
            Simd::Avx512
        } else {
            Simd::Avx2
        }
    })
}

/// `$name`: the loop of `$lane` (libm's `$exact` for the lanes it leaves) compiled
/// with the target features `$features`.
macro_rules! x86_build {
    ($name:ident, $features:literal, $lane:ident, $exact:path) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $features)]
        fn $name(x: [f64; LANES]) -> [f64; LANES] {
            lanes!(x, $lane, $exact)
        }
    };
}

x86_build!(sin_avx2, "avx2", sin_lane, libm::sin);
x86_build!(cos_avx2, "avx2", cos_lane, libm::cos);
x86_build!(sin_avx512, "avx512f,avx2", sin_lane, libm::sin);
x86_build!(cos_avx512, "avx512f,avx2", cos_lane, libm::cos);

#[cold]
#[inline(never)]
fn finish_large(x: &[f64; LANES], out: &mut [f64; LANES], f: fn(f64) -> f64) {
    for (o, &x) in out.iter_mut().zip(x) {
        if high_word(x) >= LARGE {
            *o = f(x);
        }
    }
}

/// The high word of |x|, in 64 bits (the lanes' width: no narrowing in the loop).
#[inline(always)]
fn high_word(x: f64) -> u64 {
    (x.to_bits() >> 32) & 0x7fffffff
}

/// `libm`'s sin (sin.rs) without branches; (value, whether the lane is left to libm).
#[inline(always)]
fn sin_lane(x: f64) -> (f64, bool) {
    let ix = high_word(x);
    let (q, y0, y1) = rem_pio2(x, ix);
    let s = k_sin(y0, y1);
    let c = k_cos(y0, y1);
    // n mod 4 = 0, 1, 2, 3: s, c, −s, −c (as selects: LLVM does not vectorise a match)
    let v = if q & 1 == 0 { s } else { c };
    let reduced = if q & 2 == 0 { v } else { -v };
    // |x| ≤ π/4: x itself below 2⁻²⁶, else k_sin(x, 0, 0) (the iy = 0 form).
    let small = if ix < 0x3e500000 { x } else { k_sin0(x) };
    (if ix <= 0x3fe921fb { small } else { reduced }, ix >= LARGE)
}

/// `libm`'s cos (cos.rs) without branches; (value, whether the lane is left to libm).
#[inline(always)]
fn cos_lane(x: f64) -> (f64, bool) {
    let ix = high_word(x);
    let (q, y0, y1) = rem_pio2(x, ix);
    let s = k_sin(y0, y1);
    let c = k_cos(y0, y1);
    // n mod 4 = 0, 1, 2, 3: c, −s, −c, s
    let v = if q & 1 == 0 { c } else { s };
    let reduced = if (q + 1) & 2 == 0 { v } else { -v };
    // |x| ≤ π/4: 1 below 2⁻²⁷·√2, else k_cos(x, 0).
    let small = if ix < 0x3e46a09e { 1.0 } else { k_cos(x, 0.0) };
    (if ix <= 0x3fe921fb { small } else { reduced }, ix >= LARGE)
}

/// `libm`'s rem_pio2 for |x| < 2²⁰·π/2: x = n·π/2 + y0 + y1, here with n mod 4 (all
/// that sin and cos use). Both reductions libm uses there are computed — x − k·π/2
/// for k = 1…4 near those multiples, and the "medium" one with up to three rounds —
/// and the one libm takes is selected.
#[inline(always)]
fn rem_pio2(x: f64, ix: u64) -> (u64, f64, f64) {
    // medium: rint(x/(π/2)) — n is in tmp's low mantissa bits (its ulp is 1) — then
    // 1, 2 or 3 rounds by how much cancelled
    let tmp = x * INV_PIO2 + TO_INT;
    let f_n = tmp - TO_INT;
    let q_medium = tmp.to_bits() & 3;
    let ex = (ix >> 20) as i64;
    let exponent = |y: f64| ((y.to_bits() >> 52) & 0x7ff) as i64;
    let r1 = x - f_n * PIO2_1;
    let w1 = f_n * PIO2_1T;
    let y1_0 = r1 - w1;
    let w = f_n * PIO2_2;
    let r2 = r1 - w;
    let w2 = f_n * PIO2_2T - ((r1 - r2) - w);
    let y2_0 = r2 - w2;
    let w = f_n * PIO2_3;
    let r3 = r2 - w;
    let w3 = f_n * PIO2_3T - ((r2 - r3) - w);
    let y3_0 = r3 - w3;
    let (r, w, y0) = if ex - exponent(y1_0) <= 16 {
        (r1, w1, y1_0)
    } else if ex - exponent(y2_0) <= 49 {
        (r2, w2, y2_0)
    } else {
        (r3, w3, y3_0)
    };
    let medium = (q_medium, y0, (r - y0) - w);

    // |x| ≤ 9π/4 away from the multiples where that cancels: x ∓ k·π/2, k = 1…4
    // (libm's x - 3.0 * PIO2_1 … written with the signed multiple: x + c = x − (−c))
    let k: u64 = if ix <= 0x4002d97c {
        1
    } else if ix <= 0x400f6a7a {
        2
    } else if ix <= 0x4015fdbc {
        3
    } else {
        4
    };
    let negative = x.is_sign_negative();
    let sign = if negative { -1.0 } else { 1.0 };
    let hi = sign * (k as f64 * PIO2_1);
    let lo = sign * (k as f64 * PIO2_1T);
    let z = x - hi;
    let y0 = z - lo;
    let q_near = if negative { 4 - k } else { k } & 3;
    let near = (q_near, y0, (z - y0) - lo);
    let cancels =
        (ix <= 0x400f6a7a && (ix & 0xfffff) == 0x921fb) || ix == 0x4012d97c || ix == 0x401921fb;
    if ix <= 0x401c463b && !cancels {
        near
    } else {
        medium
    }
}

/// `libm`'s k_sin(x, y, 1).
#[inline(always)]
fn k_sin(x: f64, y: f64) -> f64 {
    let z = x * x;
    let w = z * z;
    let r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6);
    let v = z * x;
    x - ((z * (0.5 * y - v * r) - y) - v * S1)
}

/// `libm`'s k_sin(x, 0, 0).
#[inline(always)]
fn k_sin0(x: f64) -> f64 {
    let z = x * x;
    let w = z * z;
    let r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6);
    let v = z * x;
    x + v * (S1 + z * r)
}

/// `libm`'s k_cos(x, y).
#[inline(always)]
fn k_cos(x: f64, y: f64) -> f64 {
    let z = x * x;
    let w = z * z;
    let r = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    w + (((1.0 - w) - hz) + (z * r - x * y))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// Every build this CPU runs (the portable loop, which wasm also runs, and the
    /// x86-64 builds), against libm lane by lane.
    fn check(xs: &[f64]) {
        type Build = (
            &'static str,
            fn([f64; LANES]) -> [f64; LANES],
            fn([f64; LANES]) -> [f64; LANES],
        );
        let mut builds: Vec<Build> = vec![(
            "portable",
            |x| lanes!(x, sin_lane, libm::sin),
            |x| lanes!(x, cos_lane, libm::cos),
        )];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2.
                builds.push((
                    "avx2",
                    |x| unsafe { sin_avx2(x) },
                    |x| unsafe { cos_avx2(x) },
                ));
            }
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512 F (and AVX2).
                builds.push((
                    "avx512",
                    |x| unsafe { sin_avx512(x) },
                    |x| unsafe { cos_avx512(x) },
                ));
            }
        }
        builds.push(("dispatched", sin_lanes, cos_lanes));
        for (build, sin, cos) in builds {
            for chunk in xs.chunks(LANES) {
                let mut x = [0.0; LANES];
                x[..chunk.len()].copy_from_slice(chunk);
                let (s, c) = (sin(x), cos(x));
                for l in 0..LANES {
                    let (ws, wc) = (libm::sin(x[l]), libm::cos(x[l]));
                    assert_eq!(
                        s[l].to_bits(),
                        ws.to_bits(),
                        "{build}: sin({:e}) = {:e}, libm {ws:e}",
                        x[l],
                        s[l]
                    );
                    assert_eq!(
                        c[l].to_bits(),
                        wc.to_bits(),
                        "{build}: cos({:e}) = {:e}, libm {wc:e}",
                        x[l],
                        c[l]
                    );
                }
            }
        }
    }

    /// Every branch of libm's sin, cos and rem_pio2, at and around its thresholds
    /// (the high words, ± a few ulps of the boundary values and of k·π/2).
    #[test]
    fn equal_libm_at_every_branch_boundary() {
        let words = [
            0x00000000u32,
            0x00100000,
            0x3e46a09e,
            0x3e500000,
            0x3fe921fb,
            0x3ff921fb,
            0x4002d97c,
            0x400921fb,
            0x400f6a7a,
            0x4012d97c,
            0x4015fdbc,
            0x401921fb,
            0x401c463b,
            0x413921fb,
            0x7ff00000,
        ];
        let mut xs = Vec::new();
        for w in words {
            for lowbits in [0u32, 1, 0x54442d18, 0xffffffff] {
                let base = f64::from_bits(((w as u64) << 32) | lowbits as u64);
                for d in -3i64..=3 {
                    let x = f64::from_bits((base.to_bits() as i64 + d).max(0) as u64);
                    xs.extend([x, -x]);
                }
            }
        }
        for k in 1..=40 {
            let m = k as f64 * std::f64::consts::FRAC_PI_2;
            for d in -4i64..=4 {
                let x = f64::from_bits((m.to_bits() as i64 + d) as u64);
                xs.extend([x, -x]);
            }
        }
        xs.extend([
            0.0,
            -0.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            1e300,
            -1e22,
            5e-324,
        ]);
        check(&xs);
    }

    /// Random arguments over the ranges a model's time functions take, and over every
    /// exponent.
    #[test]
    fn equal_libm_on_random_arguments() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut xs = Vec::new();
        for _ in 0..200_000 {
            xs.push(rng.random_range(-20.0..20.0));
            xs.push(rng.random_range(-2e6..2e6));
            let e = rng.random_range(-40..25);
            xs.push(rng.random_range(-1.0..1.0) * 2f64.powi(e));
            // near a multiple of π/2, where the reduction cancels (2nd and 3rd rounds)
            let m = rng.random_range(1..700_000) as f64 * std::f64::consts::FRAC_PI_2;
            xs.push(m * (1.0 + rng.random_range(-1.0..1.0) * 2f64.powi(-rng.random_range(8..60))));
        }
        check(&xs);
    }
}
