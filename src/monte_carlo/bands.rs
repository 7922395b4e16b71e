//! The χ² acceptance bands of the consistency checks (METHOD §1.8): quantiles by
//! bisection on the regularized lower incomplete gamma function, built on `libm` so
//! that wasm gives the native bits.

use crate::analysis::bisect_root;

/// Two-sided probability of the χ² acceptance bands.
pub const BAND_PROBABILITY: f64 = 0.95;

/// χ²_dof quantiles for the two-sided band, divided by `scale`.
pub fn chi2_band(dof: f64, scale: f64) -> [f64; 2] {
    if !(dof > 0.0) {
        return [f64::NAN, f64::NAN];
    }
    let lo = (1.0 - BAND_PROBABILITY) / 2.0;
    [
        chi2_quantile(dof, lo) / scale,
        chi2_quantile(dof, 1.0 - lo) / scale,
    ]
}

/// The χ²_dof quantile at probability p in (0, 1): the root of P(dof/2, x/2) = p,
/// bisected down to adjacent floats from a bracket fixed by dof. Built on `libm` (via
/// [`gamma_p`]) so that wasm gives the native bits: statrs' quantile iterates on the
/// standard library's functions, which differ between the C library and wasm, and its
/// bands differed around the 13th digit.
pub(crate) fn chi2_quantile(dof: f64, p: f64) -> f64 {
    let a = dof / 2.0;
    // Far beyond any quantile the band uses (mean dof, standard deviation √(2 dof)).
    let hi = dof + 40.0 * (2.0 * dof).sqrt() + 100.0;
    bisect_root(0.0, hi, |x| gamma_p(a, x / 2.0) - p)
}

/// The regularized lower incomplete gamma function P(a, x), a > 0, x ≥ 0: its power
/// series below x = a + 1, else 1 − Q by Lentz's continued fraction for Q (Numerical
/// Recipes §6.2), with `libm`'s exp, ln and lgamma.
fn gamma_p(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let front = libm::exp(-x + a * libm::log(x) - libm::lgamma(a));
    if x < a + 1.0 {
        let (mut term, mut sum, mut n) = (1.0 / a, 1.0 / a, a);
        // The terms fall once n > x; a few √a terms past that they are below ε.
        for _ in 0..100_000_000u32 {
            n += 1.0;
            term *= x / n;
            sum += term;
            if term.abs() < sum.abs() * f64::EPSILON {
                break;
            }
        }
        (sum * front).min(1.0)
    } else {
        const TINY: f64 = 1e-300;
        let mut b = x + 1.0 - a;
        let (mut c, mut d) = (1.0 / TINY, 1.0 / b);
        let mut h = d;
        for i in 1..100_000_000u32 {
            let an = -f64::from(i) * (f64::from(i) - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < TINY {
                d = TINY;
            }
            c = b + an / c;
            if c.abs() < TINY {
                c = TINY;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < f64::EPSILON {
                break;
            }
        }
        (1.0 - front * h).max(0.0)
    }
}
