//! Monte Carlo: real against potential accuracy (METHOD §1.8, seed 000 steps 21–24,
//! seed 004's figure). R imitations of the a-priori state, the measurements and the
//! filter; per step and state, the sample SKOs of the a-priori, measured and filtered
//! errors beside the potential SKO sqrt(diag R_k) and the bound χ_k; the criteria set
//! `monte_carlo`; consistency (average NEES and NIS with their χ² bands, a verdict per
//! state).
//!
//! Design: step-major. Time is cut into chunks of at most [`CHUNK_STEPS`] steps, fewer
//! where a step is costly ([`chunk_steps`]: progress is reported, and a caller can
//! cancel, between chunks). For a chunk,
//! the [`Plan`] runs the Riccati recursion once (it is the same for every run) and
//! stores that chunk's inputs and gains; then every block of runs advances through the
//! chunk (in parallel through an [`Executor`]) and returns per-step sums; the sums are
//! combined in block order. Runs are split into blocks by `runs` alone, never by the
//! thread count, and run r draws from its own ChaCha8 stream (seed, stream r), so the
//! result is bit-identical for a given seed whatever the executor. Memory is
//! O(R·N + blocks·chunk), independent of D.

use crate::analysis::inputs::{Inputs, time_err};
use crate::analysis::result::*;
use crate::analysis::{Avg, SetSums, bisect_root, criteria_set, overflowed};
use crate::error::{Error, FieldError};
use crate::model::compile::CompiledModel;
use crate::numerics::linalg::{cholesky, cholesky_solve, mul, mul_abt_sym, mul_vec};
use crate::{Model, Overrides, Progress};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use std::ops::ControlFlow;

/// Largest accepted number of runs R.
pub const MAX_RUNS: u64 = 100_000;
/// Largest accepted work runs × steps × N² (about a minute on one core at 1e10).
pub const MAX_WORK: f64 = 1e11;
/// Most steps per chunk: the Riccati is computed for a chunk, then all blocks advance.
pub const CHUNK_STEPS: usize = 256;
/// The work of a chunk (the plan's steps and every run's, units of [`crate::work`])
/// at which chunks get shorter than [`CHUNK_STEPS`]: 16 times the analysis's
/// [`crate::progress::WORK_BETWEEN_REPORTS`], ≈ 17 ms of one core (less on several
/// threads), so that handing the blocks to the executor stays a small share of a
/// chunk.
pub const CHUNK_WORK: f64 = crate::progress::WORK_BETWEEN_PARTS;
/// At most this many blocks of runs (more runs make bigger blocks).
const MAX_BLOCKS: usize = 64;
/// At least this many runs per block.
const MIN_BLOCK_RUNS: usize = 32;
/// The most values (R × (2N + 1): each run's Y, X and stream position) a Monte Carlo's
/// kept state may hold for its runs, ≈ 80 MB of JSON: a run with more keeps none and
/// starts over after a restart. (Such a run is short: with R = 100 000 runs, the most,
/// it has N > 20, so at most 2 300 steps under [`MAX_WORK`].)
pub const MAX_STATE_VALUES: usize = 1 << 22;

/// Whether a Monte Carlo of `runs` runs of an N-state model keeps its state
/// ([`MAX_STATE_VALUES`]).
pub fn keeps_state(runs: u64, n: usize) -> bool {
    (runs as f64) * (2 * n + 1) as f64 <= MAX_STATE_VALUES as f64
}

/// Two-sided probability of the χ² acceptance bands.
pub const BAND_PROBABILITY: f64 = 0.95;

pub use crate::exec::{Executor, Sequential};
use crate::exec::{Forgetful, Memo};
use crate::resume::{F, bits, put, values};
pub use state::STATE_KEY;
use state::{BlockState, RowsState, SimulationStamp, SimulationState};

pub mod kind;
pub mod report;
pub use report::traces_csv;
mod state;
pub mod work;

/// What the filter is compared with (METHOD §1.8).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Truth {
    /// Seed 000's reading: the truth is the mean y; measurements are C y + ΓΦ.
    Mean,
    /// The Kalman reading (seed 004): the truth is the imitated process Y;
    /// measurements are C Y + ΓΦ. With it the Riccati R_k is the filter's exact
    /// error covariance.
    Process,
}

/// How the model error F is drawn (METHOD §1.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelError {
    /// F ~ (0, W) drawn afresh at every step.
    White,
    /// F ~ (0, W) drawn once per run: a constant bias.
    Constant,
}

/// The seed of a request that gives none: the same in the API, `kea simulate` and the
/// browser form, so one request gives the same numbers everywhere.
pub const DEFAULT_SEED: u64 = 1;

/// A Monte Carlo request (without the model).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationRequest {
    /// Number of runs R.
    #[serde(deserialize_with = "crate::json::whole_in::<_, _, 2, MAX_RUNS>")]
    pub runs: u64,
    /// Seed of the random streams; the same seed gives bit-identical results
    /// ([`DEFAULT_SEED`] when absent).
    #[serde(default = "default_seed")]
    pub seed: u64,
    #[serde(default = "default_truth")]
    pub truth: Truth,
    #[serde(default = "default_model_error")]
    pub model_error: ModelError,
    /// Rows of the traces (each row: bucket averages); the model's option when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trace_points: Option<usize>,
}

fn default_seed() -> u64 {
    DEFAULT_SEED
}

fn default_truth() -> Truth {
    Truth::Process
}
fn default_model_error() -> ModelError {
    ModelError::White
}

impl SimulationRequest {
    pub fn new(runs: u64, seed: u64) -> Self {
        SimulationRequest {
            runs,
            seed,
            truth: Truth::Process,
            model_error: ModelError::White,
            trace_points: None,
        }
    }
}

/// The Monte Carlo result (JSON via serde).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimulationResult {
    pub request: SimulationRequest,
    pub steps: u64,
    pub dt: f64,
    pub t0: f64,
    pub t_end: f64,
    pub states: Vec<String>,
    pub measurements: Vec<String>,
    /// y_B and z_B (1.5), (3.21) of the analysis, used by every criteria set.
    pub y_max: Vec<f64>,
    pub z_max: Vec<f64>,
    /// The three criteria sets side by side: `bound`, `covariance`, `monte_carlo`.
    pub criteria: CriteriaSets,
    pub consistency: Consistency,
    /// Sample and potential SKOs at the last step D.
    #[serde(rename = "final")]
    pub final_: SimulationFinal,
    pub traces: SimulationTraces,
    pub timing: Timing,
    pub warnings: Vec<String>,
}

/// Consistency of the potential accuracy with the simulated one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Consistency {
    /// Probability of the χ² acceptance bands (two-sided).
    pub band_probability: f64,
    /// Average NEES (1/R) Σ e_kᵀ R_k⁻¹ e_k of the filtered error.
    pub nees: ConsistencyStat,
    /// Average NIS (1/R) Σ ν_kᵀ q_k⁻¹ ν_k of the innovations (available measurements).
    pub nis: ConsistencyStat,
    pub per_state: Vec<StateVerdict>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConsistencyStat {
    /// Degrees of freedom of one run at one step (N for NEES; the number of
    /// available measurements for NIS, here at the last step).
    pub dof: f64,
    /// The statistic averaged over runs and over the steps where it is defined.
    pub time_average: Option<f64>,
    /// The acceptance band of the run-average at one step: χ²_{R·dof} quantiles / R.
    pub band: [f64; 2],
    /// Fraction of the steps whose run-average lies inside its band (≈ the band
    /// probability when consistent; steps are correlated, so it varies).
    pub fraction_in_band: Option<f64>,
    /// Steps where it is undefined (R_k or q_k singular, or nothing measured).
    pub undefined_steps: u64,
    pub verdict: Verdict,
}

