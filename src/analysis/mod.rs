//! The analysis engine (METHOD §1.2–§1.6): Euler discretisation, the Joseph-form
//! Riccati recursion, means, the bound ("modulus") propagation, the exact-covariance
//! propagation, and the criteria accumulated on the fly. Memory does not grow with D.
//!
//! The per-step kernel is generic over a compile-time state dimension `N` (1..=12) so
//! the compiler unrolls and vectorises it; `N = 0` is the runtime-sized fallback.

use crate::Progress;
use crate::analysis::inputs::{Inputs, time_err};
use crate::analysis::result::*;
use crate::analysis::steps::{Selected, select_steps};
use crate::error::Error;
use crate::exec::Memo;
use crate::model::compile::{CompiledModel, StepPlan};
use crate::numerics::decimate::Decimator;
use crate::numerics::lanes::{Lanes, Scalar};
use crate::numerics::linalg::{
    SparseRows, arr, arr_mut, cov_rel_diff, mat, predict_in_place, predict_work,
};
use crate::numerics::riccati;
use crate::numerics::riccati::{Prepared, SequentialJoseph};
use crate::resume::{F, bits, put, values};
use state::LoopState;
pub use state::{SELECTION_KEY, STATE_KEY};
use std::collections::BTreeMap;
use std::ops::ControlFlow;

pub mod inputs;
pub mod kind;
pub mod report;
pub mod result;
mod state;
pub mod steps;
pub mod work;

/// How the warnings about the bound set alone begin (its overflow, its growth far
/// beyond the covariance's interval): they say nothing of the covariance set's
/// criteria, so a synthesis targeting that set leaves them out ([`bound_set_only`]).
const BOUND_WARNING: &str = "the bound (modulus procedure)";

/// The warning concerns the bound set's criteria only.
pub fn bound_set_only(warning: &str) -> bool {
    warning.starts_with(BOUND_WARNING)
}

/// When a loop over steps reports progress: every `every` steps, `every` chosen so
/// that the steps between two reports are about [`WORK_BETWEEN_REPORTS`] by the work
/// estimate (at least 1, at most [`MAX_STEPS_BETWEEN_REPORTS`]). A step of a 200-state
/// model reports every step; one of 2 states every few thousand. The check in the
/// loop is one comparison of the step with the next report's.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Checkpoints {
    next: u64,
    every: u64,
}

impl Checkpoints {
    /// Reports for steps k = 1, 2, … of `step_work` units each.
    pub(crate) fn new(step_work: f64) -> Checkpoints {
        let every = crate::progress::steps_between_reports(step_work);
        Checkpoints { next: every, every }
    }

    /// Reports for the analysis's steps of `model` ([`crate::analysis::work::AnalysisStep`]).
    pub(crate) fn analysis(model: &CompiledModel) -> Checkpoints {
        Checkpoints::new(crate::analysis::work::AnalysisStep::of(model, None).units())
    }

    /// At the step k (called for every k = 1, 2, … in turn), reports `fraction()` done
    /// when a report is due; Err(Cancelled) when the caller cancels.
    #[inline(always)]
    pub(crate) fn at(
        &mut self,
        progress: &mut dyn Progress,
        k: u64,
        fraction: impl FnOnce() -> f64,
    ) -> Result<(), Error> {
        self.reported(progress, k, fraction).map(|_| ())
    }

    /// [`Checkpoints::at`], returning whether it reported.
    #[inline(always)]
    pub(crate) fn reported(
        &mut self,
        progress: &mut dyn Progress,
        k: u64,
        fraction: impl FnOnce() -> f64,
    ) -> Result<bool, Error> {
        if k == self.next {
            self.next += self.every;
            if let ControlFlow::Break(()) = progress.report(fraction()) {
                return Err(Error::Cancelled);
            }
            return Ok(true);
        }
        Ok(false)
    }

    /// Reports for a loop that goes on after step `k` (the first due after it).
    pub(crate) fn after(mut self, k: u64) -> Checkpoints {
        self.next = (k / self.every + 1) * self.every;
        self
    }
}

