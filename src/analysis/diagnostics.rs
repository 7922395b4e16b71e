//! The analysis's warnings and numerical errors, and the causes they name: overflows
//! (the mean, the filter's covariance, the maxima (1.5)), singular innovation covariances,
//! the update's cancellation (2.7), Euler's instability (§1.2), the bound's growth; r∞ (doubling).

use crate::analysis::inputs::Inputs;
use crate::analysis::result::{Final, StepSelection};
use crate::error::Error;
use crate::model::compile::CompiledModel;
use crate::numerics::riccati;

/// How the warnings about the bound set alone begin (its overflow, its growth far
/// beyond the covariance's interval): they say nothing of the covariance set's
/// criteria, so a synthesis targeting that set leaves them out ([`bound_set_only`]).
pub(super) const BOUND_WARNING: &str = "the bound (modulus procedure)";

/// The warning concerns the bound set's criteria only.
pub fn bound_set_only(warning: &str) -> bool {
    warning.starts_with(BOUND_WARNING)
}

/// The warning for a step selection that stopped at its cap, with the last measured
/// difference and the D it would take: Euler's error halves when D doubles, so the
/// difference falls as 1/D.
pub(super) fn unconverged(s: &StepSelection) -> Option<String> {
    if s.converged {
        return None;
    }
    let measured: Vec<(u64, f64)> = s
        .history
        .iter()
        .filter_map(|h| h.difference.map(|d| (h.steps, d)))
        .collect();
    let chosen = s.history.last().map_or(s.max_steps, |h| h.steps);
    let limit = crate::model::limits::MAX_STEPS;
    let (measured, advice) = match measured.as_slice() {
        [.., (_, before), (d, diff)] if diff >= before => (
            format!(
                "; the difference did not fall as D doubled ({before:.2e}, then {diff:.2e} at D = {d}), so Euler's 1/D convergence has not begun and no D can be predicted"
            ),
            "raise time.auto.tolerance, or check the model's time scales against Δt",
        ),
        [.., (d, diff)] => {
            let needed = *d as f64 * diff / s.tolerance;
            let advice = if needed > limit as f64 {
                "beyond the limit of 1e8 steps: raise time.auto.tolerance"
            } else {
                "raise time.auto.max_steps or time.auto.tolerance"
            };
            (
                format!(
                    "; the difference was {diff:.2e} at D = {d}, so about D = {needed:.1e} would reach it"
                ),
                advice,
            )
        }
        [] => (
            String::new(),
            "raise time.auto.max_steps or time.auto.tolerance",
        ),
    };
    Some(format!(
        "time.steps \"auto\" did not reach its tolerance {:e} within time.auto.max_steps = {}: the result uses D = {chosen}{measured}; {advice}",
        s.tolerance, s.max_steps
    ))
}

/// The warning for maxima that overflowed f64 (reported as null): ẏ_B where a y_k
/// + u overflows with a finite y_k, z_B = Σ|C_ji| y_B,i (1.5) with large entries of C.
pub(super) fn overflowed_maxima(
    m: &CompiledModel,
    ydot_max: &[f64],
    z_max: &[f64],
) -> Option<String> {
    let names = |v: &[f64], of: &[String]| -> Vec<String> {
        v.iter()
            .zip(of)
            .filter(|(x, _)| !x.is_finite())
            .map(|(_, s)| format!("\"{s}\""))
            .collect()
    };
    let mut parts = Vec::new();
    let ydot = names(ydot_max, &m.states);
    if !ydot.is_empty() {
        parts.push(format!("ẏ_B of {}", ydot.join(", ")));
    }
    let z = names(z_max, &m.measurements);
    if !z.is_empty() {
        parts.push(format!("z_B of {}", z.join(", ")));
    }
    (!parts.is_empty()).then(|| {
        format!(
            "{} overflowed f64 (above 1.8e308) and {} null: the model's a·y + u or C·y_B is too large for double precision; rescale the states or the measurements",
            parts.join("; "),
            if ydot.len() + z.len() == 1 { "is" } else { "are" }
        )
    })
}