/// Per state: the sample variance of the filtered error against R_ii.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StateVerdict {
    pub state: String,
    /// Time average of (sample variance / R_ii) over the steps with R_ii > 0.
    pub variance_ratio: Option<f64>,
    /// The band of one step's ratio for R runs: χ²_R quantiles / R. The time average
    /// of correlated steps is at least as tight, so this band is conservative.
    pub band: [f64; 2],
    /// Fraction of the steps whose ratio lies inside the band.
    pub fraction_in_band: Option<f64>,
    /// Sample mean of the filtered error over runs and steps, in units of sqrt(R_ii)
    /// (a bias check; ≈ 0 when consistent).
    pub normalised_bias: Option<f64>,
    pub verdict: Verdict,
}

/// Plain verdict: is the potential (Riccati) accuracy believable?
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// The real errors agree with the potential ones.
    Consistent,
    /// The real errors are larger than the potential ones: the Riccati promises more.
    Optimistic,
    /// The real errors are smaller than the potential ones.
    Pessimistic,
    /// Nothing to judge (no step where the statistic is defined).
    Undefined,
}

impl Verdict {
    fn of(value: Option<f64>, band: [f64; 2]) -> Verdict {
        match value {
            None => Verdict::Undefined,
            Some(v) if v > band[1] => Verdict::Optimistic,
            Some(v) if v < band[0] => Verdict::Pessimistic,
            Some(_) => Verdict::Consistent,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimulationFinal {
    /// Sample SKOs at step D: a-priori (Y − y), measured (paired; null if the
    /// measurement is not available at D), filtered (X − truth).
    pub a_priori_sko: Vec<f64>,
    pub measured_sko: Vec<Option<f64>>,
    pub filtered_sko: Vec<f64>,
    /// sqrt(diag R_D) and the bound χ_D (3.19).
    pub potential_sko: Vec<f64>,
    pub chi: Vec<f64>,
}

/// Traces: each row is the average over a bucket of `bucket_steps` steps (variances
/// are averaged, then square-rooted), at the bucket's last time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimulationTraces {
    pub bucket_steps: u64,
    pub t: Vec<f64>,
    pub states: Vec<SimulationStateTrace>,
    /// Average NEES per row (null where undefined) and its per-step band.
    pub nees: Vec<Option<f64>>,
    pub nis: Vec<Option<f64>>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimulationStateTrace {
    pub state: String,
    /// Sample SKO of the a-priori error Y − y.
    pub a_priori_sko: Vec<f64>,
    /// Exact open-loop SKO sqrt(P^Y_ii) (what a_priori_sko estimates).
    pub open_loop_sko: Vec<f64>,
    /// Sample SKO of the paired measurement's error ΓΦ (null rows: not available).
    pub measured_sko: Option<Vec<Option<f64>>>,
    /// Sample SKO and sample mean of the filtered error X − truth.
    pub filtered_sko: Vec<f64>,
    pub filtered_mean: Vec<f64>,
    /// Potential SKO sqrt(R_ii) and the bound χ (3.19).
    pub potential_sko: Vec<f64>,
    pub chi: Vec<f64>,
}

/// Validate a request against a compiled model (paths: `runs`, `trace_points`, …).
pub fn check_request(req: &SimulationRequest, model: &CompiledModel) -> Result<(), Error> {
    let mut errs = Vec::new();
    if req.runs < 2 {
        errs.push(FieldError::new(
            "runs",
            "at least 2 runs are needed for sample SKOs",
        ));
    } else if req.runs > MAX_RUNS {
        errs.push(FieldError::new(
            "runs",
            format!("{} runs is more than the limit of {MAX_RUNS}", req.runs),
        ));
    }
    let max_rows = crate::model::limits::max_trace_rows(model.n_states() * T_SERIES + 2);
    if let Some(tp) = req.trace_points
        && !(2..=max_rows).contains(&tp)
    {
        errs.push(FieldError::new(
            "trace_points",
            format!(
                "expected 2 to {max_rows} rows (at most {} values in all), got {tp}",
                crate::model::limits::MAX_TRACE_VALUES
            ),
        ));
    }
    let w = work(req.runs, model.max_steps(), model.n_states());
    if errs.is_empty() && w > MAX_WORK {
        errs.push(FieldError::new(
            "runs",
            format!(
                "runs × steps × N² = {} × {} × {} = {w:.3e} is more than the limit of {MAX_WORK:.0e}; use fewer runs or steps",
                req.runs,
                model.max_steps(),
                model.n_states().pow(2)
            ),
        ));
    }
    if errs.is_empty() {
        Ok(())
    } else {
        Err(Error::Invalid(errs))
    }
}

/// runs × steps × N²: the simulation's cost in multiply-adds, up to a constant.
pub fn work(runs: u64, steps: u64, n: usize) -> f64 {
    runs as f64 * steps as f64 * (n * n) as f64
}

/// Validate, analyse (for the `bound` and `covariance` sets and y_B), and simulate.
pub fn simulate<E: Executor>(
    model: &Model,
    set: &Overrides,
    req: &SimulationRequest,
    exec: &E,
    progress: &mut dyn Progress,
) -> Result<SimulationResult, Error> {
    simulate_resumable(model, set, req, exec, progress, &Forgetful)
}

/// [`simulate`], keeping the analysis's and the runs' states in `memo` when it asks
/// for them ([`Memo::state_due`]), and going on from states an earlier run of the
/// same request kept there ([`crate::resume`]): the result is the one an
/// uninterrupted run gives (but for `timing`).
pub fn simulate_resumable<E: Executor>(
    model: &Model,
    set: &Overrides,
    req: &SimulationRequest,
    exec: &E,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
) -> Result<SimulationResult, Error> {
    let compiled = crate::model::compile::compile(model, set)?;
    simulate_compiled(&compiled, req, exec, progress, memo)
}

/// [`simulate_resumable`] of a compiled model: its analysis (the first 5 % of the
/// progress), then the runs.
pub fn simulate_compiled<E: Executor>(
    compiled: &CompiledModel,
    req: &SimulationRequest,
    exec: &E,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
) -> Result<SimulationResult, Error> {
    check_request(req, compiled)?;
    // The analysis takes a small share of the work; report it as the first 5 %.
    let mut scaled = |f: f64| progress.report(0.05 * f);
    let analysis = crate::analysis::run_resumable(compiled, &mut scaled, memo)?;
    let mut rest = |f: f64| progress.report(0.05 + 0.95 * f);
    run_resumable(compiled, &analysis, req, exec, &mut rest, memo)
}

/// Simulate a compiled model, given its analysis (D, y_B, z_B, the other sets).
pub fn run<E: Executor>(
    model: &CompiledModel,
    analysis: &AnalysisResult,
    req: &SimulationRequest,
    exec: &E,
    progress: &mut dyn Progress,
) -> Result<SimulationResult, Error> {
    run_resumable(model, analysis, req, exec, progress, &Forgetful)
}

/// [`run`], keeping the runs' state in `memo` between chunks when it asks for it, and
/// going on from a state kept there ([`simulate_resumable`]).
pub fn run_resumable<E: Executor>(
    model: &CompiledModel,
    analysis: &AnalysisResult,
    req: &SimulationRequest,
    exec: &E,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
) -> Result<SimulationResult, Error> {
    check_request(req, model)?;
    let chunk = chunk_steps(model, req);
    match model.n_states() {
        1 => run_n::<1, E>(model, analysis, req, exec, progress, memo, chunk),
        2 => run_n::<2, E>(model, analysis, req, exec, progress, memo, chunk),
        3 => run_n::<3, E>(model, analysis, req, exec, progress, memo, chunk),
        4 => run_n::<4, E>(model, analysis, req, exec, progress, memo, chunk),
        5 => run_n::<5, E>(model, analysis, req, exec, progress, memo, chunk),
        6 => run_n::<6, E>(model, analysis, req, exec, progress, memo, chunk),
        7 => run_n::<7, E>(model, analysis, req, exec, progress, memo, chunk),
        8 => run_n::<8, E>(model, analysis, req, exec, progress, memo, chunk),
        _ => run_n::<0, E>(model, analysis, req, exec, progress, memo, chunk),
    }
}

/// Steps per chunk: as many as make [`CHUNK_WORK`] by the work estimate of a step
/// (the plan's, [`crate::monte_carlo::work::simulation_plan_step`], and every run's,
/// [`crate::monte_carlo::work::simulation_run_step`]), 1 to [`CHUNK_STEPS`]. A chunk's length never
/// changes a result (each run's stream and sums go on across chunks).
pub fn chunk_steps(model: &CompiledModel, req: &SimulationRequest) -> usize {
    let step = crate::monte_carlo::work::simulation_plan_step(model, None)
        + req.runs as f64 * crate::monte_carlo::work::simulation_run_step(model, req.model_error);
    crate::work::fitting(CHUNK_WORK, step, CHUNK_STEPS as u64) as usize
}

/// Dimensions shared by the plan and the blocks.
#[derive(Clone, Copy, Debug)]
struct Dims {
    n: usize,
    nm: usize,
    nl: usize,
    ms: usize,
}

/// Layout of one step's inputs in a chunk (offsets into a flat f64 record).
#[derive(Clone, Copy, Debug)]
struct Layout {
    a: usize,      // A_{k−1}, N×N
    u: usize,      // u_{k−1}Δt, N
    bd: usize,     // b_{k−1}Δt, N×L
    gamma: usize,  // Γ_k, n×M
    gain: usize,   // p_k, N×n (zero columns for unavailable measurements)
    avail: usize,  // n flags (1.0 / 0.0)
    y: usize,      // mean y_k, N
    r_chol: usize, // Cholesky factor of R_k, N×N (valid if flag), 1/L_ii on the diagonal
    q_chol: usize, // Cholesky factor of q_k, masked, n×n, 1/L_ii on the diagonal
    flags: usize,  // [R_k factor valid, q_k factor valid, measurements available]
    size: usize,
}

impl Layout {
    fn new(d: Dims) -> Self {
        let mut o = 0;
        let mut take = |len: usize| {
            let at = o;
            o += len;
            at
        };
        let a = take(d.n * d.n);
        let u = take(d.n);
        let bd = take(d.n * d.nl);
        let gamma = take(d.nm * d.ms);
        let gain = take(d.n * d.nm);
        let avail = take(d.nm);
        let y = take(d.n);
        let r_chol = take(d.n * d.n);
        let q_chol = take(d.nm * d.nm);
        let flags = take(3);
        Layout {
            a,
            u,
            bd,
            gamma,
            gain,
            avail,
            y,
            r_chol,
            q_chol,
            flags,
            size: o,
        }
    }
}

/// Per-step sums a block returns, per step: Σ(Y−y)²_i, Σe²_i, Σe_i (N each),
/// Σ(ΓΦ)²_j (n), Σ NEES, Σ NIS.
#[derive(Clone, Copy, Debug)]
struct SumLayout {
    apriori: usize,
    filt2: usize,
    filt1: usize,
    meas2: usize,
    nees: usize,
    nis: usize,
    size: usize,
}

impl SumLayout {
    fn new(d: Dims) -> Self {
        SumLayout {
            apriori: 0,
            filt2: d.n,
            filt1: 2 * d.n,
            meas2: 3 * d.n,
            nees: 3 * d.n + d.nm,
            nis: 3 * d.n + d.nm + 1,
            size: 3 * d.n + d.nm + 2,
        }
    }
}

/// The deterministic part, advanced once per step for all runs: time functions, the
/// mean (3.3), the Riccati recursion (2.1)–(2.7) with the schedule, the bound
/// (3.16)–(3.19) and the open-loop covariance.
struct Plan<'m> {
    m: &'m CompiledModel,
    d: Dims,
    dt: f64,
    /// A = I + aΔt (dense here), uΔt, bΔt, B, Γ, Rv, ζ: the analysis' inputs.
    inp: Inputs,
    schedule: Option<crate::model::schedule::Schedules>,
    big_a: Vec<f64>,
    y: Vec<f64>,
    big_r: Vec<f64>,
    p_y: Vec<f64>,
    chi: Vec<f64>,
    gain: Vec<f64>,
    avail: Vec<bool>,
    // work buffers
    tmp_nn: Vec<f64>,
    tmp_nn2: Vec<f64>,
    r_pred: Vec<f64>,
    s_cr: Vec<f64>,
    q: Vec<f64>,
    x_solve: Vec<f64>,
    xi: Vec<f64>,
    tmp_n: Vec<f64>,
    /// Whether the next step is the first of this run (from the start, or from a kept
    /// state): its inputs are then evaluated whole.
    fresh: bool,
}

impl<'m> Plan<'m> {
    fn new(m: &'m CompiledModel, steps: u64) -> Self {
        let n = m.n_states();
        let d = Dims {
            n,
            nm: m.n_measurements(),
            nl: m.b.cols,
            ms: m.noise.sources(),
        };
        let mut big_r = vec![0.0; n * n];
        for i in 0..n {
            big_r[i * n + i] = m.eta0[i] * m.eta0[i];
        }
        let dt = (m.t_end - m.t0) / steps as f64;
        Plan {
            m,
            d,
            dt,
            inp: Inputs::new(m, n, dt),
            schedule: m.schedule.clone(),
            big_a: vec![0.0; n * n],
            y: m.y0.clone(),
            p_y: big_r.clone(),
            big_r,
            chi: vec![0.0; n],
            gain: vec![0.0; n * d.nm],
            avail: vec![true; d.nm],
            tmp_nn: vec![0.0; n * n],
            tmp_nn2: vec![0.0; n * n],
            r_pred: vec![0.0; n * n],
            s_cr: vec![0.0; d.nm * n],
            q: vec![0.0; d.nm * d.nm],
            x_solve: vec![0.0; d.nm * n],
            xi: vec![0.0; n],
            tmp_n: vec![0.0; n],
            fresh: true,
        }
    }

    /// Advance to step k and write its record (layout `lay`) into `rec`.
    fn step(&mut self, k: u64, lay: &Layout, rec: &mut [f64]) -> Result<(), Error> {
        let Dims { n, nm, nl, ms } = self.d;
        let m = self.m;
        let dt = self.dt;
        let t_k = m.t0 + k as f64 * dt;
        // (1.11)–(1.15): A, uΔt, bΔt at t_{k−1}; Γ at t_k — the analysis' inputs.
        let whole = std::mem::replace(&mut self.fresh, false);
        let a_changed = whole || !self.inp.a_fn.is_constant();
        self.inp.at(m, k, whole)?;
        if a_changed {
            self.inp.dense_a_into(&mut self.big_a);
        }
        // The measurement schedule at step k (time t_k).
        if let Some(sched) = &mut self.schedule {
            sched
                .mask(k, t_k, &mut self.avail)
                .map_err(|p| time_err(&p, k, t_k))?;
        }
        let n_avail = self.avail.iter().filter(|a| **a).count();

        // (3.3) y_k = A y + uΔt
        mul_vec(&mut self.tmp_n, &self.big_a, &self.y, n, n);
        for i in 0..n {
            self.y[i] = self.tmp_n[i] + self.inp.u_dt[i];
        }
        // (2.1) r = A R Aᵀ + B
        mul(&mut self.tmp_nn, &self.big_a, &self.big_r, n, n, n);
        mul_abt_sym(
            &mut self.r_pred,
            &self.tmp_nn,
            &self.big_a,
            Some(&self.inp.big_b),
            n,
            n,
        );
        // S = C r; (2.3) q = S Cᵀ + Rv. An unavailable measurement j gets S_j = 0 and
        // q_jj = 1 with no coupling: its gain column is then exactly zero and the
        // other columns are the Kalman gain of the available measurements alone.
        self.s_cr.fill(0.0);
        for &(j, i, c) in &self.inp.c_nz {
            if self.avail[j] {
                for (s, r) in self.s_cr[j * n..j * n + n]
                    .iter_mut()
                    .zip(&self.r_pred[i * n..i * n + n])
                {
                    *s += c * r;
                }
            }
        }
        self.q.copy_from_slice(&self.inp.rv);
        for &(l, i, c) in &self.inp.c_nz {
            for j in 0..nm {
                self.q[j * nm + l] += c * self.s_cr[j * n + i];
            }
        }
        for j in 0..nm {
            if !self.avail[j] {
                for l in 0..nm {
                    self.q[j * nm + l] = 0.0;
                    self.q[l * nm + j] = 0.0;
                }
                self.q[j * nm + j] = 1.0;
            }
        }
        let q_ok = nm == 0 || cholesky(&mut self.q, nm);
        if !q_ok {
            return Err(crate::analysis::singular(k, t_k));
        }
        // (2.5) pᵀ = q⁻¹ S
        self.x_solve.copy_from_slice(&self.s_cr);
        if nm > 0 {
            cholesky_solve(&self.q, &mut self.x_solve, nm, n);
        }
        for i in 0..n {
            for j in 0..nm {
                self.gain[i * nm + j] = self.x_solve[j * n + i];
            }
        }
        // (2.7) Joseph form R = h r hᵀ + p Rv pᵀ, h = I − pC (available columns only:
        // unavailable gain columns are zero, so they drop out of both terms).
        // h
        for i in 0..n {
            for j in 0..n {
                self.tmp_nn[i * n + j] = if i == j { 1.0 } else { 0.0 };
            }
        }
        for &(l, j, c) in &self.inp.c_nz {
            for i in 0..n {
                self.tmp_nn[i * n + j] -= self.gain[i * nm + l] * c;
            }
        }
        mul(&mut self.tmp_nn2, &self.tmp_nn, &self.r_pred, n, n, n); // h r
        mul_abt_sym(&mut self.big_r, &self.tmp_nn2, &self.tmp_nn, None, n, n); // h r hᵀ
        if nm > 0 {
            let mut prv = vec![0.0; n * nm];
            mul(&mut prv, &self.gain, &self.inp.rv, n, nm, nm);
            let mut add = vec![0.0; n * n];
            mul_abt_sym(&mut add, &prv, &self.gain, None, n, nm);
            for (r, a) in self.big_r.iter_mut().zip(&add) {
                *r += a;
            }
        }
        // P^Y = A P Aᵀ + B
        mul(&mut self.tmp_nn2, &self.big_a, &self.p_y, n, n, n);
        mul_abt_sym(
            &mut self.p_y,
            &self.tmp_nn2,
            &self.big_a,
            Some(&self.inp.big_b),
            n,
            n,
        );
        // Bound (3.18)–(3.19): ξ = |A| χ, χ = |h| ξ + |p| ζ
        for i in 0..n {
            self.xi[i] = (0..n)
                .map(|j| self.big_a[i * n + j].abs() * self.chi[j])
                .sum();
        }
        for i in 0..n {
            let mut s: f64 = (0..n)
                .map(|j| self.tmp_nn[i * n + j].abs() * self.xi[j])
                .sum();
            for j in 0..nm {
                s += self.gain[i * nm + j].abs() * self.inp.zeta[j];
            }
            self.chi[i] = s;
        }
        if !self.big_r.iter().all(|v| v.is_finite()) || !self.y.iter().all(|v| v.is_finite()) {
            return Err(overflowed(
                "the filtered covariance or the mean",
                "system",
                k,
                t_k,
            ));
        }

        // The record for the blocks.
        rec[lay.a..lay.a + n * n].copy_from_slice(&self.big_a);
        rec[lay.u..lay.u + n].copy_from_slice(&self.inp.u_dt);
        rec[lay.bd..lay.bd + n * nl].copy_from_slice(&self.inp.bd);
        rec[lay.gamma..lay.gamma + nm * ms].copy_from_slice(&self.inp.gamma);
        rec[lay.gain..lay.gain + n * nm].copy_from_slice(&self.gain);
        for j in 0..nm {
            rec[lay.avail + j] = if self.avail[j] { 1.0 } else { 0.0 };
        }
        rec[lay.y..lay.y + n].copy_from_slice(&self.y);
        let rc = &mut rec[lay.r_chol..lay.r_chol + n * n];
        rc.copy_from_slice(&self.big_r);
        let r_ok = cholesky(rc, n);
        // Reciprocal diagonals: the per-run solves multiply instead of divide.
        if r_ok {
            for i in 0..n {
                rc[i * n + i] = 1.0 / rc[i * n + i];
            }
        }
        let qc = &mut rec[lay.q_chol..lay.q_chol + nm * nm];
        qc.copy_from_slice(&self.q);
        if n_avail > 0 {
            for j in 0..nm {
                qc[j * nm + j] = 1.0 / qc[j * nm + j];
            }
        }
        rec[lay.flags] = if r_ok { 1.0 } else { 0.0 };
        rec[lay.flags + 1] = if n_avail > 0 { 1.0 } else { 0.0 };
        rec[lay.flags + 2] = n_avail as f64;
        Ok(())
    }
}

/// A block of runs: their imitated states and filters, and their random streams.
struct Block {
    runs: usize,
    /// Y (imitated a-priori state), X (estimate), F (constant model error), each
    /// runs × dim.
    y: Vec<f64>,
    x: Vec<f64>,
    f_const: Vec<f64>,
    rngs: Vec<ChaCha8Rng>,
}

/// Read-only inputs shared by all blocks in a chunk.
struct Shared<'a> {
    d: Dims,
    lay: Layout,
    sl: SumLayout,
    truth: Truth,
    model_error: ModelError,
    c_nz: &'a [(usize, usize, f64)],
    /// Entries of A = I + aΔt, bΔt and Γ that can be non-zero (row, col): the
    /// per-run products skip the structural zeros.
    a_nz: &'a [(usize, usize)],
    bd_nz: &'a [(usize, usize)],
    g_nz: &'a [(usize, usize)],
    /// Lower-triangular square roots of W (L×L) and V (M×M).
    w_sqrt: &'a [f64],
    v_sqrt: &'a [f64],
}

#[inline(always)]
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

/// z = S ξ with S lower-triangular (dim×dim), ξ standard normal.
#[inline(always)]
fn draw(rng: &mut ChaCha8Rng, s: &[f64], dim: usize, xi: &mut [f64], z: &mut [f64]) {
    for v in xi[..dim].iter_mut() {
        *v = normal(rng);
    }
    for i in 0..dim {
        let mut acc = 0.0;
        for j in 0..=i {
            acc += s[i * dim + j] * xi[j];
        }
        z[i] = acc;
    }
}

impl Block {
    fn new(first_run: u64, runs: usize, seed: u64, m: &CompiledModel, sh: &Shared) -> Self {
        let Dims { n, nl, .. } = sh.d;
        let mut y = vec![0.0; runs * n];
        let x: Vec<f64> = (0..runs).flat_map(|_| m.y0.iter().copied()).collect();
        let mut f_const = vec![0.0; runs * nl];
        let mut xi = vec![0.0; nl.max(n)];
        let mut rngs = Vec::with_capacity(runs);
        for r in 0..runs {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(first_run + r as u64);
            // Y_0 ~ (y0, diag η0²) (step 7), then the constant model error if any.
            for i in 0..n {
                y[r * n + i] = m.y0[i] + m.eta0[i] * normal(&mut rng);
            }
            if sh.model_error == ModelError::Constant {
                let mut f = vec![0.0; nl];
                draw(&mut rng, sh.w_sqrt, nl, &mut xi, &mut f);
                f_const[r * nl..r * nl + nl].copy_from_slice(&f);
            }
            rngs.push(rng);
        }
        Block {
            runs,
            y,
            x,
            f_const,
            rngs,
        }
    }

