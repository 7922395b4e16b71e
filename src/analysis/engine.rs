//! The analysis's step loop (METHOD §1.2–§1.6): the mean (3.3), the Joseph-form Riccati
//! recursion (2.1)–(2.7), the open-loop covariance (§1.5), the bound (3.16)–(3.19) and a
//! step's criteria ratios (3.23)–(3.24); then the result assembled (3.20)–(3.26).

use super::Checkpoints;
use super::criteria::{
    C_BOUND_YX, C_BOUND_YZ, C_BOUND_ZX, C_COV_YX, C_COV_YZ, C_COV_ZX, Running, criteria_set,
    laplace_lambda,
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
use crate::numerics::riccati::{Prepared, SequentialJoseph};
use crate::progress::Progress;
use crate::resume::{F, bits, put, values};

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

        // --- state
        let mut y = m.y0.clone();
        let mut ey = vec![0.0; n];
        let mut y_max: Vec<f64> = y.iter().map(|v| v.abs()).collect();
        let mut ydot_max = vec![0.0f64; n];
        let mut big_r = vec![0.0; n * n]; // R_k
        for i in 0..n {
            big_r[i * n + i] = m.eta0[i] * m.eta0[i];
        }
        let mut p_y = big_r.clone(); // open-loop covariance P^Y
        // Fixed N: P^Y's diagonal, gathered once a step (after the prediction) for
        // its check and its roots.
        let mut py_diag = [0.0f64; N];
        let mut work = predict_work(n);
        let mut eta = m.eta0.clone();
        let mut chi = vec![0.0; n]; // χ(t0) = 0 (3.18)
        let mut xi = vec![0.0; n];
        let mut joseph = SequentialJoseph::new(n, nm);
        let mut prep = Prepared::new(n, nm);
        let mut schedule = m.schedule.clone();
        let mut avail = vec![true; nm];
        let mut avail_prev = vec![true; nm]; // the mask `prep` was prepared for
        let mut abs_ht = vec![0.0; n * n]; // |I − pC|ᵀ
        let mut pz = vec![0.0; n]; // |p| ζ (3.19)
        let mut pot = vec![0.0; n]; // sqrt(diag R_k)
        let mut inv_pot = vec![0.0; n];

        let mut running = Running::new(n);
        let pair = &m.pair_of_state;
        // A step's trace values (NaN: no value), followed by its covariance-set
        // ratios (NaN: excluded), so that the six criteria's ratios are contiguous
        // (the bound set's are the last three trace series); which criteria take part.
        let mut row = vec![f64::NAN; (SERIES + 3) * n];
        let mut part = vec![0u64; 6 * n];
        let mut part_for: Option<(bool, bool)> = None; // (bound_ok, open_ok) of `part`
        // Per state: ζ, σ_Z while its measurement is available (NaN when unpaired or
        // unavailable, which makes every measured ratio NaN), and their reciprocals
        // where positive (NaN otherwise: a ratio over them is then NaN, excluded).
        let (mut zeta_s, mut meas_s) = (vec![f64::NAN; n], vec![f64::NAN; n]);
        let (mut inv_zeta_s, mut inv_meas_s) = (vec![f64::NAN; n], vec![f64::NAN; n]);
        let mut has_meas = vec![false; n];
        let mut dec = Decimator::new(self.steps, n * SERIES, m.trace_points);
        // Whether the row's constant series (before S_Y) and covariance ZX ratios
        // are those of the previous step.
        let mut constant_rows = false;
        // The row written at the end of the previous step, not yet summed.
        let mut written: Option<Written> = None;

        let mut frozen_at: Option<u64> = None;
        // The bound (|A| element-wise) or the open-loop covariance can overflow while
        // the filter itself is fine; the affected criteria then become null.
        // (step, t, whether η — the a-priori bound — overflowed, not only χ)
        let mut bound_diverged: Option<(u64, f64, bool)> = None;
        let mut open_diverged: Option<(u64, f64)> = None;
        let mut steady_at: Option<u64> = None;
        let mut steady_cov: Option<(Vec<f64>, Vec<f64>)> = None;
        // The first step (k, t_k, state) whose filtered variance is at rounding level,
        // and how many steps had one.
        let mut cancelled: Option<(u64, f64, usize)> = None;
        let mut cancelled_steps = 0u64;
        // The first step whose Rv is ill-conditioned, and the worst spread of its pivots.
        let mut ill_conditioned: Option<(u64, f64, f64)> = None;
        let mut checkpoints = Checkpoints::analysis(m);

        // An earlier run's state (a restart): its values, and on from its step. (The
        // inputs of the next step are evaluated whole, which counts as Rv changed: the
        // factorisation of Rv is made again, from the same Rv and mask.)
        let mut first = 1;
        let mut resumed_from = None;
        let py_len = if N > 0 { N } else { 0 };
        let earlier = (!self.covariance_only)
            .then(|| self.memo.recall(STATE_KEY))
            .flatten()
            .and_then(|text| LoopState::from_text(&text, self.steps, (n, nm, py_len), &dec));
        if let Some(s) = earlier {
            put(&mut y, &s.y);
            put(&mut y_max, &s.y_max);
            put(&mut ydot_max, &s.ydot_max);
            put(&mut big_r, &s.big_r);
            put(&mut p_y, &s.p_y);
            put(&mut py_diag[..py_len], &s.py_diag);
            put(&mut eta, &s.eta);
            put(&mut chi, &s.chi);
            put(&mut joseph.r_pred, &s.r_pred);
            put(&mut joseph.gain_t, &s.gain_t);
            put(&mut joseph.ht, &s.ht);
            joseph.exact = s.exact;
            avail.copy_from_slice(&s.avail);
            avail_prev.copy_from_slice(&s.avail_prev);
            put(&mut abs_ht, &s.abs_ht);
            put(&mut pz, &s.pz);
            put(&mut pot, &s.pot);
            put(&mut inv_pot, &s.inv_pot);
            put(&mut running.sum, &s.sum);
            running.count.copy_from_slice(&s.count);
            running.excluded.copy_from_slice(&s.excluded);
            put(&mut row, &s.row);
            part.copy_from_slice(&s.part);
            part_for = s.part_for;
            put(&mut zeta_s, &s.zeta_s);
            put(&mut meas_s, &s.meas_s);
            put(&mut inv_zeta_s, &s.inv_zeta_s);
            put(&mut inv_meas_s, &s.inv_meas_s);
            has_meas.copy_from_slice(&s.has_meas);
            dec.restore(&s.dec);
            constant_rows = s.constant_rows;
            written = s
                .written
                .map(|(k, t, bound_ok, open_ok, constants)| Written {
                    k,
                    t: t.0,
                    bound_ok,
                    open_ok,
                    constants,
                });
            frozen_at = s.frozen_at;
            bound_diverged = s.bound_diverged.map(|(k, t, e)| (k, t.0, e));
            open_diverged = s.open_diverged.map(|(k, t)| (k, t.0));
            steady_at = s.steady_at;
            steady_cov = s.steady_cov.map(|(r, g)| (values(&r), values(&g)));
            cancelled = s.cancelled.map(|(k, t, i)| (k, t.0, i));
            cancelled_steps = s.cancelled_steps;
            ill_conditioned = s.ill_conditioned.map(|(k, t, x)| (k, t.0, x.0));
            first = s.k + 1;
            resumed_from = Some(s.k);
            checkpoints = checkpoints.after(s.k);
            if first <= self.steps {
                inp.at(m, first, true)?;
            }
        }

        for k in first..=self.steps {
            let t_k = t0 + k as f64 * dt;
            if k > first {
                inp.at(m, k, false)?;
            }

            // y_k = A y_{k−1} + uΔt (3.3), A = I + E; ẏ(t_{k−1}) = a y + u (1.4)
            mul_vec::<N, L>(&inp.e, &mut ey, &y, n);
            let ydot = &mut xi[..n]; // (xi as scratch: it is set again below)
            zip_into(ydot, &ey, &inp.u, |e, u| (e / dt + u).abs());
            zip_update(&mut ydot_max[..n], ydot, |m, d| if d > m { d } else { m });
            let step = &mut xi[..n];
            zip_into(step, &ey, &inp.u_dt, |e, u| e + u);
            zip_update(&mut y[..n], step, |y, s| y + s);
            zip_update(
                &mut y_max[..n],
                &y,
                |m, y| if y.abs() > m { y.abs() } else { m },
            );
            if !all_finite(&y[..n]) {
                let span = m.t_end - m.t0;
                return Err(
                    match euler_unstable(&inp.dense_a(), n, dt, span, self.steps) {
                        Some(message) => Error::Numerical {
                            step: k,
                            t: t_k,
                            path: "system.a".into(),
                            message,
                        },
                        None => mean_overflowed(&inp, &m.y0, &y, &m.states, k, t_k),
                    },
                );
            }

            if frozen_at.is_none() {
                // Measurements available at this step (all, unless scheduled).
                let all = match schedule.as_mut() {
                    None => true,
                    Some(sc) => sc
                        .mask(k, t_k, &mut avail)
                        .map_err(|p| time_err(&p, k, t_k))?,
                };
                let mask_changed = avail_prev != avail;
                if k == 1 || inp.rv_changed || mask_changed {
                    let mask = (!all).then_some(&avail[..]);
                    if prep.prepare(&m.c, &inp.rv, mask, n, nm).is_err() {
                        let r = &joseph.r_pred;
                        return Err(not_positive(&big_r, r, &inp, k, t_k, m, &prep.idx));
                    }
                    if prep.spread > ILL_CONDITIONED_RV {
                        let worst = ill_conditioned.map_or(0.0, |(_, _, s)| s).max(prep.spread);
                        let (first, t_first) = ill_conditioned.map_or((k, t_k), |(f, t, _)| (f, t));
                        ill_conditioned = Some((first, t_first, worst));
                    }
                    avail_prev.copy_from_slice(&avail);
                    if k == 1 || mask_changed {
                        for (h, p) in has_meas.iter_mut().zip(pair) {
                            *h = p.is_some_and(|j| avail[j]);
                        }
                        part_for = None;
                    }
                }
                if !joseph.step::<N, L>(n, &mut big_r, &inp.e, &inp.big_b, &prep) {
                    return Err(match cancelled {
                        Some((j, t_j, i)) if all_finite(&big_r) => {
                            lost_precision(k, t_k, j, t_j, &m.states[i])
                        }
                        _ => not_positive(&big_r, &joseph.r_pred, &inp, k, t_k, m, &prep.idx),
                    });
                }
                for i in 0..n {
                    pot[i] = big_r[i * n + i];
                }
                // R_ii far below r_ii is the small difference of large terms (2.7):
                // rounding error, not the filter (see ROUNDING_LEVEL) — except for a
                // state a unit row measures in an exact update.
                if let Some(i) = (0..n).position(|i| {
                    let r = joseph.r_pred[i * n + i];
                    r > 0.0 && pot[i] <= ROUNDING_LEVEL * r && !(joseph.exact && prep.measures(i))
                }) {
                    cancelled.get_or_insert((k, t_k, i));
                    cancelled_steps += 1;
                }
                if !all_finite(&pot[..n]) {
                    let otherwise =
                        "the model diverges faster than f64 can follow on this interval";
                    return Err(covariance_overflowed(
                        &inp,
                        k,
                        t_k,
                        &pot[..n],
                        &m.states,
                        otherwise,
                    ));
                }
                for p in &mut pot[..n] {
                    *p = p.max(0.0).sqrt();
                }
                zip_update(&mut inv_pot[..n], &pot, |_, p| {
                    if p > 0.0 { 1.0 / p } else { f64::NAN }
                });
                // |I − pC| and |p| ζ for the bound (3.19)
                if !self.covariance_only {
                    zip_update(&mut abs_ht, &joseph.ht, |_, x| x.abs());
                    pz.fill(0.0);
                    for (j, g) in joseph.gain_t.chunks_exact(n).enumerate() {
                        let z = inp.zeta[j];
                        zip_update(&mut pz[..n], g, |p, g| p + g.abs() * z);
                    }
                }
                // Steady state: r_k within STEADY_TOL of r∞ (then R, p are stationary too).
                if let Some(r_inf) = &r_inf
                    && steady_at.is_none()
                    && diag_close(&joseph.r_pred, r_inf, n, STEADY_TOL)
                    && cov_rel_diff(&joseph.r_pred, r_inf, n) <= STEADY_TOL
                {
                    steady_at = Some(k);
                    steady_cov = Some((big_r.clone(), gain_rows(&joseph.gain_t, n, nm)));
                    if m.steady_state_shortcut {
                        frozen_at = Some(k);
                    }
                }
            }

            if self.covariance_only {
                checkpoints.at(progress, k, || k as f64 / self.steps as f64)?;
                continue;
            }

            // Open-loop covariance P^Y = A P Aᵀ + B (§1.5, exact second moments)
            if open_diverged.is_none() {
                predict_in_place::<N, L>(&mut p_y, &inp.e, &inp.big_b, &mut work, n);
                let finite = if N > 0 {
                    let p = mat::<N>(&p_y);
                    for i in 0..N {
                        py_diag[i] = p[i][i];
                    }
                    all_finite(&py_diag)
                } else {
                    (0..n).fold(true, |ok, i| ok & p_y[i * n + i].is_finite())
                };
                if !finite {
                    open_diverged = Some((k, t_k));
                }
            }

            // Bound propagation (3.16)–(3.19): η = |A| η + |bΔt| φ, χ = |h| |A| χ + |p| ζ
            if bound_diverged.is_none() {
                mul_vec::<N, L>(&inp.abs_a, &mut xi, &eta, n);
                zip_into(&mut eta[..n], &xi, &inp.b_phi, |x, b| x + b);
                mul_vec::<N, L>(&inp.abs_a, &mut xi, &chi, n);
                // χ_c = (Σ_b |h_cb| ξ_b, b in order) + (|p| ζ)_c, as row operations on |h|ᵀ
                if N > 0 {
                    let (h, x, c) = (mat::<N>(&abs_ht), arr::<N>(&xi), arr_mut::<N>(&mut chi));
                    let mut w = [0.0f64; N];
                    for b in 0..N {
                        for j in 0..N {
                            w[j] += h[b][j] * x[b];
                        }
                    }
                    *c = w;
                } else {
                    chi.fill(0.0);
                    for (h, &x) in abs_ht.chunks_exact(n).zip(&xi) {
                        for (c, h) in chi.iter_mut().zip(h) {
                            *c += h * x;
                        }
                    }
                }
                zip_update(&mut chi[..n], &pz, |c, p| c + p);
                if !(all_finite(&eta[..n]) & all_finite(&chi[..n])) {
                    bound_diverged = Some((k, t_k, !all_finite(&eta[..n])));
                }
            }
            let bound_ok = bound_diverged.is_none();
            let open_ok = open_diverged.is_none();

            // The previous step's row, summed and decimated only now: its loads then
            // read stores made a whole recursion earlier. Read right after being
            // written, the row's whole-lane loads spanned two series' stores and
            // waited for them to reach the cache (store forwarding fails on such a
            // load). Before `part` is updated for this step.
            if let Some(w) = written.take() {
                take_row(&mut row, &part, &mut running, &mut dec, n, w);
            }

            // Criteria (3.23)–(3.24) as ratios; traces. Each series is one branch-free
            // loop over the states.
            if inp.rv_changed || part_for.is_none() {
                for (i, p) in pair.iter().enumerate() {
                    let j = p.filter(|_| has_meas[i]);
                    zeta_s[i] = j.map_or(f64::NAN, |j| inp.zeta[j]);
                    meas_s[i] = j.map_or(f64::NAN, |j| inp.meas_sko[j]);
                    let positive = |v: f64, inv: f64| if v > 0.0 { inv } else { f64::NAN };
                    inv_zeta_s[i] = j.map_or(f64::NAN, |j| positive(inp.zeta[j], inp.inv_zeta[j]));
                    inv_meas_s[i] =
                        j.map_or(f64::NAN, |j| positive(inp.meas_sko[j], inp.inv_meas[j]));
                }
            }
            if part_for != Some((bound_ok, open_ok)) {
                // A paired state whose measurement is unavailable has no measured
                // information at this step: an excluded step of YZ and ZX (its
                // ratios are NaN).
                for i in 0..n {
                    let paired = pair[i].is_some();
                    let without = paired && !has_meas[i];
                    let p = |on: bool| u64::from(on);
                    part[C_BOUND_YZ * n + i] = p(paired && bound_ok || without);
                    part[C_BOUND_ZX * n + i] = p(paired && bound_ok || without);
                    part[C_BOUND_YX * n + i] = p(bound_ok);
                    part[C_COV_YZ * n + i] = p(paired && open_ok || without);
                    part[C_COV_ZX * n + i] = p(paired);
                    part[C_COV_YX * n + i] = p(open_ok);
                }
                part_for = Some((bound_ok, open_ok));
                constant_rows = false;
            }
            // Once frozen, ζ, R and σ_Z no longer change: the row keeps the first three
            // series and the covariance ZX ratios the previous step wrote.
            let constants = !constant_rows || inp.rv_changed;
            constant_rows = frozen_at.is_some() && !inp.rv_changed;
            {
                let nan = f64::NAN;
                let (r_zeta, rest) = row.split_at_mut(n);
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
                let (eta, chi, pot, inv_pot) = (&eta[..n], &chi[..n], &pot[..n], &inv_pot[..n]);
                let (zeta_s, meas_s) = (&zeta_s[..n], &meas_s[..n]);
                let (inv_zeta_s, inv_meas_s) = (&inv_zeta_s[..n], &inv_meas_s[..n]);
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
                    r_y[i] = y[i];
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
                        r_open[i] = p_y[i * n + i].max(0.0).sqrt();
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
            written = Some(Written {
                k,
                t: t_k,
                bound_ok,
                open_ok,
                constants,
            });

            if checkpoints.reported(progress, k, || k as f64 / self.steps as f64)?
                && self.memo.state_due()
            {
                let w = written
                    .as_ref()
                    .map(|w| (w.k, F(w.t), w.bound_ok, w.open_ok, w.constants));
                let state = LoopState {
                    format: 0,
                    steps: 0,
                    n: 0,
                    nm: 0,
                    k,
                    y: bits(&y),
                    y_max: bits(&y_max),
                    ydot_max: bits(&ydot_max),
                    big_r: bits(&big_r),
                    p_y: bits(&p_y),
                    py_diag: bits(&py_diag[..py_len]),
                    eta: bits(&eta),
                    chi: bits(&chi),
                    r_pred: bits(&joseph.r_pred),
                    gain_t: bits(&joseph.gain_t),
                    ht: bits(&joseph.ht),
                    exact: joseph.exact,
                    avail: avail.clone(),
                    avail_prev: avail_prev.clone(),
                    abs_ht: bits(&abs_ht),
                    pz: bits(&pz),
                    pot: bits(&pot),
                    inv_pot: bits(&inv_pot),
                    sum: bits(&running.sum),
                    count: running.count.clone(),
                    excluded: running.excluded.clone(),
                    row: bits(&row),
                    part: part.clone(),
                    part_for,
                    zeta_s: bits(&zeta_s),
                    meas_s: bits(&meas_s),
                    inv_zeta_s: bits(&inv_zeta_s),
                    inv_meas_s: bits(&inv_meas_s),
                    has_meas: has_meas.clone(),
                    dec: dec.state(),
                    constant_rows,
                    written: w,
                    frozen_at,
                    bound_diverged: bound_diverged.map(|(k, t, e)| (k, F(t), e)),
                    open_diverged: open_diverged.map(|(k, t)| (k, F(t))),
                    steady_at,
                    steady_cov: steady_cov.as_ref().map(|(r, g)| (bits(r), bits(g))),
                    cancelled: cancelled.map(|(k, t, i)| (k, F(t), i)),
                    cancelled_steps,
                    ill_conditioned: ill_conditioned.map(|(k, t, x)| (k, F(t), F(x))),
                };
                self.memo
                    .keep_state(STATE_KEY, &state.stamped(self.steps, n, nm).to_text());
            }
        }
        if let Some(w) = written.take() {
            take_row(&mut row, &part, &mut running, &mut dec, n, w);
        }
        let _ = progress.report(1.0);

        // --- assemble (3.20)–(3.26)
        // (Fresh copies for the closures below: a closure that borrows the loop's n
        // takes its address, and LLVM then reloads n from memory after every call in
        // the loop instead of folding the constant N into the loops' trip counts.)
        let (n, nm) = (n, nm);
        let z_max: Vec<f64> = (0..nm)
            .map(|j| (0..n).map(|i| m.c[j * n + i].abs() * y_max[i]).sum())
            .collect();
        if let Some(w) = overflowed_maxima(m, &ydot_max, &z_max) {
            warnings.push(w);
        }
        let lambda = laplace_lambda(m.confidence);
        let (bound, cov) = running.into_sets(n);
        // An open-loop covariance that overflows with A growing: the model is unstable
        // on this interval, and a bound on the a-priori error rightly grows with it.
        let unstable = open_diverged.is_some() && growth_per_step(&inp.dense_a(), n) > 1.0;
        let bound_why = bound_diverged.map(|(k, t, eta_too)| {
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
        let open_why = open_diverged.map(|(k, t)| {
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
            &y_max,
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
            &y_max,
            &z_max,
            "covariance",
            [open_why.as_deref(), None, open_why.as_deref()],
        );
        let traces = build_traces(m, dec, &y_max, &z_max, &mut warnings);
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
            covariance: to_rows(&big_r, n),
            gain: to_rows(&gain_rows(&joseph.gain_t, n, nm), nm),
            predicted_covariance: to_rows(&joseph.r_pred, n),
            eta: eta.clone(),
            zeta: zeta_state.clone(),
            chi: chi.clone(),
            potential_sko: (0..n).map(|i| big_r[i * n + i].max(0.0).sqrt()).collect(),
            open_loop_sko: (0..n).map(|i| p_y[i * n + i].max(0.0).sqrt()).collect(),
            measured_sko: inp.meas_sko.clone(),
            delta_y: eta.iter().map(|x| lambda * x).collect(),
            delta_z: zeta_state.iter().map(|x| lambda * x).collect(),
            delta_x: chi.iter().map(|x| lambda * x).collect(),
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
        let steady_state = steady_at.map(|k| {
            let (r, g) = steady_cov.clone().unwrap_or_default();
            SteadyState {
                reached_at_step: k,
                t: t0 + k as f64 * dt,
                covariance: to_rows(&r, n),
                gain: to_rows(&g, nm),
                shortcut_used: frozen_at.is_some(),
            }
        });
        if bound_why.is_none()
            && let Some(w) = bound_growth(&m.states, &final_, lambda)
        {
            warnings.push(w);
        }
        if let Some((k, t, spread)) = ill_conditioned {
            warnings.push(format!(
                "the measurement noise covariance Γ V Γᵀ is ill-conditioned from step {k} (t = {}): the pivots of its factorisation span up to {:.1e}, so whitening the measurements loses about {:.0} of f64's 16 digits, which the covariance set's R and, more so, the bound set's χ (a product of |I − pC| over the steps) carry; noises this nearly dependent are better given a noise of their own per measurement, or the shared noise modelled as a state",
                crate::text::num(t),
                spread,
                spread.log10().round()
            ));
        }
        if let Some((k, t, i)) = cancelled {
            warnings.push(format!(
                "the filtered variance of \"{}\" fell to ≤ {ROUNDING_LEVEL:e} of its predicted variance at step {k} (t = {}); {cancelled_steps} of the {} steps had a state's at that level: the update cancels it almost exactly — a state measured only through others (its correlation with a measured state, or a row of c that combines states), with an initial or model-error SKO far above what the measurements leave of it — so R's diagonal there keeps fewer than 4 correct digits: the covariance set's ZX and YX at those steps are ratios of rounding errors, and later steps inherit R's error until the filter forgets it",
                m.states[i],
                crate::text::num(t),
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
            y_max,
            ydot_max,
            z_max,
            confidence: m.confidence,
            lambda,
            criteria: CriteriaSets {
                bound: bound_set,
                covariance: cov_set,
                monte_carlo: None,
            },
            final_,
            steady_state,
            traces,
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
