//! The analysis's step loop (METHOD §1.2–§1.6): the mean (3.3), the Joseph-form Riccati
//! recursion (2.1)–(2.7), the open-loop covariance (§1.5), the bound (3.16)–(3.19) and a
//! step's criteria ratios (3.23)–(3.24); then the result assembled (3.20)–(3.26).

use super::Checkpoints;
use super::criteria::{
    C_BOUND_YX, C_BOUND_YZ, C_BOUND_ZX, C_COV_YX, C_COV_YZ, C_COV_ZX, criteria_set, laplace_lambda,
};
use super::diagnostics::{
    BOUND_WARNING, ILL_CONDITIONED_RV, ROUNDING_LEVEL, all_finite, bound_growth,
    covariance_overflowed, euler_unstable, growth_per_step, lost_precision, mean_overflowed,
    not_positive, overflowed_maxima, stationary,
};
use super::state::{LoopState, STATE_KEY};
use super::traces::{SERIES, Written, build_traces, take_row};
#[cfg(target_arch = "x86_64")]
use super::{Build, build};
use crate::analysis::inputs::{Inputs, time_err};
use crate::analysis::result::{AnalysisResult, CriteriaSets, Final, PairOut, SteadyState, Timing};
use crate::error::Error;
use crate::exec::Memo;
use crate::model::compile::CompiledModel;
use crate::numerics::decimate::Decimator;
use crate::numerics::lanes::{Lanes, Scalar};
use crate::numerics::linalg::{
    SparseRows, arr, arr_mut, cov_rel_diff, mat, predict_in_place, predict_work,
};
use crate::numerics::riccati::Prepared;
use crate::progress::Progress;
use crate::resume::{F, bits, values};

/// The shortcut freezes the Riccati recursion once r_k is this close (relative) to
/// the stationary solution r∞ of the DARE (rounding keeps a slowly contracting
/// recursion from getting much closer).
const STEADY_TOL: f64 = 1e-13;

pub(super) struct Engine<'m, const N: usize> {
    m: &'m CompiledModel,
    steps: u64,
    /// N and n (measurements), L, M.
    nn: usize,
    nm: usize,
    dt: f64,
    /// Only the filter's covariance recursion and the mean
    /// ([`covariance_recursion`](super::covariance_recursion)).
    covariance_only: bool,
    /// Where the loop's state is kept, and an earlier run's found ([`crate::resume`]).
    memo: &'m dyn Memo,
}

impl<'m, const N: usize> Engine<'m, N> {
    pub(super) fn new(
        m: &'m CompiledModel,
        steps: u64,
        covariance_only: bool,
        memo: &'m dyn Memo,
    ) -> Self {
        let nn = if N == 0 { m.n_states() } else { N };
        debug_assert_eq!(nn, m.n_states());
        Engine {
            m,
            steps,
            nn,
            nm: m.n_measurements(),
            dt: (m.t_end - m.t0) / steps as f64,
            covariance_only,
            memo,
        }
    }

    #[inline(always)]
    fn n(&self) -> usize {
        if N == 0 { self.nn } else { N }
    }