/// The shortcut freezes the Riccati recursion once r_k is this close (relative) to
/// the stationary solution r∞ of the DARE (rounding keeps a slowly contracting
/// recursion from getting much closer).
const STEADY_TOL: f64 = 1e-13;

/// Run the analysis of a compiled model.
pub fn run(model: &CompiledModel, progress: &mut dyn Progress) -> Result<AnalysisResult, Error> {
    run_resumable(model, progress, &crate::exec::Forgetful)
}

/// [`run`], keeping the step loop's state in `memo` when it asks for it
/// ([`Memo::state_due`]), and going on from a state an earlier run of the same model
/// kept there ([`crate::resume`]): the result is the one an uninterrupted run gives
/// (but for `timing`). A `"steps": "auto"` selection is kept in `memo` once made, and
/// taken from there by a run after a restart instead of made again.
pub fn run_resumable(
    model: &CompiledModel,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
) -> Result<AnalysisResult, Error> {
    let (steps, selection) = match model.steps {
        StepPlan::Fixed(d) => (d, None),
        StepPlan::Auto {
            tolerance,
            initial_steps,
            max_steps,
        } => {
            let kept = memo
                .recall(SELECTION_KEY)
                .and_then(|text| Selected::from_text(&text, tolerance, max_steps));
            let s = match kept {
                Some(s) => s,
                None => {
                    let s = select_steps(model, tolerance, initial_steps, max_steps, progress)?;
                    memo.keep(SELECTION_KEY, &s.to_text());
                    s
                }
            };
            (s.chosen, Some(s.selection))
        }
    };
    let mut result = dispatch(model, steps, false, progress, memo)?;
    if let Some(w) = selection.as_ref().and_then(unconverged) {
        result.warnings.insert(0, w);
    }
    result.warnings.splice(0..0, model.notes.iter().cloned());
    result.step_selection = selection;
    Ok(result)
}

/// The warning for a step selection that stopped at its cap, with the last measured
/// difference and the D it would take: Euler's error halves when D doubles, so the
/// difference falls as 1/D.
fn unconverged(s: &StepSelection) -> Option<String> {
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

/// The filter's covariance recursion alone — (2.1)–(2.7) and the mean (3.3) at every
/// step, with none of the analysis around it (no open-loop covariance, bound,
/// criteria or traces): what a Kalman filter library's covariance pass computes, for
/// timing kea against one on the same recursion (BENCHMARKS.md). Returns R_D and p_D,
/// the analysis's `final.covariance` and `final.gain` bit for bit. Needs a fixed
/// number of steps.
pub fn covariance_recursion(
    model: &CompiledModel,
    progress: &mut dyn Progress,
) -> Result<FinalCovariance, Error> {
    let StepPlan::Fixed(steps) = model.steps else {
        return Err(Error::invalid(
            "time.steps",
            "the covariance recursion alone runs a fixed number of steps, not \"auto\"",
        ));
    };
    let r = dispatch(model, steps, true, progress, &crate::exec::Forgetful)?;
    Ok(FinalCovariance {
        covariance: r.final_.covariance,
        gain: r.final_.gain,
    })
}

/// The engine compiled for the model's state dimension (1..=12, else runtime-sized).
fn dispatch(
    model: &CompiledModel,
    steps: u64,
    covariance_only: bool,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
) -> Result<AnalysisResult, Error> {
    match model.n_states() {
        1 => Engine::<1>::new(model, steps, covariance_only, memo).run(progress),
        2 => Engine::<2>::new(model, steps, covariance_only, memo).run(progress),
        3 => Engine::<3>::new(model, steps, covariance_only, memo).run(progress),
        4 => Engine::<4>::new(model, steps, covariance_only, memo).run(progress),
        5 => Engine::<5>::new(model, steps, covariance_only, memo).run(progress),
        6 => Engine::<6>::new(model, steps, covariance_only, memo).run(progress),
        7 => Engine::<7>::new(model, steps, covariance_only, memo).run(progress),
        8 => Engine::<8>::new(model, steps, covariance_only, memo).run(progress),
        9 => Engine::<9>::new(model, steps, covariance_only, memo).run(progress),
        10 => Engine::<10>::new(model, steps, covariance_only, memo).run(progress),
        11 => Engine::<11>::new(model, steps, covariance_only, memo).run(progress),
        12 => Engine::<12>::new(model, steps, covariance_only, memo).run(progress),
        _ => Engine::<0>::new(model, steps, covariance_only, memo).run(progress),
    }
}

/// The builds of the engine's loop (x86-64).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Build {
    /// AVX-512 F + VL with AVX2 + FMA: the fixed-size loops in 8-lane registers, a
    /// row of up to 8 values in one (masked) operation.
    Avx512,
    /// AVX2 + FMA: the explicit 4-lane row kernels.
    Avx2,
    /// Portable code (SSE2).
    Baseline,
}