/// A filtered variance R_ii at or below this fraction of the predicted r_ii is
/// reported, unless a unit row measures state i in an exact update (`riccati`'s
/// `update_exact`, which keeps R_ii's relative precision). Otherwise the update (2.7)
/// forms R_ii from terms of size r_ii, so its rounding error is ≈ 1e-16 r_ii — at
/// R_ii = 1e-12 r_ii, 1e-4 of R_ii. Such steps come from a state determined only
/// through others (the tracker's velocity from two positions, with a diffuse start)
/// and make the covariance set's ZX = σ_Z/σ_X and YX ratios of rounding errors, which
/// can dominate their averages.
pub const ROUNDING_LEVEL: f64 = 1e-12;

/// The spread of Rv's pivots above which a warning says how many digits whitening the
/// measurements loses (8: an audit measured χ 1e-7 off at 8.7e7, 2× off at 7.6e18).
pub(super) const ILL_CONDITIONED_RV: f64 = 1e8;

/// How many times the covariance's confidence half-width λσ the bound may be at t_end
/// before a warning says the bound set describes |A|'s growth rather than the filter.
/// Bounds that follow the filter stay within ≈ 10³ of it (the seed's example: 365 for
/// η, 332 for χ); the modulus procedure on oscillatory or feedback dynamics grows
/// geometrically past 10⁶ (the textbook tracker: χ at 7.1·10³² times λσ after 100 s).
pub const BOUND_GROWTH_WARN: f64 = 1e6;

/// The warning for a bound (η or χ at t_end) above [`BOUND_GROWTH_WARN`] times the
/// covariance's λσ (open-loop for η, potential for χ), naming the worst state.
///
/// A confidence below ≈ 0.68 (λ < 1) compares with σ itself: the bound does not shrink
/// with λ, so λσ would make any bound look grown (P = 1e-7: λ = 1.3e-7, a scalar
/// a = 0 model's χ "2.1e7 times λσ").
pub(super) fn bound_growth(states: &[String], f: &Final, lambda: f64) -> Option<String> {
    let (scale, sigma) = if lambda >= 1.0 {
        (lambda, "λσ")
    } else {
        (1.0, "σ")
    };
    let worst = |bound: &[f64], sko: &[f64]| {
        (0..states.len())
            .filter(|&i| scale * sko[i] > 0.0 && bound[i].is_finite())
            .map(|i| (bound[i] / (scale * sko[i]), i))
            .fold(None, |w: Option<(f64, usize)>, x| match w {
                Some(w) if w.0 >= x.0 => Some(w),
                _ => Some(x),
            })
    };
    let mut parts = Vec::new();
    for (name, bound, sko, what) in [
        ("χ", &f.chi, &f.potential_sko, "the potential"),
        ("η", &f.eta, &f.open_loop_sko, "the open-loop"),
    ] {
        if let Some((ratio, i)) = worst(bound, sko).filter(|w| w.0 > BOUND_GROWTH_WARN) {
            // (A tiny σ can make the ratio pass f64's range.)
            let ratio = if ratio.is_finite() {
                format!("{ratio:.1e}")
            } else {
                "more than 1.8e308".to_string()
            };
            parts.push(format!(
                "{name} of \"{}\" is {ratio} times {what} {sigma}",
                states[i]
            ));
        }
    }
    (!parts.is_empty()).then(|| format!(
        "{BOUND_WARNING} grew far beyond the covariance's confidence interval by t_end ({}): |A| and |I − pC| taken element-wise grow where A and I − pC do not (oscillatory or feedback dynamics), so the bound set's criteria describe that growth rather than the filter; see the covariance set",
        parts.join("; ")
    ))
}

/// The error for a quantity that left f64's range at step k (t).
pub(crate) fn overflowed(what: &str, path: &str, k: u64, t: f64) -> Error {
    Error::Numerical {
        step: k,
        t,
        path: path.to_string(),
        message: format!(
            "{what} overflowed: the model diverges faster than f64 can follow on this interval"
        ),
    }
}