    /// The block's state ([`crate::resume`]).
    fn state(&self) -> BlockState {
        BlockState {
            y: bits(&self.y),
            x: bits(&self.x),
            // (2⁶⁴ words of one stream are beyond any run: a position is a u64.)
            word_pos: self.rngs.iter().map(|r| r.get_word_pos() as u64).collect(),
        }
    }

    /// The block as `kept`: a new block of the same runs (its constant model errors
    /// drawn as they were), where the kept one had gone.
    fn restore(&mut self, kept: &BlockState) {
        self.y = values(&kept.y);
        self.x = values(&kept.x);
        for (r, &pos) in self.rngs.iter_mut().zip(&kept.word_pos) {
            r.set_word_pos(u128::from(pos));
        }
    }

    /// Advance every run through a chunk of `steps` records; return the per-step sums
    /// (steps × `SumLayout::size`).
    ///
    /// Run-minor ("structure of arrays"): every quantity is stored as dim × runs, so
    /// each product is a loop over the block's runs that the compiler vectorises. Each
    /// run still draws from its own stream in the same order (F, then Φ, per step), and
    /// the per-step sums run over the runs in order: results do not depend on threads.
    fn advance<const N: usize>(&mut self, sh: &Shared, chunk: &[f64], steps: usize) -> Vec<f64> {
        let d = sh.d;
        let n = if N == 0 { d.n } else { N };
        let (nm, nl, ms) = (d.nm, d.nl, d.ms);
        let nr = self.runs;
        let lay = sh.lay;
        let sl = sh.sl;
        let mut sums = vec![0.0; steps * sl.size];
        // dim × runs buffers
        let soa = |aos: &[f64], dim: usize| -> Vec<f64> {
            let mut v = vec![0.0; dim * nr];
            for r in 0..nr {
                for i in 0..dim {
                    v[i * nr + r] = aos[r * dim + i];
                }
            }
            v
        };
        let mut ys = soa(&self.y, n);
        let mut xs = soa(&self.x, n);
        let mut f = soa(&self.f_const, nl);
        let mut y_new = vec![0.0; n * nr];
        let mut phi = vec![0.0; ms * nr];
        let mut noise = vec![0.0; nm * nr];
        let mut h = vec![0.0; n * nr];
        let mut nu = vec![0.0; nm * nr];
        let mut e = vec![0.0; n * nr];
        let mut mean = vec![0.0; if sh.truth == Truth::Mean { n * nr } else { 0 }];
        let mut w = vec![0.0; n.max(nm) * nr];
        let mut norm2 = vec![0.0; nr];
        let mut xi = vec![0.0; nl.max(ms)];
        let mut one = vec![0.0; nl.max(ms)];
        for s in 0..steps {
            let rec = &chunk[s * lay.size..(s + 1) * lay.size];
            let out = &mut sums[s * sl.size..(s + 1) * sl.size];
            let a = &rec[lay.a..lay.a + n * n];
            let u = &rec[lay.u..lay.u + n];
            let bd = &rec[lay.bd..lay.bd + n * nl];
            let ym = &rec[lay.y..lay.y + n];
            let gamma = &rec[lay.gamma..lay.gamma + nm * ms];
            let gain = &rec[lay.gain..lay.gain + n * nm];
            // Draws, run by run: F (white model error), then Φ.
            for (r, rng) in self.rngs.iter_mut().enumerate() {
                if sh.model_error == ModelError::White {
                    draw(rng, sh.w_sqrt, nl, &mut xi, &mut one);
                    for l in 0..nl {
                        f[l * nr + r] = one[l];
                    }
                }
                draw(rng, sh.v_sqrt, ms, &mut xi, &mut one);
                for l in 0..ms {
                    phi[l * nr + r] = one[l];
                }
            }
            // Step 21: Y_k = A Y + uΔt + bΔt F.
            for i in 0..n {
                y_new[i * nr..(i + 1) * nr].fill(u[i]);
            }
            for &(i, j) in sh.a_nz {
                axpy(&mut y_new, i, &ys, j, a[i * n + j], nr);
            }
            for &(i, l) in sh.bd_nz {
                axpy(&mut y_new, i, &f, l, bd[i * nl + l], nr);
            }
            std::mem::swap(&mut ys, &mut y_new);
            let truth: &[f64] = match sh.truth {
                Truth::Process => &ys,
                Truth::Mean => {
                    for i in 0..n {
                        mean[i * nr..(i + 1) * nr].fill(ym[i]);
                    }
                    &mean
                }
            };
            // Step 22: Z_k = C·truth + Γ_k Φ (Φ drawn every step, used where available).
            noise.fill(0.0);
            for &(j, l) in sh.g_nz {
                axpy(&mut noise, j, &phi, l, gamma[j * ms + l], nr);
            }
            // (2.8) H = A X + uΔt; (2.10) X = H + p (Z − C H)
            for i in 0..n {
                h[i * nr..(i + 1) * nr].fill(u[i]);
            }
            for &(i, j) in sh.a_nz {
                axpy(&mut h, i, &xs, j, a[i * n + j], nr);
            }
            nu.copy_from_slice(&noise);
            for &(j, i, c) in sh.c_nz {
                let (t, hh) = (&truth[i * nr..(i + 1) * nr], &h[i * nr..(i + 1) * nr]);
                for ((v, t), hh) in nu[j * nr..(j + 1) * nr].iter_mut().zip(t).zip(hh) {
                    *v += c * (t - hh);
                }
            }
            for j in 0..nm {
                if rec[lay.avail + j] == 0.0 {
                    nu[j * nr..(j + 1) * nr].fill(0.0);
                }
            }
            xs.copy_from_slice(&h);
            for i in 0..n {
                for j in 0..nm {
                    let g = gain[i * nm + j];
                    if g != 0.0 {
                        axpy(&mut xs, i, &nu, j, g, nr);
                    }
                }
            }
            // Errors and their sums (over the runs, in order).
            for i in 0..n {
                let (yi, xi_, ti) = (
                    &ys[i * nr..(i + 1) * nr],
                    &xs[i * nr..(i + 1) * nr],
                    &truth[i * nr..(i + 1) * nr],
                );
                let ei = &mut e[i * nr..(i + 1) * nr];
                for r in 0..nr {
                    let ea = yi[r] - ym[i];
                    out[sl.apriori + i] += ea * ea;
                    let er = xi_[r] - ti[r];
                    ei[r] = er;
                    out[sl.filt2 + i] += er * er;
                    out[sl.filt1 + i] += er;
                }
            }
            for j in 0..nm {
                for v in &noise[j * nr..(j + 1) * nr] {
                    out[sl.meas2 + j] += v * v;
                }
            }
            // NEES = ‖L⁻¹ e‖² with R_k = L Lᵀ.
            if rec[lay.flags] != 0.0 {
                forward_norm2(&rec[lay.r_chol..], &e, &mut w, &mut norm2, n, nr);
                for v in &norm2 {
                    out[sl.nees] += v;
                }
            }
            // NIS = ‖Lq⁻¹ ν‖² (ν = 0 for unavailable measurements, q masked).
            if rec[lay.flags + 1] != 0.0 {
                forward_norm2(&rec[lay.q_chol..], &nu, &mut w, &mut norm2, nm, nr);
                for v in &norm2 {
                    out[sl.nis] += v;
                }
            }
        }
        // back to runs × dim
        for r in 0..nr {
            for i in 0..n {
                self.y[r * n + i] = ys[i * nr + r];
                self.x[r * n + i] = xs[i * nr + r];
            }
        }
        sums
    }
}

/// Row i of `dst` += v · row j of `src` (both dim × len).
#[inline(always)]
fn axpy(dst: &mut [f64], i: usize, src: &[f64], j: usize, v: f64, len: usize) {
    for (d, s) in dst[i * len..(i + 1) * len]
        .iter_mut()
        .zip(&src[j * len..(j + 1) * len])
    {
        *d += v * s;
    }
}

/// out[r] = ‖L⁻¹ v_r‖² for every run r (v, w: dim × runs) with L lower-triangular
/// (dim×dim, row-major) stored with 1/L_ii on its diagonal.
#[inline(always)]
fn forward_norm2(l: &[f64], v: &[f64], w: &mut [f64], out: &mut [f64], dim: usize, nr: usize) {
    out.fill(0.0);
    for i in 0..dim {
        let (done, rest) = w.split_at_mut(i * nr);
        let wi = &mut rest[..nr];
        wi.copy_from_slice(&v[i * nr..(i + 1) * nr]);
        for k in 0..i {
            let lik = l[i * dim + k];
            for (x, y) in wi.iter_mut().zip(&done[k * nr..(k + 1) * nr]) {
                *x -= lik * y;
            }
        }
        let d = l[i * dim + i];
        for (x, o) in wi.iter_mut().zip(out.iter_mut()) {
            *x *= d;
            *o += *x * *x;
        }
    }
}

/// Lower-triangular S with S Sᵀ = cov for a positive semi-definite cov (dim×dim):
/// Cholesky, with a zero column where a pivot is zero (a degenerate direction).
fn sqrt_psd(cov: &[f64], dim: usize) -> Vec<f64> {
    let mut l = vec![0.0; dim * dim];
    let scale = (0..dim).map(|i| cov[i * dim + i].abs()).fold(0.0, f64::max);
    for j in 0..dim {
        let mut d = cov[j * dim + j];
        for k in 0..j {
            d -= l[j * dim + k] * l[j * dim + k];
        }
        if d <= 1e-14 * scale {
            continue; // column j stays zero
        }
        let d = d.sqrt();
        l[j * dim + j] = d;
        for i in j + 1..dim {
            let mut s = cov[i * dim + j];
            for k in 0..j {
                s -= l[i * dim + k] * l[j * dim + k];
            }
            l[i * dim + j] = s / d;
        }
    }
    l
}

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
fn chi2_quantile(dof: f64, p: f64) -> f64 {
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

/// Bucket averages of variances for the traces.
struct Rows {
    bucket: u64,
    steps: u64,
    series: usize,
    sum: Vec<f64>,
    count: Vec<u64>,
    in_bucket: u64,
    t: Vec<f64>,
    cols: Vec<Vec<Option<f64>>>,
}

impl Rows {
    fn new(steps: u64, series: usize, max_rows: usize) -> Self {
        let bucket = steps.div_ceil(max_rows.max(1) as u64).max(1);
        Rows {
            bucket,
            steps,
            series,
            sum: vec![0.0; series],
            count: vec![0; series],
            in_bucket: 0,
            t: Vec::new(),
            cols: vec![Vec::new(); series],
        }
    }
    fn put(&mut self, s: usize, v: f64) {
        self.sum[s] += v;
        self.count[s] += 1;
    }
    /// The rows' state ([`crate::resume`]).
    fn state(&self) -> RowsState {
        RowsState {
            sum: bits(&self.sum),
            count: self.count.clone(),
            in_bucket: self.in_bucket,
            t: bits(&self.t),
            cols: self
                .cols
                .iter()
                .map(|c| c.iter().map(|v| v.map(F)).collect())
                .collect(),
        }
    }
    /// The rows as `kept` (of as many series).
    fn restore(&mut self, kept: RowsState) {
        self.sum = values(&kept.sum);
        self.count = kept.count;
        self.in_bucket = kept.in_bucket;
        self.t = values(&kept.t);
        self.cols = kept
            .cols
            .into_iter()
            .map(|c| c.into_iter().map(|v| v.map(|v| v.0)).collect())
            .collect();
    }
    fn end(&mut self, k: u64, t: f64) {
        self.in_bucket += 1;
        if self.in_bucket == self.bucket || k == self.steps {
            self.t.push(t);
            for s in 0..self.series {
                self.cols[s].push((self.count[s] > 0).then(|| self.sum[s] / self.count[s] as f64));
                self.sum[s] = 0.0;
                self.count[s] = 0;
            }
            self.in_bucket = 0;
        }
    }
}

// Trace series per state (variances are averaged, SKOs derived at the end).
const T_APRIORI: usize = 0;
const T_OPEN: usize = 1;
const T_MEAS: usize = 2;
const T_FILT: usize = 3;
const T_MEAN: usize = 4;
const T_POT: usize = 5;
const T_CHI: usize = 6;
const T_SERIES: usize = 7;

fn run_n<const N: usize, E: Executor>(
    m: &CompiledModel,
    analysis: &AnalysisResult,
    req: &SimulationRequest,
    exec: &E,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
    chunk_len: usize,
) -> Result<SimulationResult, Error> {
    let steps = analysis.steps;
    let runs = req.runs as usize;
    let mut plan = Plan::new(m, steps);
    let d = plan.d;
    let n = d.n;
    let nm = d.nm;
    let lay = Layout::new(d);
    let sl = SumLayout::new(d);
    let w_sqrt = sqrt_psd(&m.w, d.nl);
    let v_sqrt = sqrt_psd(&m.v, d.ms);
    let c_nz = plan.inp.c_nz.clone();
    let pattern = |tm: &crate::expr::TimeMatrix, diag: bool| -> Vec<(usize, usize)> {
        (0..tm.rows)
            .flat_map(|i| (0..tm.cols).map(move |j| (i, j)))
            .filter(|&(i, j)| {
                (diag && i == j) || tm.values[i * tm.cols + j] != 0.0 || tm.varies(i * tm.cols + j)
            })
            .collect()
    };
    let a_nz = pattern(&m.a, true);
    let bd_nz = pattern(&m.b, false);
    // Γ = C g in the seed's form: Γ's pattern is not g's; take it dense then.
    let g_nz = match &m.noise {
        crate::model::compile::MeasurementNoise::Gamma(g) => pattern(g, false),
        crate::model::compile::MeasurementNoise::SeedG(_) => (0..d.nm)
            .flat_map(|i| (0..d.ms).map(move |j| (i, j)))
            .collect(),
    };
    let sh = Shared {
        d,
        lay,
        sl,
        truth: req.truth,
        model_error: req.model_error,
        c_nz: &c_nz,
        a_nz: &a_nz,
        bd_nz: &bd_nz,
        g_nz: &g_nz,
        w_sqrt: &w_sqrt,
        v_sqrt: &v_sqrt,
    };
    // Blocks depend on R only.
    let n_blocks = runs.div_ceil(MIN_BLOCK_RUNS).clamp(1, MAX_BLOCKS);
    let per_block = runs.div_ceil(n_blocks);
    let mut blocks: Vec<Block> = (0..n_blocks)
        .map(|b| {
            let first = b * per_block;
            let len = per_block.min(runs.saturating_sub(first));
            (first, len)
        })
        .filter(|&(_, len)| len > 0)
        .map(|(first, len)| Block::new(first as u64, len, req.seed, m, &sh))
        .collect();

    let rf = runs as f64;
    let nees_band = chi2_band(rf * n as f64, rf);
    let nis_bands: Vec<[f64; 2]> = (0..=nm).map(|a| chi2_band(rf * a as f64, rf)).collect();
    let var_band = chi2_band(rf, rf);
    let pair = &m.pair_of_state;

    let trace_points = req.trace_points.unwrap_or(m.trace_points);
    let mut rows = Rows::new(steps, n * T_SERIES + 2, trace_points);
    let mut mc = (
        vec![Avg::default(); n],
        vec![Avg::default(); n],
        vec![Avg::default(); n],
    );
    let mut nees_sum = 0.0;
    let mut nees_count = 0u64;
    let mut nees_in = 0u64;
    let mut nis_sum = 0.0;
    let mut nis_dof_sum = 0.0;
    let mut nis_count = 0u64;
    let mut nis_in = 0u64;
    let mut ratio_sum = vec![0.0; n];
    let mut ratio_count = vec![0u64; n];
    let mut ratio_in = vec![0u64; n];
    let mut bias_sum = vec![0.0; n];
    let mut last_nis_dof = 0.0;
    let mut final_ = SimulationFinal {
        a_priori_sko: vec![0.0; n],
        measured_sko: vec![None; n],
        filtered_sko: vec![0.0; n],
        potential_sko: vec![0.0; n],
        chi: vec![0.0; n],
    };

    let mut chunk = vec![0.0; chunk_len * lay.size];
    let mut pot = vec![0.0; chunk_len * n];
    let mut chi = vec![0.0; chunk_len * n];
    let mut open = vec![0.0; chunk_len * n];
    let mut k0 = 1u64;

    // An earlier run's state (a restart): its values, and on from the chunk after it.
    let stamp = SimulationStamp::new(steps, (n, nm), req.runs, req.seed, chunk_len);
    let keeps = keeps_state(req.runs, n);
    let block_runs: Vec<usize> = blocks.iter().map(|b| b.runs).collect();
    let series = n * T_SERIES + 2;
    let earlier = memo
        .recall(STATE_KEY)
        .and_then(|text| SimulationState::from_text(&text, stamp, &block_runs, series));
    let mut resumed_from = None;
    if let Some(s) = earlier {
        put(&mut plan.y, &s.y);
        put(&mut plan.big_r, &s.big_r);
        put(&mut plan.p_y, &s.p_y);
        put(&mut plan.chi, &s.chi);
        for (b, kept) in blocks.iter_mut().zip(&s.blocks) {
            b.restore(kept);
        }
        rows.restore(s.rows);
        let avgs = |kept: &[(F, u64, u64)]| -> Vec<Avg> {
            kept.iter()
                .map(|&(sum, count, excluded)| Avg {
                    sum: sum.0,
                    count,
                    excluded,
                })
                .collect()
        };
        mc = (avgs(&s.mc[0]), avgs(&s.mc[1]), avgs(&s.mc[2]));
        (nees_sum, nees_count, nees_in) = (s.nees.0.0, s.nees.1, s.nees.2);
        (nis_sum, nis_dof_sum, nis_count, nis_in) = (s.nis.0.0, s.nis.1.0, s.nis.2, s.nis.3);
        put(&mut ratio_sum, &s.ratio_sum);
        ratio_count = s.ratio_count;
        ratio_in = s.ratio_in;
        put(&mut bias_sum, &s.bias_sum);
        k0 = s.k + 1;
        resumed_from = Some(s.k);
    }

    while k0 <= steps {
        let len = (steps - k0 + 1).min(chunk_len as u64) as usize;
        for s in 0..len {
            let k = k0 + s as u64;
            plan.step(k, &lay, &mut chunk[s * lay.size..(s + 1) * lay.size])?;
            for i in 0..n {
                pot[s * n + i] = plan.big_r[i * n + i].max(0.0);
                chi[s * n + i] = plan.chi[i];
                open[s * n + i] = plan.p_y[i * n + i].max(0.0);
            }
        }
        let chunk_ref = &chunk[..len * lay.size];
        let results: Vec<(Block, Vec<f64>)> = exec.map(blocks, |mut b| {
            let s = b.advance::<N>(&sh, chunk_ref, len);
            (b, s)
        });
        // Combine in block order (deterministic).
        let mut total = vec![0.0; len * sl.size];
        blocks = Vec::with_capacity(results.len());
        for (b, s) in results {
            for (t, v) in total.iter_mut().zip(&s) {
                *t += v;
            }
            blocks.push(b);
        }
        for s in 0..len {
            let k = k0 + s as u64;
            let t_k = m.t0 + k as f64 * plan.dt;
            let tot = &total[s * sl.size..(s + 1) * sl.size];
            let rec = &chunk[s * lay.size..(s + 1) * lay.size];
            for i in 0..n {
                let va = tot[sl.apriori + i] / rf;
                let vf = tot[sl.filt2 + i] / rf;
                let mean_f = tot[sl.filt1 + i] / rf;
                let p = pot[s * n + i];
                // The filter's error is X − Y of two stored numbers of size |Y|: beyond
                // PRECISION_RATIO times its SKO (the real one, or the potential one where
                // the real one is smaller) it is rounding, not the filter.
                let scale = va.sqrt().hypot(rec[lay.y + i]);
                let err = vf.max(p).sqrt();
                if !(scale.is_finite() && vf.is_finite())
                    || (err > 0.0 && scale > PRECISION_RATIO * err)
                {
                    return Err(outgrown(&m.states[i], scale, err, k, t_k));
                }
                let base = i * T_SERIES;
                rows.put(base + T_APRIORI, va);
                rows.put(base + T_OPEN, open[s * n + i]);
                rows.put(base + T_FILT, vf);
                rows.put(base + T_MEAN, mean_f);
                rows.put(base + T_POT, p);
                rows.put(base + T_CHI, chi[s * n + i]);
                let (eta_s, chi_s) = (va.sqrt(), vf.sqrt());
                mc.2[i].add(eta_s, chi_s);
                let meas = pair[i]
                    .and_then(|j| (rec[lay.avail + j] != 0.0).then(|| tot[sl.meas2 + j] / rf));
                if let Some(j) = pair[i] {
                    match meas {
                        Some(vm) => {
                            rows.put(base + T_MEAS, vm);
                            mc.0[i].add(eta_s, vm.sqrt());
                            mc.1[i].add(vm.sqrt(), chi_s);
                        }
                        None => {
                            // Not measured at this step: nothing to compare with.
                            mc.0[i].excluded += 1;
                            mc.1[i].excluded += 1;
                        }
                    }
                    let _ = j;
                }
                if p > 0.0 {
                    let ratio = vf / p;
                    ratio_sum[i] += ratio;
                    ratio_count[i] += 1;
                    if ratio >= var_band[0] && ratio <= var_band[1] {
                        ratio_in[i] += 1;
                    }
                    bias_sum[i] += mean_f / p.sqrt();
                }
                if k == steps {
                    final_.a_priori_sko[i] = eta_s;
                    final_.filtered_sko[i] = chi_s;
                    final_.measured_sko[i] = meas.map(f64::sqrt);
                    final_.potential_sko[i] = p.sqrt();
                    final_.chi[i] = chi[s * n + i];
                }
            }
            if rec[lay.flags] != 0.0 {
                let v = tot[sl.nees] / rf;
                rows.put(n * T_SERIES, v);
                nees_sum += v;
                nees_count += 1;
                if v >= nees_band[0] && v <= nees_band[1] {
                    nees_in += 1;
                }
            }
            if rec[lay.flags + 1] != 0.0 {
                let a = rec[lay.flags + 2] as usize;
                let v = tot[sl.nis] / rf;
                rows.put(n * T_SERIES + 1, v);
                nis_sum += v;
                nis_dof_sum += a as f64;
                nis_count += 1;
                let band = nis_bands[a];
                if v >= band[0] && v <= band[1] {
                    nis_in += 1;
                }
                if k == steps {
                    last_nis_dof = a as f64;
                }
            }
            rows.end(k, t_k);
        }
        k0 += len as u64;
        if let ControlFlow::Break(()) = progress.report((k0 - 1) as f64 / steps as f64) {
            return Err(Error::Cancelled);
        }
        if keeps && k0 <= steps && memo.state_due() {
            let avgs = |a: &[Avg]| -> Vec<(F, u64, u64)> {
                a.iter().map(|a| (F(a.sum), a.count, a.excluded)).collect()
            };
            let state = SimulationState {
                stamp,
                k: k0 - 1,
                y: bits(&plan.y),
                big_r: bits(&plan.big_r),
                p_y: bits(&plan.p_y),
                chi: bits(&plan.chi),
                blocks: blocks.iter().map(Block::state).collect(),
                rows: rows.state(),
                mc: [avgs(&mc.0), avgs(&mc.1), avgs(&mc.2)],
                nees: (F(nees_sum), nees_count, nees_in),
                nis: (F(nis_sum), F(nis_dof_sum), nis_count, nis_in),
                ratio_sum: bits(&ratio_sum),
                ratio_count: ratio_count.clone(),
                ratio_in: ratio_in.clone(),
                bias_sum: bits(&bias_sum),
            };
            memo.keep_state(STATE_KEY, &state.to_text());
        }
    }

    // --- assemble
    let mc = SetSums {
        yz: mc.0,
        zx: mc.1,
        yx: mc.2,
    };
    let monte_carlo = criteria_set(
        m,
        &mc,
        &analysis.y_max,
        &analysis.z_max,
        "monte_carlo",
        [None; 3],
    );
    let mut criteria = analysis.criteria.clone();
    criteria.monte_carlo = Some(monte_carlo);

    let frac = |inside: u64, count: u64| (count > 0).then(|| inside as f64 / count as f64);
    let nees_avg = (nees_count > 0).then(|| nees_sum / nees_count as f64);
    // For NEES the band of the time average is judged with the one-step band
    // (conservative, as for the per-state ratios).
    let nees = ConsistencyStat {
        dof: n as f64,
        time_average: nees_avg,
        band: nees_band,
        fraction_in_band: frac(nees_in, nees_count),
        undefined_steps: steps - nees_count,
        verdict: Verdict::of(nees_avg, nees_band),
    };
    let nis_avg = (nis_count > 0).then(|| nis_sum / nis_count as f64);
    // NIS normalised per degree of freedom when availability varies: compare the
    // average NIS with the average dof via the band for the typical dof.
    let nis_dof = if nis_count > 0 {
        nis_dof_sum / nis_count as f64
    } else {
        last_nis_dof
    };
    let nis_band = chi2_band(rf * nis_dof, rf);
    let nis = ConsistencyStat {
        dof: nis_dof,
        time_average: nis_avg,
        band: nis_band,
        fraction_in_band: frac(nis_in, nis_count),
        undefined_steps: steps - nis_count,
        verdict: Verdict::of(nis_avg, nis_band),
    };
    let per_state = (0..n)
        .map(|i| {
            let ratio = (ratio_count[i] > 0).then(|| ratio_sum[i] / ratio_count[i] as f64);
            StateVerdict {
                state: m.states[i].clone(),
                variance_ratio: ratio,
                band: var_band,
                fraction_in_band: frac(ratio_in[i], ratio_count[i]),
                normalised_bias: (ratio_count[i] > 0).then(|| bias_sum[i] / ratio_count[i] as f64),
                verdict: Verdict::of(ratio, var_band),
            }
        })
        .collect();

    let Rows {
        t, cols, bucket, ..
    } = rows;
    let mut cols: Vec<Option<Vec<Option<f64>>>> = cols.into_iter().map(Some).collect();
    let mut take = |s: usize| cols[s].take().unwrap_or_default();
    let sqrt_col = |v: Vec<Option<f64>>| -> Vec<f64> {
        v.into_iter()
            .map(|x| x.unwrap_or(0.0).max(0.0).sqrt())
            .collect()
    };
    let plain =
        |v: Vec<Option<f64>>| -> Vec<f64> { v.into_iter().map(|x| x.unwrap_or(0.0)).collect() };
    let mut states = Vec::with_capacity(n);
    for i in 0..n {
        let base = i * T_SERIES;
        let meas = take(base + T_MEAS);
        states.push(SimulationStateTrace {
            state: m.states[i].clone(),
            a_priori_sko: sqrt_col(take(base + T_APRIORI)),
            open_loop_sko: sqrt_col(take(base + T_OPEN)),
            measured_sko: pair[i].map(|_| {
                meas.into_iter()
                    .map(|x| x.map(|v| v.max(0.0).sqrt()))
                    .collect()
            }),
            filtered_sko: sqrt_col(take(base + T_FILT)),
            filtered_mean: plain(take(base + T_MEAN)),
            potential_sko: sqrt_col(take(base + T_POT)),
            // χ is an SKO already: its bucket average is kept as is.
            chi: plain(take(base + T_CHI)),
        });
    }
    let nees_tr = take(n * T_SERIES);
    let nis_tr = take(n * T_SERIES + 1);
    let mut warnings = analysis.warnings.clone();
    if req.model_error == ModelError::Constant {
        warnings.push("model_error = \"constant\": the Riccati assumes white model error, so the filter is not matched to the simulated process".into());
    }
    if req.truth == Truth::Mean {
        warnings.push("truth = \"mean\" (seed 000's reading): the filtered error excludes the model error, so it is not expected to match R_k".into());
    }
    if nis_count == 0 {
        warnings.push("no measurement is available at any step, so the NIS check is undefined (its band and average are null)".into());
    }
    Ok(SimulationResult {
        request: req.clone(),
        steps,
        dt: plan.dt,
        t0: m.t0,
        t_end: m.t_end,
        states: m.states.clone(),
        measurements: m.measurements.clone(),
        y_max: analysis.y_max.clone(),
        z_max: analysis.z_max.clone(),
        criteria,
        consistency: Consistency {
            band_probability: BAND_PROBABILITY,
            nees,
            nis,
            per_state,
        },
        final_,
        traces: SimulationTraces {
            bucket_steps: bucket,
            t,
            states,
            nees: nees_tr,
            nis: nis_tr,
        },
        timing: Timing {
            wall_ms: 0.0,
            resumed_from_step: resumed_from,
        },
        warnings,
    })
}

/// How many times the filter's error SKO (the sample one, or the potential one where
/// that is larger) the simulated process (its sample RMS, sqrt(sample variance +
/// mean²)) may grow before the run stops: the simulated error X − Y is the difference
/// of two numbers of that size, so its rounding (≈ 2.2e-16 of them) would be ≈ 2e-4
/// of the SKO being measured at 1e12 — and at 1e16 the noise vanishes into Y's last
/// bit, and the sample SKO comes out 0 (an unstable model did).
pub const PRECISION_RATIO: f64 = 1e12;

fn outgrown(state: &str, scale: f64, sko: f64, k: u64, t: f64) -> Error {
    let size = if scale.is_finite() {
        format!(
            "{scale:.1e}, {:.1e} times the filter's error SKO",
            scale / sko
        )
    } else {
        "beyond f64 (1.8e308)".to_string()
    };
    Error::Numerical {
        step: k,
        t,
        path: "system".into(),
        message: format!(
            "the simulated process of \"{state}\" reached {size}: the simulated filter errors, differences of numbers this large, would be rounding rather than the filter (the limit is {PRECISION_RATIO:.0e} times the SKO); simulate a shorter span (t_end), a model whose process stays bounded, or states measured from a nearby reference (an offset of 1e13 with an SKO of 1 is beyond it); a filter SKO near 0 — a measurement given no noise (psi = 0) — makes the ratio as large"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_runs_state_is_kept_up_to_its_bound() {
        assert!(keeps_state(100_000, 20)); // 4.1e6 values
        assert!(!keeps_state(100_000, 21));
        assert!(keeps_state(MAX_RUNS, 8));
        assert!(keeps_state(1, 2_097_151));
        assert!(!keeps_state(1, 2_097_152));
    }

    /// A chunk's length changes no bit of the result: chunks of 1, 7 and 256 steps.
    #[test]
    fn the_chunk_length_changes_nothing() {
        let mut json: serde_json::Value =
            serde_json::from_str(crate::presets::get_json("seed-example").expect("preset"))
                .unwrap();
        json["time"]["steps"] = 2000.into();
        let model = crate::model_from_value(json).unwrap();
        let compiled = crate::model::compile::compile(&model, &Overrides::new()).unwrap();
        let analysis = crate::analysis::run(&compiled, &mut crate::NoProgress).unwrap();
        let req = SimulationRequest::new(40, 7);
        let json = |chunk: usize| {
            let r = run_n::<0, Sequential>(
                &compiled,
                &analysis,
                &req,
                &Sequential,
                &mut crate::NoProgress,
                &Forgetful,
                chunk,
            )
            .unwrap();
            serde_json::to_string(&r).unwrap()
        };
        let whole = json(CHUNK_STEPS);
        assert_eq!(json(1), whole);
        assert_eq!(json(7), whole);
    }
}