/// The widest build this CPU runs, within the ceiling a shell set
/// ([`crate::cpu::limit`]: the tests compare the builds).
#[cfg(target_arch = "x86_64")]
fn build() -> Build {
    use crate::cpu::Limit;
    let limit = crate::cpu::limit();
    if limit == Limit::Baseline
        || !(std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma"))
    {
        Build::Baseline
    } else if limit == Limit::Widest
        && std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
    {
        Build::Avx512
    } else {
        Build::Avx2
    }
}

/// Running sums of one criterion of one state (3.24).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Avg {
    pub(crate) sum: f64,
    pub(crate) count: u64,
    pub(crate) excluded: u64,
}

impl Avg {
    #[inline(always)]
    pub(crate) fn add(&mut self, num: f64, den: f64) {
        let f = num / den;
        if den > 0.0 && f.is_finite() {
            self.sum += f;
            self.count += 1;
        } else {
            self.excluded += 1;
        }
    }
    pub(crate) fn mean(&self) -> Option<f64> {
        (self.count > 0).then(|| self.sum / self.count as f64)
    }
}

/// Accumulated criteria of one set (bound or covariance): ratios η/ζ, ζ/χ, η/χ per
/// state; the constant factors z_B/y_B are applied at the end (y_B is a sup over k).
#[derive(Clone, Debug)]
pub(crate) struct SetSums {
    pub(crate) yz: Vec<Avg>,
    pub(crate) zx: Vec<Avg>,
    pub(crate) yx: Vec<Avg>,
}

/// The running sums (3.24) of the six criteria of every state during a run, as
/// parallel arrays indexed [criterion · n + state] (criteria in the order of the
/// `C_*` constants) so that a step's update is one vectorisable loop.
struct Running {
    sum: Vec<f64>,
    count: Vec<u64>,
    excluded: Vec<u64>,
}

const C_BOUND_YZ: usize = 0;
const C_BOUND_ZX: usize = 1;
const C_BOUND_YX: usize = 2;
const C_COV_YZ: usize = 3;
const C_COV_ZX: usize = 4;
const C_COV_YX: usize = 5;

impl Running {
    fn new(n: usize) -> Self {
        Running {
            sum: vec![0.0; 6 * n],
            count: vec![0; 6 * n],
            excluded: vec![0; 6 * n],
        }
    }

    /// One step: `ratio` holds the six criteria's ratios (laid out as the sums); for
    /// every entry where `part` is 1, a finite ratio counts and any other (NaN where
    /// its denominator is not positive) is an excluded step.
    #[inline(always)]
    fn add(&mut self, ratio: &[f64], part: &[u64]) {
        let len = self.sum.len();
        let (sum, count, excluded) = (
            &mut self.sum[..],
            &mut self.count[..len],
            &mut self.excluded[..len],
        );
        let (ratio, part) = (&ratio[..len], &part[..len]);
        for x in 0..len {
            let f = ratio[x];
            let take = part[x] & u64::from(f.is_finite());
            // + 0.0 leaves a sum alone (a sum of +0.0 and ratios is never −0.0).
            sum[x] += if take != 0 { f } else { 0.0 };
            count[x] += take;
            excluded[x] += part[x] - take;
        }
    }