/// The error where the mean overflows and Euler's step is not the cause: a growing A
/// (the model diverges on this interval), else the scale of the states themselves —
/// y0 or u·Δt too large for f64 — named at the larger of the two for the first state
/// that overflowed. (`a = 0, u = -1e308` was blamed on `system.a`.)
#[cold]
#[inline(never)]
pub(super) fn mean_overflowed(
    inp: &Inputs,
    y0: &[f64],
    y: &[f64],
    states: &[String],
    k: u64,
    t: f64,
) -> Error {
    let n = inp.n;
    if growth_per_step(&inp.dense_a(), n) > 1.0 {
        return overflowed("the mean state", "system.a", k, t);
    }
    let i = y[..n].iter().position(|v| !v.is_finite()).unwrap_or(0);
    let (path, what) = if inp.u_dt[i].abs() * k as f64 >= y0[i].abs() {
        (format!("system.u[{i}]"), "its input u")
    } else {
        (format!("system.y0[{i}]"), "its initial mean y0")
    };
    Error::Numerical {
        step: k,
        t,
        path,
        message: format!(
            "the mean of \"{}\" overflowed f64 (above 1.8e308) where A does not grow: {what} is too large for double precision over the interval; rescale the state (its units)",
            states[i]
        ),
    }
}

/// r∞ of a time-invariant model by doubling ([`riccati::dare_doubling`]), with the
/// warning where it fails. Out of line: inlined into the step loop's function, its code
/// changed how LLVM laid out the loop (+11 % a step of a constant P = 10 model).
#[inline(never)]
pub(super) fn stationary(
    inp: &Inputs,
    n: usize,
    nm: usize,
    steps: u64,
    warnings: &mut Vec<String>,
) -> Option<Vec<f64>> {
    let found = riccati::dare_doubling(
        &inp.dense_a(),
        &inp.c_nz,
        &inp.big_b,
        &inp.rv,
        n,
        nm,
        riccati::doublings_for(steps),
    );
    // Not settled within the doublings worth taking: the recursion reaches no steady
    // state in D steps either (`doublings_for`), which the result says by itself.
    if let Err(riccati::NoStationary::Failed) = found {
        // The doubling needs Rv⁻¹: a noise-free measurement, or fewer noise sources
        // than measurements, is no reason to suspect the model.
        let rv = nalgebra::DMatrix::from_row_slice(nm, nm, &inp.rv);
        let why = if nm > 0 && rv.cholesky().is_none() {
            "is not computed where the measurement-noise covariance Γ V Γᵀ is singular (its doubling algorithm needs the inverse)"
        } else {
            "could not be computed (no stabilising solution?)"
        };
        warnings.push(format!(
            "the stationary Riccati solution {why}: the full recursion was run and no steady state is reported"
        ));
    }
    found.ok()
}

/// The error where the mean overflows although the model is stable: Euler's step
/// y + (a y + u)Δt is unstable at this Δt. A mode λ of a (μ = 1 + λΔt of A) decays when Re λ < 0, but
/// the step multiplies it by |μ| > 1 unless Δt < −2 Re λ / |λ|² (METHOD §1.2's
/// discretisation as the seed has it). The hint names the worst such mode and the
/// steps that would make every one stable.
pub(super) fn euler_unstable(
    a: &[f64],
    n: usize,
    dt: f64,
    span: f64,
    steps: u64,
) -> Option<String> {
    let mu = eigenvalues(a, n)?;
    let mut worst: Option<(f64, f64)> = None; // (Δt_max, Re λ)
    for m in mu.iter() {
        let (re, im) = ((m.re - 1.0) / dt, m.im / dt);
        if re < 0.0 && m.re.hypot(m.im) > 1.0 {
            let dt_max = -2.0 * re / (re * re + im * im);
            if worst.is_none_or(|(d, _)| dt_max < d) {
                worst = Some((dt_max, re));
            }
        }
    }
    let (dt_max, re) = worst?;
    let needed = (span / dt_max).floor() as u64 + 1;
    Some(format!(
        "the mean state overflowed, though the model is stable here: Euler's step y + (a y + u)Δt is not. A mode of a with real part {} decays, but each step of Δt = {} multiplies it by more than 1 (Euler is stable for it only with Δt < {}); give time.steps ≥ {needed} (now {steps}), or \"auto\"",
        crate::text::num(re),
        crate::text::num(dt),
        crate::text::num(dt_max)
    ))
}