    /// Runs the recursion, compiled for AVX-512 or AVX2 + FMA when the CPU has them
    /// (x86-64, [`build`]). Rust never contracts a·b + c into an FMA and LLVM does
    /// not reorder floating-point sums, so every build of the loop gives
    /// bit-identical results (`server/tests/cli.rs::simd_builds_agree_bitwise`).
    pub(super) fn run(&self, progress: &mut dyn Progress) -> Result<AnalysisResult, Error> {
        #[cfg(target_arch = "x86_64")]
        match build() {
            // SAFETY: `build` chose each only where the CPU has its features.
            Build::Avx512 => return unsafe { self.run_avx512(progress) },
            Build::Avx2 => return unsafe { self.run_avx2(progress) },
            Build::Baseline => {}
        }
        self.run_body::<Scalar>(progress)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn run_avx2(&self, progress: &mut dyn Progress) -> Result<AnalysisResult, Error> {
        // The explicit AVX2 row kernels: this function is only entered on a CPU with AVX2.
        self.run_body::<crate::numerics::lanes::Avx2>(progress)
    }

    /// The same loop for AVX-512: LLVM puts the fixed-size (N ≤ 12) row operations
    /// in 8-lane registers (a 10-state row in two operations instead of three); the
    /// runtime-sized kernels stay the explicit AVX2 ones.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
    fn run_avx512(&self, progress: &mut dyn Progress) -> Result<AnalysisResult, Error> {
        self.run_body::<crate::numerics::lanes::Avx2>(progress)
    }

    /// The recursion; `L` supplies the row kernels (portable or AVX2).
    #[inline(always)]
    fn run_body<L: Lanes>(&self, progress: &mut dyn Progress) -> Result<AnalysisResult, Error> {
        let n = self.n();
        let (nm, dt) = (self.nm, self.dt);
        let m = self.m;
        let t0 = m.t0;
        let mut inp = Inputs::new(m, n, dt);
        inp.at(m, 1, true)?;
        let invariant = m.is_time_invariant();

        // The stationary predicted covariance r∞ (doubling), for the shortcut.
        let mut warnings = Vec::new();
        let r_inf = if invariant {
            stationary(&inp, n, nm, self.steps, &mut warnings)
        } else {
            None
        };

        // --- the loop's state (kept for a resume), and what a step recomputes
        let mut ey = vec![0.0; n];
        let mut xi = vec![0.0; n];
        let mut work = predict_work(n);
        let mut prep = Prepared::new(n, nm);
        let mut schedule = m.schedule.clone();
        let pair = &m.pair_of_state;
        let mut dec = Decimator::new(self.steps, n * SERIES, m.trace_points);
        let mut checkpoints = Checkpoints::analysis(m);

        // An earlier run's state (a restart): on from its step. (The inputs of the next
        // step are evaluated whole, which counts as Rv changed: the factorisation of Rv
        // is made again, from the same Rv and mask.)
        let earlier = (!self.covariance_only)
            .then(|| self.memo.recall(STATE_KEY))
            .flatten()
            .and_then(|text| LoopState::from_text(&text, self.steps, m, (n, nm), &mut dec));
        let resumed_from = earlier.as_ref().map(|s| s.k);
        let mut st = earlier.unwrap_or_else(|| LoopState::new(m, n, nm));
        let first = st.k + 1;
        if let Some(k) = resumed_from {
            checkpoints = checkpoints.after(k);
            if first <= self.steps {
                inp.at(m, first, true)?;
            }
        }
        // Fixed N: P^Y's diagonal, gathered once a step (after the prediction) for its
        // check and its roots.
        let mut py_diag = [0.0f64; N];
        for (i, d) in py_diag.iter_mut().enumerate() {
            *d = st.p_y[i * n + i];
        }

        for k in first..=self.steps {
            let t_k = t0 + k as f64 * dt;
            if k > first {
                inp.at(m, k, false)?;
            }

            // y_k = A y_{k−1} + uΔt (3.3), A = I + E; ẏ(t_{k−1}) = a y + u (1.4)
            mul_vec::<N, L>(&inp.e, &mut ey, &st.y, n);
            let ydot = &mut xi[..n]; // (xi as scratch: it is set again below)
            zip_into(ydot, &ey, &inp.u, |e, u| (e / dt + u).abs());
            zip_update(
                &mut st.ydot_max[..n],
                ydot,
                |m, d| if d > m { d } else { m },
            );
            let step = &mut xi[..n];
            zip_into(step, &ey, &inp.u_dt, |e, u| e + u);
            zip_update(&mut st.y[..n], step, |y, s| y + s);
            zip_update(&mut st.y_max[..n], &st.y, |m, y| {
                if y.abs() > m { y.abs() } else { m }
            });
            if !all_finite(&st.y[..n]) {
                let span = m.t_end - m.t0;
                return Err(
                    match euler_unstable(&inp.dense_a(), n, dt, span, self.steps) {
                        Some(message) => Error::Numerical {
                            step: k,
                            t: t_k,
                            path: "system.a".into(),
                            message,
                        },
                        None => mean_overflowed(&inp, &m.y0, &st.y, &m.states, k, t_k),
                    },
                );
            }

            if st.frozen_at.is_none() {
                // Measurements available at this step (all, unless scheduled).
                let all = match schedule.as_mut() {
                    None => true,
                    Some(sc) => sc
                        .mask(k, t_k, &mut st.avail)
                        .map_err(|p| time_err(&p, k, t_k))?,
                };
                let mask_changed = st.avail_prev != st.avail;
                if k == 1 || inp.rv_changed || mask_changed {
                    let mask = (!all).then_some(&st.avail[..]);
                    if prep.prepare(&m.c, &inp.rv, mask, n, nm).is_err() {
                        let r = &st.joseph.r_pred;
                        return Err(not_positive(&st.big_r, r, &inp, k, t_k, m, &prep.idx));
                    }
                    if prep.spread > ILL_CONDITIONED_RV {
                        let worst = st
                            .ill_conditioned
                            .map_or(0.0, |(_, _, s)| s.0)
                            .max(prep.spread);
                        let (first, t_first) =
                            st.ill_conditioned.map_or((k, F(t_k)), |(f, t, _)| (f, t));
                        st.ill_conditioned = Some((first, t_first, F(worst)));
                    }
                    st.avail_prev.copy_from_slice(&st.avail);
                    if k == 1 || mask_changed {
                        for (h, p) in st.has_meas.iter_mut().zip(pair) {
                            *h = p.is_some_and(|j| st.avail[j]);
                        }
                        st.part_for = None;
                    }
                }
                if !st
                    .joseph
                    .step::<N, L>(n, &mut st.big_r, &inp.e, &inp.big_b, &prep)
                {
                    return Err(match st.cancelled {
                        Some((j, t_j, i)) if all_finite(&st.big_r) => {
                            lost_precision(k, t_k, j, t_j.0, &m.states[i])
                        }
                        _ => not_positive(&st.big_r, &st.joseph.r_pred, &inp, k, t_k, m, &prep.idx),
                    });
                }
                for i in 0..n {
                    st.pot[i] = st.big_r[i * n + i];
                }
                // R_ii far below r_ii is the small difference of large terms (2.7):
                // rounding error, not the filter (see ROUNDING_LEVEL) — except for a
                // state a unit row measures in an exact update.
                if let Some(i) = (0..n).position(|i| {
                    let r = st.joseph.r_pred[i * n + i];
                    r > 0.0
                        && st.pot[i] <= ROUNDING_LEVEL * r
                        && !(st.joseph.exact && prep.measures(i))
                }) {
                    st.cancelled.get_or_insert((k, F(t_k), i));
                    st.cancelled_steps += 1;
                }
                if !all_finite(&st.pot[..n]) {
                    let otherwise =
                        "the model diverges faster than f64 can follow on this interval";
                    return Err(covariance_overflowed(
                        &inp,
                        k,
                        t_k,
                        &st.pot[..n],
                        &m.states,
                        otherwise,
                    ));
                }
                for p in &mut st.pot[..n] {
                    *p = p.max(0.0).sqrt();
                }
                zip_update(&mut st.inv_pot[..n], &st.pot, |_, p| {
                    if p > 0.0 { 1.0 / p } else { f64::NAN }
                });
                // |I − pC| and |p| ζ for the bound (3.19)
                if !self.covariance_only {
                    zip_update(&mut st.abs_ht, &st.joseph.ht, |_, x| x.abs());
                    st.pz.fill(0.0);
                    for (j, g) in st.joseph.gain_t.chunks_exact(n).enumerate() {
                        let z = inp.zeta[j];
                        zip_update(&mut st.pz[..n], g, |p, g| p + g.abs() * z);
                    }
                }
                // Steady state: r_k within STEADY_TOL of r∞ (then R, p are stationary too).
                if let Some(r_inf) = &r_inf
                    && st.steady_at.is_none()
                    && diag_close(&st.joseph.r_pred, r_inf, n, STEADY_TOL)
                    && cov_rel_diff(&st.joseph.r_pred, r_inf, n) <= STEADY_TOL
                {
                    st.steady_at = Some(k);
                    st.steady_cov =
                        Some((bits(&st.big_r), bits(&gain_rows(&st.joseph.gain_t, n, nm))));
                    if m.steady_state_shortcut {
                        st.frozen_at = Some(k);
                    }
                }
            }

            if self.covariance_only {
                checkpoints.at(progress, k, || k as f64 / self.steps as f64)?;
                continue;
            }

            // Open-loop covariance P^Y = A P Aᵀ + B (§1.5, exact second moments)
            if st.open_diverged.is_none() {
                predict_in_place::<N, L>(&mut st.p_y, &inp.e, &inp.big_b, &mut work, n);
                let finite = if N > 0 {
                    let p = mat::<N>(&st.p_y);
                    for i in 0..N {
                        py_diag[i] = p[i][i];
                    }
                    all_finite(&py_diag)
                } else {
                    (0..n).fold(true, |ok, i| ok & st.p_y[i * n + i].is_finite())
                };
                if !finite {
                    st.open_diverged = Some((k, F(t_k)));
                }
            }

            // Bound propagation (3.16)–(3.19): η = |A| η + |bΔt| φ, χ = |h| |A| χ + |p| ζ
            if st.bound_diverged.is_none() {
                mul_vec::<N, L>(&inp.abs_a, &mut xi, &st.eta, n);
                zip_into(&mut st.eta[..n], &xi, &inp.b_phi, |x, b| x + b);
                mul_vec::<N, L>(&inp.abs_a, &mut xi, &st.chi, n);
                // χ_c = (Σ_b |h_cb| ξ_b, b in order) + (|p| ζ)_c, as row operations on |h|ᵀ
                if N > 0 {
                    let (h, x, c) = (
                        mat::<N>(&st.abs_ht),
                        arr::<N>(&xi),
                        arr_mut::<N>(&mut st.chi),
                    );
                    let mut w = [0.0f64; N];
                    for b in 0..N {
                        for j in 0..N {
                            w[j] += h[b][j] * x[b];
                        }
                    }
                    *c = w;
                } else {
                    st.chi.fill(0.0);
                    for (h, &x) in st.abs_ht.chunks_exact(n).zip(&xi) {
                        for (c, h) in st.chi.iter_mut().zip(h) {
                            *c += h * x;
                        }
                    }
                }
                zip_update(&mut st.chi[..n], &st.pz, |c, p| c + p);
                if !(all_finite(&st.eta[..n]) & all_finite(&st.chi[..n])) {
                    st.bound_diverged = Some((k, F(t_k), !all_finite(&st.eta[..n])));
                }
            }
            let bound_ok = st.bound_diverged.is_none();
            let open_ok = st.open_diverged.is_none();

            // The previous step's row, summed and decimated only now: its loads then
            // read stores made a whole recursion earlier. Read right after being
            // written, the row's whole-lane loads spanned two series' stores and
            // waited for them to reach the cache (store forwarding fails on such a
            // load). Before `part` is updated for this step.
            if let Some(w) = st.written.take() {
                take_row(&mut st.row, &st.part, &mut st.running, &mut dec, n, w);
            }

            // Criteria (3.23)–(3.24) as ratios; traces. Each series is one branch-free
            // loop over the states.
            if inp.rv_changed || st.part_for.is_none() {
                for (i, p) in pair.iter().enumerate() {
                    let j = p.filter(|_| st.has_meas[i]);
                    st.zeta_s[i] = j.map_or(f64::NAN, |j| inp.zeta[j]);
                    st.meas_s[i] = j.map_or(f64::NAN, |j| inp.meas_sko[j]);
                    let positive = |v: f64, inv: f64| if v > 0.0 { inv } else { f64::NAN };
                    st.inv_zeta_s[i] =
                        j.map_or(f64::NAN, |j| positive(inp.zeta[j], inp.inv_zeta[j]));
                    st.inv_meas_s[i] =
                        j.map_or(f64::NAN, |j| positive(inp.meas_sko[j], inp.inv_meas[j]));
                }
            }
            if st.part_for != Some((bound_ok, open_ok)) {
                // A paired state whose measurement is unavailable has no measured
                // information at this step: an excluded step of YZ and ZX (its
                // ratios are NaN).
                for i in 0..n {
                    let paired = pair[i].is_some();
                    let without = paired && !st.has_meas[i];
                    let p = |on: bool| u64::from(on);
                    st.part[C_BOUND_YZ * n + i] = p(paired && bound_ok || without);
                    st.part[C_BOUND_ZX * n + i] = p(paired && bound_ok || without);
                    st.part[C_BOUND_YX * n + i] = p(bound_ok);
                    st.part[C_COV_YZ * n + i] = p(paired && open_ok || without);
                    st.part[C_COV_ZX * n + i] = p(paired);
                    st.part[C_COV_YX * n + i] = p(open_ok);
                }
                st.part_for = Some((bound_ok, open_ok));
                st.constant_rows = false;
            }
            // Once frozen, ζ, R and σ_Z no longer change: the row keeps the first three
            // series and the covariance ZX ratios the previous step wrote.
            let constants = !st.constant_rows || inp.rv_changed;
            st.constant_rows = st.frozen_at.is_some() && !inp.rv_changed;
            {
                let nan = f64::NAN;
                let (r_zeta, rest) = st.row.split_at_mut(n);
                let (r_pot, rest) = rest.split_at_mut(n);
                let (r_meas, rest) = rest.split_at_mut(n);
                let (r_y, rest) = rest.split_at_mut(n);
                let (r_eta, rest) = rest.split_at_mut(n);
                let (r_chi, rest) = rest.split_at_mut(n);
                let (r_open, rest) = rest.split_at_mut(n);
                let (r_ryz, rest) = rest.split_at_mut(n);
                let (r_rzx, rest) = rest.split_at_mut(n);
                let (r_ryx, rest) = rest.split_at_mut(n);
                let (c_yz, rest) = rest.split_at_mut(n);
                let (c_zx, c_yx) = rest.split_at_mut(n);
                let (eta, chi, pot, inv_pot) =
                    (&st.eta[..n], &st.chi[..n], &st.pot[..n], &st.inv_pot[..n]);
                let (zeta_s, meas_s) = (&st.zeta_s[..n], &st.meas_s[..n]);
                let (inv_zeta_s, inv_meas_s) = (&st.inv_zeta_s[..n], &st.inv_meas_s[..n]);
                // (One loop rather than four copy_from_slice: each of those is a call
                // to memcpy, dearer than the copy of N values.)
                #[allow(clippy::manual_memcpy)]
                if constants {
                    for i in 0..n {
                        r_pot[i] = pot[i];
                        r_zeta[i] = zeta_s[i];
                        r_meas[i] = meas_s[i];
                        c_zx[i] = meas_s[i] * inv_pot[i];
                    }
                }
                #[allow(clippy::manual_memcpy)]
                for i in 0..n {
                    r_y[i] = st.y[i];
                }
                if N > 0 {
                    // From the gathered diagonal, so that the roots are taken a whole
                    // lane at a time (one at a time they were ≈ 10 % of a frozen step).
                    let mut d = py_diag;
                    for v in &mut d {
                        *v = v.max(0.0).sqrt();
                    }
                    *arr_mut::<N>(r_open) = d;
                } else {
                    for i in 0..n {
                        r_open[i] = st.p_y[i * n + i].max(0.0).sqrt();
                    }
                }
                // (A reciprocal is NaN where its value is not positive.)
                for i in 0..n {
                    let open = r_open[i];
                    c_yz[i] = open * inv_meas_s[i];
                    c_yx[i] = open * inv_pot[i];
                }
                for i in 0..n {
                    let (e, c, zb) = (eta[i], chi[i], zeta_s[i]);
                    let inv_chi = 1.0 / c;
                    r_ryx[i] = if c > 0.0 { e * inv_chi } else { nan };
                    r_ryz[i] = e * inv_zeta_s[i];
                    r_rzx[i] = if c > 0.0 { zb * inv_chi } else { nan };
                }
                r_eta.copy_from_slice(eta);
                r_chi.copy_from_slice(chi);
            }
            st.written = Some(Written {
                k,
                t: t_k,
                bound_ok,
                open_ok,
                constants,
            });

            if checkpoints.reported(progress, k, || k as f64 / self.steps as f64)?
                && self.memo.state_due()
            {
                st.k = k;
                let text = st.to_text(&dec, self.steps, n, nm);
                self.memo.keep_state(STATE_KEY, &text);
            }
        }
        if let Some(w) = st.written.take() {
            take_row(&mut st.row, &st.part, &mut st.running, &mut dec, n, w);
        }
        let _ = progress.report(1.0);

        // --- assemble (3.20)–(3.26)
        // (Fresh copies for the closures below: a closure that borrows the loop's n
        // takes its address, and LLVM then reloads n from memory after every call in
        // the loop instead of folding the constant N into the loops' trip counts.)
        let (n, nm) = (n, nm);
        let z_max: Vec<f64> = (0..nm)
            .map(|j| (0..n).map(|i| m.c[j * n + i].abs() * st.y_max[i]).sum())
            .collect();
        if let Some(w) = overflowed_maxima(m, &st.ydot_max, &z_max) {
            warnings.push(w);
        }
        let lambda = laplace_lambda(m.confidence);
        let (bound, cov) = st.running.into_sets(n);
        // An open-loop covariance that overflows with A growing: the model is unstable
        // on this interval, and a bound on the a-priori error rightly grows with it.
        let unstable = st.open_diverged.is_some() && growth_per_step(&inp.dense_a(), n) > 1.0;
        let bound_why = st.bound_diverged.map(|(k, F(t), eta_too)| {
            let why = if eta_too && unstable {
                "the model is unstable on this interval (a mode of A grows, and the open-loop covariance overflowed too), so the a-priori error and its bound grow beyond f64's range; shorten the interval, or see the covariance set's ZX"
            } else {
                "|A| taken element-wise grows where A does not (oscillatory or feedback dynamics), so the bound is not informative here; see the covariance set"
            };
            format!(
                "{BOUND_WARNING} overflowed at step {k} (t = {}): {why}",
                crate::text::short(t)
            )
        });
        let open_why = st.open_diverged.map(|(k, F(t))| {
            format!(
                "the open-loop (a-priori) covariance overflowed at step {k} (t = {}){}",
                crate::text::short(t),
                if unstable {
                    ": the model is unstable on this interval (a mode of A grows)"
                } else {
                    ""
                }
            )
        });
        if let Some(w) = &bound_why {
            warnings.push(w.clone());
        }
        if let Some(w) = &open_why {
            warnings.push(w.clone());
        }
        let bound_set = criteria_set(
            m,
            &bound,
            &st.y_max,
            &z_max,
            "bound",
            [
                bound_why.as_deref(),
                bound_why.as_deref(),
                bound_why.as_deref(),
            ],
        );
        let cov_set = criteria_set(
            m,
            &cov,
            &st.y_max,
            &z_max,
            "covariance",
            [open_why.as_deref(), None, open_why.as_deref()],
        );
        let traces = build_traces(m, dec, &st.y_max, &z_max, &mut warnings);
        let to_rows = |v: &[f64], cols: usize| -> Vec<Vec<f64>> {
            v.chunks_exact(cols.max(1)).map(|r| r.to_vec()).collect()
        };
        let pairs = (0..n)
            .filter_map(|i| {
                pair[i].map(|j| PairOut {
                    state: m.states[i].clone(),
                    measurement: m.measurements[j].clone(),
                })
            })
            .collect();
        let zeta_state: Vec<f64> = inp.zeta.clone();
        let mut final_ = Final {
            covariance: to_rows(&st.big_r, n),
            gain: to_rows(&gain_rows(&st.joseph.gain_t, n, nm), nm),
            predicted_covariance: to_rows(&st.joseph.r_pred, n),
            eta: st.eta.clone(),
            zeta: zeta_state.clone(),
            chi: st.chi.clone(),
            potential_sko: (0..n)
                .map(|i| st.big_r[i * n + i].max(0.0).sqrt())
                .collect(),
            open_loop_sko: (0..n).map(|i| st.p_y[i * n + i].max(0.0).sqrt()).collect(),
            measured_sko: inp.meas_sko.clone(),
            delta_y: st.eta.iter().map(|x| lambda * x).collect(),
            delta_z: zeta_state.iter().map(|x| lambda * x).collect(),
            delta_x: st.chi.iter().map(|x| lambda * x).collect(),
        };
        // Past an overflow the last values are stale (the propagation stopped there):
        // null, as the traces are.
        if bound_why.is_some() {
            for v in [
                &mut final_.eta,
                &mut final_.chi,
                &mut final_.delta_y,
                &mut final_.delta_x,
            ] {
                v.fill(f64::NAN);
            }
        }
        if open_why.is_some() {
            final_.open_loop_sko.fill(f64::NAN);
        }
        let steady_state = st.steady_at.map(|k| {
            let (r, g) = st
                .steady_cov
                .as_ref()
                .map_or_else(Default::default, |(r, g)| (values(r), values(g)));
            SteadyState {
                reached_at_step: k,
                t: t0 + k as f64 * dt,
                covariance: to_rows(&r, n),
                gain: to_rows(&g, nm),
                shortcut_used: st.frozen_at.is_some(),
            }
        });
        if bound_why.is_none()
            && let Some(w) = bound_growth(&m.states, &final_, lambda)
        {
            warnings.push(w);
        }
        if let Some((k, F(t), F(spread))) = st.ill_conditioned {
            warnings.push(format!(
                "the measurement noise covariance Γ V Γᵀ is ill-conditioned from step {k} (t = {}): the pivots of its factorisation span up to {:.1e}, so whitening the measurements loses about {:.0} of f64's 16 digits, which the covariance set's R and, more so, the bound set's χ (a product of |I − pC| over the steps) carry; noises this nearly dependent are better given a noise of their own per measurement, or the shared noise modelled as a state",
                crate::text::num(t),
                spread,
                spread.log10().round()
            ));
        }
        if let Some((k, F(t), i)) = st.cancelled {
            warnings.push(format!(
                "the filtered variance of \"{}\" fell to ≤ {ROUNDING_LEVEL:e} of its predicted variance at step {k} (t = {}); {} of the {} steps had a state's at that level: the update cancels it almost exactly — a state measured only through others (its correlation with a measured state, or a row of c that combines states), with an initial or model-error SKO far above what the measurements leave of it — so R's diagonal there keeps fewer than 4 correct digits: the covariance set's ZX and YX at those steps are ratios of rounding errors, and later steps inherit R's error until the filter forgets it",
                m.states[i],
                crate::text::num(t),
                st.cancelled_steps,
                self.steps
            ));
        }
        Ok(AnalysisResult {
            steps: self.steps,
            dt,
            t0,
            t_end: m.t_end,
            step_selection: None,
            states: m.states.clone(),
            measurements: m.measurements.clone(),
            pairs,
            y_max: st.y_max,
            ydot_max: st.ydot_max,
            z_max,
            confidence: m.confidence,
            lambda,
            criteria: CriteriaSets {
                bound: bound_set,
                covariance: cov_set,
                monte_carlo: None,
                actual: None,
            },
            final_,
            steady_state,
            traces,
            budget: None,
            mismatch: None,
            timing: Timing {
                resumed_from_step: resumed_from,
                ..Timing::default()
            },
            warnings,
        })
    }
}

/// p (N × nm, row-major) from pᵀ.
fn gain_rows(gain_t: &[f64], n: usize, nm: usize) -> Vec<f64> {
    let mut g = vec![0.0; n * nm];
    for j in 0..nm {
        for i in 0..n {
            g[i * nm + j] = gain_t[j * n + i];
        }
    }
    g
}

/// out_i = f(a_i, b_i). Element-wise loops go through these two: as function
/// arguments the slices are known not to overlap, so LLVM vectorises them; written
/// inline over the engine's buffers, the same loops stay scalar.
#[inline(always)]
fn zip_into(out: &mut [f64], a: &[f64], b: &[f64], f: impl Fn(f64, f64) -> f64) {
    let (a, b) = (&a[..out.len()], &b[..out.len()]);
    for i in 0..out.len() {
        out[i] = f(a[i], b[i]);
    }
}

/// out_i = f(out_i, a_i).
#[inline(always)]
fn zip_update(out: &mut [f64], a: &[f64], f: impl Fn(f64, f64) -> f64) {
    let a = &a[..out.len()];
    for i in 0..out.len() {
        out[i] = f(out[i], a[i]);
    }
}

/// y = M x (n = N when N > 0: the fixed-size build).
#[inline(always)]
fn mul_vec<const N: usize, L: Lanes>(m: &SparseRows, y: &mut [f64], x: &[f64], n: usize) {
    if N > 0 {
        m.mul_vec_fixed::<N>(arr_mut::<N>(y), arr::<N>(x));
    } else {
        m.mul_vec::<L>(y, x, n);
    }
}

/// The cheap first test of the steady state: every diagonal entry within `tol`.
#[inline(always)]
fn diag_close(a: &[f64], b: &[f64], n: usize, tol: f64) -> bool {
    (0..n).all(|i| (a[i * n + i] - b[i * n + i]).abs() <= tol * b[i * n + i].abs())
}