    /// The bound and the covariance set.
    fn into_sets(self, n: usize) -> (SetSums, SetSums) {
        let avg = |c: usize| -> Vec<Avg> {
            (c * n..c * n + n)
                .map(|x| Avg {
                    sum: self.sum[x],
                    count: self.count[x],
                    excluded: self.excluded[x],
                })
                .collect()
        };
        (
            SetSums {
                yz: avg(C_BOUND_YZ),
                zx: avg(C_BOUND_ZX),
                yx: avg(C_BOUND_YX),
            },
            SetSums {
                yz: avg(C_COV_YZ),
                zx: avg(C_COV_ZX),
                yx: avg(C_COV_YX),
            },
        )
    }
}

/// Series kept in the traces for every state (in this order; a step's row holds
/// series s of state i at s · n + i). The first three are constant once the Riccati
/// recursion is frozen (the shortcut), the last three are the bound set's ratios —
/// followed in the row by the covariance set's, so the six criteria are contiguous.
pub(crate) const SERIES: usize = 10;
const S_ZETA: usize = 0;
const S_POT: usize = 1;
const S_MEAS: usize = 2;
/// The series from here on change every step.
const S_Y: usize = 3;
const S_ETA: usize = 4;
const S_CHI: usize = 5;
const S_OPEN: usize = 6;
const S_RYZ: usize = 7;
const S_RZX: usize = 8;
const S_RYX: usize = 9;

/// A step whose row is written (its trace values and criteria ratios) and how.
#[derive(Clone, Copy)]
struct Written {
    k: u64,
    t: f64,
    bound_ok: bool,
    open_ok: bool,
    /// The row's constant series were written at this step.
    constants: bool,
}

/// Adds a written row to the criteria's sums (with the `part` it was written for)
/// and to the traces.
#[inline(always)]
fn take_row(
    row: &mut [f64],
    part: &[u64],
    running: &mut Running,
    dec: &mut Decimator,
    n: usize,
    w: Written,
) {
    running.add(&row[S_RYZ * n..], part);
    // Series without a value at this step (after the sums: their parts are 0).
    if !w.bound_ok {
        for s in [S_ETA, S_CHI, S_RYZ, S_RZX, S_RYX] {
            row[s * n..s * n + n].fill(f64::NAN);
        }
    }
    if !w.open_ok {
        row[S_OPEN * n..S_OPEN * n + n].fill(f64::NAN);
    }
    dec.begin(w.t);
    if w.constants || dec.bucket_starts() {
        dec.put_row(0, &row[..SERIES * n]);
    } else {
        dec.put_row(S_Y * n, &row[S_Y * n..SERIES * n]);
    }
    dec.end(w.k);
}

struct Engine<'m, const N: usize> {
    m: &'m CompiledModel,
    steps: u64,
    /// N and n (measurements), L, M.
    nn: usize,
    nm: usize,
    dt: f64,
    /// Only the filter's covariance recursion and the mean ([`covariance_recursion`]).
    covariance_only: bool,
    /// Where the loop's state is kept, and an earlier run's found ([`crate::resume`]).
    memo: &'m dyn Memo,
}