/// The error for an innovation covariance that is not positive definite: an overflow
/// where the filter's covariance left f64's range (huge initial SKOs), else singular.
/// (Noise covariances that leave f64's range are refused where `Inputs::at` computes
/// them, before the step.)
///
/// The overflow names its likely cause from A = I + aΔt (`a`, dense n × n) at step k:
/// an entry so large that one step multiplies the covariance beyond reason, else a
/// growing mode (|μ| > 1) that the measurements do not hold, else the input levels.
/// (Cold and out of line, as every error path of the step loop: inlined, their code
/// changed how LLVM laid out the loop, +17 % instructions in Table 1.)
#[cold]
#[inline(never)]
pub(super) fn not_positive(
    big_r: &[f64],
    r_pred: &[f64],
    inp: &Inputs,
    k: u64,
    t: f64,
    m: &CompiledModel,
    available: &[usize],
) -> Error {
    let states = &m.states;
    if all_finite(big_r) {
        return singular_at(r_pred, inp, m, available, k, t).unwrap_or_else(|| singular(k, t));
    }
    let otherwise = "the noise levels or the initial SKOs are too large to square";
    // The prediction A R Aᵀ + B is where a variance first leaves f64's range.
    let n = inp.n;
    let from = if all_finite(r_pred) { big_r } else { r_pred };
    let diagonal: Vec<f64> = (0..n).map(|i| from[i * n + i]).collect();
    covariance_overflowed(inp, k, t, &diagonal, states, otherwise)
}

/// The error for the filter's covariance leaving f64's range at step k: the cause A
/// shows ([`covariance_growth`]), else `otherwise`.
#[cold]
#[inline(never)]
pub(super) fn covariance_overflowed(
    inp: &Inputs,
    k: u64,
    t: f64,
    diagonal: &[f64],
    states: &[String],
    otherwise: &str,
) -> Error {
    let (path, cause) = covariance_growth(&inp.dense_a(), inp.n, inp.dt, k)
        .unwrap_or_else(|| ("system".to_string(), otherwise.to_string()));
    let gone: Vec<&str> = states
        .iter()
        .zip(diagonal)
        .filter(|(_, v)| !v.is_finite())
        .map(|(s, _)| s.as_str())
        .collect();
    let what = match gone.as_slice() {
        [] => "the filter's covariance overflowed f64 (a variance above 1.8e308)".to_string(),
        [one] => format!("the filter's variance of \"{one}\" overflowed f64 (above 1.8e308)"),
        many => format!(
            "the filter's variances of {} overflowed f64 (above 1.8e308)",
            quoted_names(many)
        ),
    };
    Error::Numerical {
        step: k,
        t,
        path,
        message: format!("{what}: {cause}"),
    }
}

/// `"x1"`, `"x1" and "x2"`, `"x1", "x2", "x3" and 4 more`: names for a message.
fn quoted_names(names: &[&str]) -> String {
    const SHOWN: usize = 3;
    let q = |s: &&str| format!("\"{s}\"");
    match names {
        [] => String::new(),
        [one] => q(one),
        _ if names.len() <= SHOWN => {
            let (last, rest) = names.split_last().expect("two or more");
            format!(
                "{} and {}",
                rest.iter().map(q).collect::<Vec<_>>().join(", "),
                q(last)
            )
        }
        _ => format!(
            "{} and {} more",
            names[..SHOWN].iter().map(q).collect::<Vec<_>>().join(", "),
            names.len() - SHOWN
        ),
    }
}

/// Most iterations of the eigenvalue algorithm per state. nalgebra's Schur
/// decomposition does not converge on some matrices (dimforge/nalgebra#611: the
/// 10 × 10 `a_ij = 10i + j + 1`, rank 2, looped for ever, and no cancel or time limit
/// can stop it inside); it converges in a few iterations per eigenvalue where it does.
const EIGEN_ITERATIONS_PER_STATE: usize = 10;

/// The eigenvalues of A (dense n × n), or `None` where the algorithm does not converge
/// within [`EIGEN_ITERATIONS_PER_STATE`]` · max(n, 10)` iterations (each O(n²): at
/// N = 200 a matrix it does not converge on took 3.7 s with 100 per state, 0.4 s now;
/// the callers have answers without eigenvalues).
fn eigenvalues(a: &[f64], n: usize) -> Option<Vec<nalgebra::Complex<f64>>> {
    let m = nalgebra::DMatrix::from_row_slice(n, n, a);
    let schur =
        nalgebra::linalg::Schur::try_new(m, f64::EPSILON, EIGEN_ITERATIONS_PER_STATE * n.max(10))?;
    Some(schur.complex_eigenvalues().iter().copied().collect())
}

/// The spectral radius of A (dense n × n): the most a mode grows in one step; where
/// the eigenvalues are not found, [`gelfand_radius`].
pub(super) fn growth_per_step(a: &[f64], n: usize) -> f64 {
    match eigenvalues(a, n) {
        Some(mu) => mu.iter().map(|m| m.re.hypot(m.im)).fold(0.0, f64::max),
        None => gelfand_radius(a, n),
    }
}

/// The spectral radius of A (dense n × n) by Gelfand's formula ρ = lim ‖A^k‖^(1/k),
/// with k = 2⁴⁰: A squared 40 times, each power scaled to norm 1 and the scales summed
/// as logs, so that nothing overflows. ‖A^k‖^(1/k) exceeds ρ by a relative
/// ≈ (ln κ + (m − 1) ln k) / k, κ the condition of A's eigenvector basis and m its
/// largest Jordan block: below 1e-8 for any n ≤ 200 and κ f64 can hold.
fn gelfand_radius(a: &[f64], n: usize) -> f64 {
    let mut p = nalgebra::DMatrix::from_row_slice(n, n, a);
    let mut log_norm = 0.0; // ln ‖A^(2^j)‖
    let mut rate = 0.0;
    for j in 0..=40 {
        let s = p.norm();
        if !(s > 0.0 && s.is_finite()) {
            return if s == 0.0 { 0.0 } else { f64::INFINITY };
        }
        log_norm += s.ln();
        rate = (log_norm / 2f64.powi(j)).exp();
        p /= s;
        p = &p * &p;
        log_norm *= 2.0;
    }
    rate
}

/// Why the filter's covariance A R Aᵀ + B left f64's range, when A says so:
/// (path, cause). `HUGE` bounds |A_ij| of any model f64 can follow for many steps.
fn covariance_growth(a: &[f64], n: usize, dt: f64, k: u64) -> Option<(String, String)> {
    const HUGE: f64 = 1e10;
    // (Four significant digits: these are magnitudes, not values to copy.)
    let num = |x: f64| crate::text::num(format!("{x:.3e}").parse().unwrap_or(x));
    let (big, at) = a
        .iter()
        .enumerate()
        .map(|(i, x)| (x.abs(), i))
        .fold((0.0, 0), |m, x| if x.0 > m.0 { x } else { m });
    if big >= HUGE {
        let (i, j) = (at / n, at % n);
        let entry = (a[at] - if i == j { 1.0 } else { 0.0 }) / dt;
        return Some((
            format!("system.a[{i}][{j}]"),
            format!(
                "A = I + aΔt has an entry of {} here (a = {} there, Δt = {}), and each step multiplies the covariance by about its square: rescale the states or the time unit",
                num(a[at]),
                num(entry),
                num(dt)
            ),
        ));
    }
    if k < 2 {
        return None;
    }
    let grow = growth_per_step(a, n);
    (grow > 1.0).then(|| {
        (
            "system.a".to_string(),
            format!(
                "a mode of A = I + aΔt grows (by {} a step, rate {} per unit of t) and the measurements do not hold it: C does not see it, or sees it through too much noise; measure that mode, or shorten the interval",
                num(grow),
                num(grow.ln() / dt)
            ),
        )
    })
}

/// An innovation covariance ≤ 0 at step k after the update had cancelled a variance
/// to rounding level from step j on: the covariance's precision, not the model, gave
/// out (an SKO far above the measurement's: `eta0 = 1e150` against `psi = 1`).
pub(super) fn lost_precision(k: u64, t: f64, j: u64, t_j: f64, state: &str) -> Error {
    Error::Numerical {
        step: k,
        t,
        path: "system".into(),
        message: format!(
            "the filter's covariance lost its precision: from step {j} (t = {}) the update cancelled the variance of \"{state}\" to 1e-12 of its predicted variance or less (the small difference of large terms), and here the innovation covariance q = C r Cᵀ + Γ V Γᵀ came out ≤ 0 by rounding; an initial SKO (eta0) or a model-error SKO (phi) many orders of magnitude above the measurement's (psi) does this: bring them nearer, or rescale the units",
            crate::text::num(t_j)
        ),
    }
}