impl<'m, const N: usize> Engine<'m, N> {
    fn new(m: &'m CompiledModel, steps: u64, covariance_only: bool, memo: &'m dyn Memo) -> Self {
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
    fn run(&self, progress: &mut dyn Progress) -> Result<AnalysisResult, Error> {
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

/// The warning for maxima that overflowed f64 (reported as null): ẏ_B where a y_k
/// + u overflows with a finite y_k, z_B = Σ|C_ji| y_B,i (1.5) with large entries of C.
fn overflowed_maxima(m: &CompiledModel, ydot_max: &[f64], z_max: &[f64]) -> Option<String> {
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
const ILL_CONDITIONED_RV: f64 = 1e8;

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
fn bound_growth(states: &[String], f: &Final, lambda: f64) -> Option<String> {
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
fn mean_overflowed(
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
fn stationary(
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
fn euler_unstable(a: &[f64], n: usize, dt: f64, span: f64, steps: u64) -> Option<String> {
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
fn not_positive(
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
fn covariance_overflowed(
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
fn growth_per_step(a: &[f64], n: usize) -> f64 {
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
fn lost_precision(k: u64, t: f64, j: u64, t_j: f64, state: &str) -> Error {
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

/// Whether every entry is finite (no early exit, so the loop vectorises).
#[inline(always)]
fn all_finite(v: &[f64]) -> bool {
    v.iter().fold(true, |ok, x| ok & x.is_finite())
}

/// The cheap first test of the steady state: every diagonal entry within `tol`.
#[inline(always)]
fn diag_close(a: &[f64], b: &[f64], n: usize, tol: f64) -> bool {
    (0..n).all(|i| (a[i * n + i] - b[i * n + i]).abs() <= tol * b[i * n + i].abs())
}

/// λ = Φ⁻¹((1+P)/2), the two-sided normal quantile (3.14): the root of
/// erfc(λ/√2) = 1 − P (or, for P < 1/2, of erf(λ/√2) = P), bisected on `libm`'s erfc
/// (erf) down to adjacent floats. A quantile built on the standard library's exp and
/// ln (statrs') differs in its last bits between the native C library and wasm
/// (P = 0.99 did); this one is the same arithmetic on every target. `p` in (0, 1).
pub fn laplace_lambda(p: f64) -> f64 {
    if p < 0.5 {
        // erf keeps its relative accuracy near 0, where 1 − P would round to 1 and
        // λ to 0 (P = 1e-300 gave λ = 0, and ΔY = λη = 0).
        return bisect_root(0.0, 40.0, |x| {
            libm::erf(x * std::f64::consts::FRAC_1_SQRT_2) - p
        });
    }
    // 1 − P is exact for P ≥ 1/2 (Sterbenz), and erfc keeps its relative accuracy in
    // the tail, so λ stays accurate for P near 1.
    let tail = 1.0 - p;
    // erfc(x/√2) falls from 1 at 0 to below f64's smallest 1 − P (2⁻⁵³, P < 1)
    // before x = 40: the root is in the bracket.
    bisect_root(0.0, 40.0, |x| {
        tail - libm::erfc(x * std::f64::consts::FRAC_1_SQRT_2)
    })
}

/// The root of an increasing g in [lo, hi] (g(lo) ≤ 0 ≤ g(hi)), bisected down to
/// adjacent floats; of those two, the one where |g| is smaller. From a fixed bracket
/// this is the same sequence of operations on every target (the quantiles of λ and of
/// the Monte Carlo's χ² bands rely on it for the same bits natively and in wasm).
pub(crate) fn bisect_root(mut lo: f64, mut hi: f64, g: impl Fn(f64) -> f64) -> f64 {
    loop {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if g(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    if g(lo).abs() <= g(hi).abs() { lo } else { hi }
}

/// Averaged (3.24) and weighted (3.25) criteria of one set from its running sums;
/// `invalid[c]` nulls criterion c (yz, zx, yx) for every state with that reason.
pub(crate) fn criteria_set(
    m: &CompiledModel,
    s: &SetSums,
    y_max: &[f64],
    z_max: &[f64],
    set: &str,
    invalid: [Option<&str>; 3],
) -> CriteriaSet {
    let n = m.n_states();
    let mut per_state = Vec::with_capacity(n);
    for i in 0..n {
        let mut undefined = BTreeMap::new();
        let pair = m.pair_of_state[i];
        let yb = y_max[i];
        let zb = pair.map(|j| z_max[j]);
        let mut finish = |name: &str,
                          avg: &Avg,
                          factor: Option<f64>,
                          paired: bool|
         -> Option<f64> {
            if !paired {
                undefined.insert(
                    name.to_string(),
                    format!("state \"{}\" has no paired measurement", m.states[i]),
                );
                return None;
            }
            if yb == 0.0 {
                undefined.insert(
                    name.to_string(),
                    format!("y_B = 0: the mean of \"{}\" is identically zero, so relative errors (3.20) are undefined", m.states[i]),
                );
                return None;
            }
            let Some(factor) = factor else {
                undefined.insert(
                    name.to_string(),
                    "z_B = 0: the mean measurement is identically zero".to_string(),
                );
                return None;
            };
            if !factor.is_finite() {
                let why = if zb.is_some_and(f64::is_finite) {
                    format!(
                        "y_B/z_B or z_B/y_B overflowed f64 (y_B = {yb:e}, z_B = {:e}): the measurement's scale is out of all proportion to the state's",
                        zb.unwrap_or(0.0)
                    )
                } else {
                    "z_B = Σ|C_ji| y_B,i (1.5) overflowed f64, so relative errors (3.20) of the measurement are not numbers".to_string()
                };
                undefined.insert(name.to_string(), why);
                return None;
            }
            match avg.mean() {
                Some(v) if !(v * factor).is_finite() => {
                    undefined.insert(
                        name.to_string(),
                        format!("the {set} set's average (3.24) overflowed f64"),
                    );
                    None
                }
                Some(v) => Some(v * factor),
                None => {
                    undefined.insert(
                        name.to_string(),
                        format!(
                            "every step is excluded in the {set} set (a zero denominator, or no measurement available)"
                        ),
                    );
                    None
                }
            }
        };
        // f^YZ = (η/y_B)/(ζ/z_B) = (η/ζ)(z_B/y_B); f^ZX = (ζ/χ)(y_B/z_B); f^YX = η/χ.
        let f_yz = zb.filter(|z| *z > 0.0).map(|z| z / yb);
        let f_zx = zb.filter(|z| *z > 0.0).map(|z| yb / z);
        let mut yz = finish("yz", &s.yz[i], f_yz, pair.is_some());
        let mut zx = finish("zx", &s.zx[i], f_zx, pair.is_some());
        let mut yx = finish("yx", &s.yx[i], Some(1.0), true);
        for ((name, v), why) in [("yz", &mut yz), ("zx", &mut zx), ("yx", &mut yx)]
            .into_iter()
            .zip(invalid)
        {
            if let Some(why) = why {
                *v = None;
                undefined.insert(name.to_string(), why.to_string());
            }
        }
        per_state.push(StateCriteria {
            state: m.states[i].clone(),
            measurement: pair.map(|j| m.measurements[j].clone()),
            yz,
            zx,
            yx,
            undefined,
            excluded_steps: ExcludedSteps {
                yz: s.yz[i].excluded,
                zx: s.zx[i].excluded,
                yx: s.yx[i].excluded,
            },
        });
    }
    let mut undefined = BTreeMap::new();
    let mut weighted = |name: &str, given: Option<&Vec<f64>>, values: Vec<Option<f64>>| {
        let (w, v) = weighted_sum(given, &values);
        match v {
            Ok(v) => (w, Some(v)),
            Err(why) => {
                let why = why.replace("{state}", "");
                let named = why
                    .split_once('#')
                    .map(|(a, i)| format!("{a}\"{}\"", m.states[i.parse::<usize>().unwrap_or(0)]))
                    .unwrap_or(why);
                undefined.insert(name.to_string(), named);
                (w, None)
            }
        }
    };
    let (w_yz, yz) = weighted(
        "yz",
        m.weights_yz.as_ref(),
        per_state.iter().map(|p| p.yz).collect(),
    );
    let (w_zx, zx) = weighted(
        "zx",
        m.weights_zx.as_ref(),
        per_state.iter().map(|p| p.zx).collect(),
    );
    let (w_yx, yx) = weighted(
        "yx",
        m.weights_yx.as_ref(),
        per_state.iter().map(|p| p.yx).collect(),
    );
    CriteriaSet {
        per_state,
        weighted: Weighted {
            yz,
            zx,
            yx,
            weights: WeightsOut {
                yz: w_yz,
                zx: w_zx,
                yx: w_yx,
            },
            undefined,
        },
    }
}

/// (3.25): F = Σ k_i f_i. Default weights: equal over the states where f_i is defined.
/// Err names (as `#i`) a state with positive weight whose criterion is undefined.
fn weighted_sum(
    given: Option<&Vec<f64>>,
    values: &[Option<f64>],
) -> (Vec<f64>, Result<f64, String>) {
    let n = values.len();
    match given {
        Some(w) => {
            for i in 0..n {
                if w[i] > 0.0 && values[i].is_none() {
                    return (
                        w.clone(),
                        Err(format!(
                            "the criterion is undefined for weighted state #{i}"
                        )),
                    );
                }
            }
            let v = (0..n).map(|i| w[i] * values[i].unwrap_or(0.0)).sum();
            (w.clone(), Ok(v))
        }
        None => {
            let defined = values.iter().filter(|v| v.is_some()).count();
            if defined == 0 {
                return (
                    vec![0.0; n],
                    Err("the criterion is undefined for every state".to_string()),
                );
            }
            let k = 1.0 / defined as f64;
            let w: Vec<f64> = values
                .iter()
                .map(|v| if v.is_some() { k } else { 0.0 })
                .collect();
            let v = values.iter().flatten().map(|x| k * x).sum();
            (w, Ok(v))
        }
    }
}

fn build_traces(
    m: &CompiledModel,
    dec: Decimator,
    y_max: &[f64],
    z_max: &[f64],
    warnings: &mut Vec<String>,
) -> Traces {
    let n = m.n_states();
    let bucket_steps = dec.bucket_steps();
    let Decimator { t, mut columns, .. } = dec;
    let mut take = |i: usize, s: usize| std::mem::take(&mut columns[s * n + i]);
    // y always has a value (a mean that overflows stops the run); every other series
    // is null where it has none (an overflowed bound, an unavailable measurement), and
    // never a stand-in 0.
    let plain = |v: Vec<Option<f64>>| {
        v.into_iter()
            .map(|x| x.unwrap_or(f64::NAN))
            .collect::<Vec<f64>>()
    };
    // Relative errors and local criteria are values over y_B and z_B: with extreme
    // scales (y_B = 1e-300) they can overflow f64; null then, counted for a warning.
    let overflowed = std::cell::Cell::new(0u64);
    let finite = |x: f64| {
        if x.is_finite() {
            Some(x)
        } else {
            overflowed.set(overflowed.get() + 1);
            None
        }
    };
    let scale_opt = |v: Vec<Option<f64>>, f: Option<f64>| -> Vec<Option<f64>> {
        v.into_iter()
            .map(|x| x.zip(f).and_then(|(x, f)| finite(x * f)))
            .collect()
    };
    let mut states = Vec::with_capacity(n);
    let mut overflowing_states = Vec::new();
    for i in 0..n {
        overflowed.set(0);
        let yb = y_max[i];
        let pair = m.pair_of_state[i];
        let zb = pair.map(|j| z_max[j]);
        let y = plain(take(i, S_Y));
        let eta = take(i, S_ETA);
        let chi = take(i, S_CHI);
        let zeta = pair.map(|_| take(i, S_ZETA));
        let measured = pair.map(|_| take(i, S_MEAS));
        let yb_ok = (yb > 0.0).then_some(yb);
        let zb_ok = zb.filter(|z| *z > 0.0);
        let rel = |v: &[Option<f64>], b: Option<f64>| -> Vec<Option<f64>> {
            v.iter()
                .map(|x| x.zip(b).and_then(|(x, b)| finite(x / b)))
                .collect()
        };
        let local_yz =
            pair.map(|_| scale_opt(take(i, S_RYZ), zb_ok.zip(yb_ok).map(|(z, y)| z / y)));
        let local_zx =
            pair.map(|_| scale_opt(take(i, S_RZX), zb_ok.zip(yb_ok).map(|(z, y)| y / z)));
        let local_yx = scale_opt(take(i, S_RYX), yb_ok.map(|_| 1.0));
        states.push(StateTrace {
            state: m.states[i].clone(),
            rel_y: rel(&eta, yb_ok),
            rel_x: rel(&chi, yb_ok),
            rel_z: zeta.as_ref().map(|z| rel(z, zb_ok)),
            y,
            eta,
            zeta,
            chi,
            potential_sko: take(i, S_POT),
            open_loop_sko: take(i, S_OPEN),
            measured_sko: measured,
            local_yz,
            local_zx,
            local_yx,
        });
        if overflowed.get() > 0 {
            overflowing_states.push(format!("\"{}\" ({} values)", m.states[i], overflowed.get()));
        }
    }
    if !overflowing_states.is_empty() {
        warnings.push(format!(
            "trace values of {} overflowed f64 and are null: relative errors (3.20) and local criteria (3.23) are ratios to y_B and z_B, which this model's scales (y_B or z_B tiny against the SKOs, or far apart) put beyond 1.8e308",
            overflowing_states.join(", ")
        ));
    }
    Traces {
        bucket_steps,
        t,
        states,
    }
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