/// A singular innovation covariance at step k (time t), with its possible causes.
/// The singular innovation covariance q = C r Cᵀ + Γ V Γᵀ (over the `available`
/// measurements, r the prediction) named at the measurement where it fails: one whose
/// q is 0 (no noise, and what it measures known exactly), else the first that adds
/// nothing to those before it (q's Cholesky pivot ≤ 1e-14 of its diagonal: its
/// innovation is a combination of theirs). None if q turns out definite here.
fn singular_at(
    r_pred: &[f64],
    inp: &Inputs,
    m: &CompiledModel,
    available: &[usize],
    k: u64,
    t: f64,
) -> Option<Error> {
    let (n, nm) = (inp.n, m.measurements.len());
    let mut idx = available.to_vec();
    idx.sort_unstable();
    let nk = idx.len();
    let row = |j: usize| &m.c[j * n..j * n + n];
    let mut q = vec![0.0; nk * nk];
    for (a, &i) in idx.iter().enumerate() {
        for (b, &j) in idx.iter().enumerate() {
            let crc: f64 = (0..n)
                .map(|x| row(i)[x] * (0..n).map(|y| r_pred[x * n + y] * row(j)[y]).sum::<f64>())
                .sum();
            q[a * nk + b] = crc + inp.rv[i * nm + j];
        }
    }
    let culprit = |j: usize, message: String| Error::Numerical {
        step: k,
        t,
        path: format!("measurement.c[{j}]"),
        message,
    };
    if let Some(a) = (0..nk).find(|&a| !q[a * nk + a].is_finite()) {
        let j = idx[a];
        return Some(culprit(
            j,
            format!(
                "the innovation variance of measurement \"{}\" (C r Cᵀ + Γ V Γᵀ) overflowed f64 (above 1.8e308): its row of c times the predicted SKOs of the states it measures is too large to square; rescale the states or the measurement (their units)",
                m.measurements[j]
            ),
        ));
    }
    if let Some(a) = (0..nk).find(|&a| q[a * nk + a] <= 0.0) {
        let j = idx[a];
        return Some(culprit(
            j,
            format!(
                "the innovation covariance q = C r Cᵀ + Γ V Γᵀ is singular: measurement \"{}\" has no error (its Γ V Γᵀ is 0) and what it measures is known exactly (its C r Cᵀ is 0: the states it measures have no variance yet, nor process noise); give it noise (psi or V), or those states an initial SKO (eta0)",
                m.measurements[j]
            ),
        ));
    }
    // Cholesky, row by row: the pivot of row a is what measurement a adds. (Not
    // linalg::cholesky, which fails only at a pivot ≤ 0: this q, formed again, can
    // keep a rounding-level pivot where the step's factorisation failed.)
    let mut l = vec![0.0; nk * nk];
    for a in 0..nk {
        for b in 0..=a {
            let dot: f64 = (0..b).map(|x| l[a * nk + x] * l[b * nk + x]).sum();
            let v = q[a * nk + b] - dot;
            if a == b {
                if v <= 1e-14 * q[a * nk + a] {
                    let j = idx[a];
                    let before: Vec<&str> = idx[..a]
                        .iter()
                        .map(|&i| m.measurements[i].as_str())
                        .collect();
                    return Some(culprit(
                        j,
                        format!(
                            "the innovation covariance q = C r Cᵀ + Γ V Γᵀ is singular: measurement \"{}\" adds nothing to {} (its error and what it measures are a combination of theirs, with no error of its own); give it noise of its own (psi or V), or drop it",
                            m.measurements[j],
                            quoted_names(&before)
                        ),
                    ));
                }
                l[a * nk + a] = v.sqrt();
            } else {
                l[a * nk + b] = v / l[b * nk + b];
            }
        }
    }
    None
}

pub(crate) fn singular(k: u64, t: f64) -> Error {
    Error::Numerical {
        step: k,
        t,
        path: "measurement".into(),
        message: "the innovation covariance q = C r Cᵀ + Γ V Γᵀ is singular (not positive definite): a measurement has no error (Γ V Γᵀ is 0 in its direction) and what it measures is already known exactly (C r Cᵀ is 0 there: C is 0, or the state's variance is); or the terms are below f64's range (entries of c, gamma or psi near 1e-154 or below, whose squares underflow to 0); give non-zero psi/V or eta0, or rescale the units".into(),
    }
}

/// Whether every entry is finite (no early exit, so the loop vectorises).
#[inline(always)]
pub(super) fn all_finite(v: &[f64]) -> bool {
    v.iter().fold(true, |ok, x| ok & x.is_finite())
}

#[cfg(test)]
mod tests {
    /// Gelfand's formula, the fallback where the eigenvalue algorithm does not
    /// converge, against the eigenvalues on random matrices (growing, decaying,
    /// rotating), a defective one (a Jordan block) and the zero matrix.
    #[test]
    fn gelfand_radius_agrees_with_the_eigenvalues() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for n in [1, 2, 3, 5, 10, 30] {
            for scale in [0.1, 1.0, 1e3] {
                let a: Vec<f64> = (0..n * n)
                    .map(|_| scale * rng.random_range(-1.0..1.0))
                    .collect();
                let rho = super::eigenvalues(&a, n).expect("converges here");
                let rho = rho.iter().map(|m| m.re.hypot(m.im)).fold(0.0, f64::max);
                let g = super::gelfand_radius(&a, n);
                assert!((g / rho - 1.0).abs() < 1e-9, "n = {n}: {g} against {rho}");
            }
        }
        // A 4 × 4 Jordan block of 0.9: ρ = 0.9, ‖A^k‖ grows like k³ 0.9^k first.
        let mut j = vec![0.0; 16];
        for i in 0..4 {
            j[i * 4 + i] = 0.9;
            if i < 3 {
                j[i * 4 + i + 1] = 1.0;
            }
        }
        assert!((super::gelfand_radius(&j, 4) / 0.9 - 1.0).abs() < 1e-9);
        assert_eq!(super::gelfand_radius(&[0.0; 9], 3), 0.0);
    }

    /// nalgebra's Schur decomposition loops for ever on this matrix (a_ij = 10i + j + 1,
    /// rank 2; dimforge/nalgebra#611) without a bound on its iterations; bounded, the
    /// spectral radius still comes out, by one way or the other.
    #[test]
    fn the_spectral_radius_of_a_matrix_schur_loops_on_terminates() {
        let n = 10;
        let a: Vec<f64> = (0..n * n)
            .map(|k| (10 * (k / n) + k % n + 1) as f64)
            .collect();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || tx.send(super::growth_per_step(&a, n)).unwrap());
        let rho = rx
            .recv_timeout(std::time::Duration::from_secs(60))
            .expect("an answer within a minute");
        // Rank 2: the non-zero eigenvalues solve λ² − tr(A)λ + (the 2 × 2 minors' sum) = 0.
        let tr: f64 = (0..n).map(|i| (11 * i + 1) as f64).sum();
        let e2: f64 = (0..n)
            .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
            .map(|(i, j)| {
                let at = |r: usize, c: usize| (10 * r + c + 1) as f64;
                at(i, i) * at(j, j) - at(i, j) * at(j, i)
            })
            .sum();
        let want = (tr + (tr * tr - 4.0 * e2).sqrt()) / 2.0;
        assert!((rho / want - 1.0).abs() < 1e-9, "{rho} against {want}");
    }
    use super::quoted_names;

    #[test]
    fn names_are_listed_as_a_sentence_says_them() {
        assert_eq!(quoted_names(&["x"]), "\"x\"");
        assert_eq!(quoted_names(&["x", "v"]), "\"x\" and \"v\"");
        assert_eq!(quoted_names(&["a", "b", "c"]), "\"a\", \"b\" and \"c\"");
        assert_eq!(
            quoted_names(&["a", "b", "c", "d", "e"]),
            "\"a\", \"b\", \"c\" and 2 more"
        );
    }
}
