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

use crate::analysis::result::{AnalysisResult, Timing};
use crate::analysis::{Avg, SetSums, criteria_set};
use crate::error::Error;
use crate::model::Model;
use crate::model::Overrides;
use crate::model::compile::CompiledModel;
use crate::progress::Progress;
use std::ops::ControlFlow;

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

pub use crate::exec::{Executor, Sequential};
use crate::exec::{Forgetful, Memo};
use crate::resume::{F, bits, put};
pub use state::STATE_KEY;
use state::{MonteCarloStamp, MonteCarloState};

mod actual;
pub(crate) mod bands;
pub mod kind;
mod plan;
pub mod report;
pub use report::traces_csv;
mod request;
mod result;
mod rows;
mod runs;
mod state;
pub mod work;

use actual::ActualSums;
pub use bands::{BAND_PROBABILITY, chi2_band};
use plan::{Layout, Plan, SumLayout};
pub use request::{
    DEFAULT_SEED, MAX_RUNS, MAX_WORK, ModelError, MonteCarloRequest, Truth, check_request, work,
};
pub use result::{
    Consistency, ConsistencyStat, MonteCarloFinal, MonteCarloResult, MonteCarloStateTrace,
    MonteCarloTraces, StateVerdict, Verdict,
};
use rows::{Rows, T_APRIORI, T_CHI, T_FILT, T_MEAN, T_MEAS, T_OPEN, T_POT, T_SERIES};
use runs::{Block, Shared, sqrt_psd};

/// Validate, analyse (for the `bound` and `covariance` sets and y_B), and simulate.
pub fn simulate<E: Executor>(
    model: &Model,
    set: &Overrides,
    req: &MonteCarloRequest,
    exec: &E,
    progress: &mut dyn Progress,
) -> Result<MonteCarloResult, Error> {
    simulate_resumable(model, set, req, exec, progress, &Forgetful)
}

/// [`simulate`], keeping the analysis's and the runs' states in `memo` when it asks
/// for them ([`Memo::state_due`]), and going on from states an earlier run of the
/// same request kept there ([`crate::resume`]): the result is the one an
/// uninterrupted run gives (but for `timing`).
pub fn simulate_resumable<E: Executor>(
    model: &Model,
    set: &Overrides,
    req: &MonteCarloRequest,
    exec: &E,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
) -> Result<MonteCarloResult, Error> {
    let compiled = crate::model::compile::compile(model, set)?;
    simulate_compiled(&compiled, None, req, exec, progress, memo)
}

/// The truth of a Monte Carlo of a mismatched filter (`"truth": {"set"|"model"}`,
/// [`crate::analysis::mismatch`]): the world the runs imitate, while the filter is
/// designed on the model. Compiled by [`crate::analysis::mismatch::compile`].
#[derive(Clone, Copy)]
pub struct Mismatched<'a> {
    pub truth: &'a CompiledModel,
    /// The truth is a model of its own (`truth.model`): where its errors are placed.
    pub truth_is_model: bool,
}

/// [`simulate_resumable`] of a compiled model, in the world `truth` if given: its
/// analysis (the first 5 % of the progress), then the runs.
pub fn simulate_compiled<E: Executor>(
    compiled: &CompiledModel,
    truth: Option<Mismatched>,
    req: &MonteCarloRequest,
    exec: &E,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
) -> Result<MonteCarloResult, Error> {
    check_request(req, compiled)?;
    // The analysis takes a small share of the work; report it as the first 5 %.
    let mut scaled = |f: f64| progress.report(0.05 * f);
    let analysis = crate::analysis::run_resumable(compiled, &mut scaled, memo)?;
    let mut rest = |f: f64| progress.report(0.05 + 0.95 * f);
    run_resumable(compiled, truth, &analysis, req, exec, &mut rest, memo)
}

/// Simulate a compiled model, given its analysis (D, y_B, z_B, the other sets).
pub fn run<E: Executor>(
    model: &CompiledModel,
    analysis: &AnalysisResult,
    req: &MonteCarloRequest,
    exec: &E,
    progress: &mut dyn Progress,
) -> Result<MonteCarloResult, Error> {
    run_resumable(model, None, analysis, req, exec, progress, &Forgetful)
}

/// [`run`] in the world `truth` if given, keeping the runs' state in `memo` between
/// chunks when it asks for it, and going on from a state kept there
/// ([`simulate_resumable`]). A run with a truth keeps no state: it starts over.
pub fn run_resumable<E: Executor>(
    model: &CompiledModel,
    truth: Option<Mismatched>,
    analysis: &AnalysisResult,
    req: &MonteCarloRequest,
    exec: &E,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
) -> Result<MonteCarloResult, Error> {
    check_request(req, model)?;
    let chunk = chunk_steps(model, req);
    match model.n_states() {
        1 => run_n::<1, E>((model, truth), analysis, req, exec, progress, memo, chunk),
        2 => run_n::<2, E>((model, truth), analysis, req, exec, progress, memo, chunk),
        3 => run_n::<3, E>((model, truth), analysis, req, exec, progress, memo, chunk),
        4 => run_n::<4, E>((model, truth), analysis, req, exec, progress, memo, chunk),
        5 => run_n::<5, E>((model, truth), analysis, req, exec, progress, memo, chunk),
        6 => run_n::<6, E>((model, truth), analysis, req, exec, progress, memo, chunk),
        7 => run_n::<7, E>((model, truth), analysis, req, exec, progress, memo, chunk),
        8 => run_n::<8, E>((model, truth), analysis, req, exec, progress, memo, chunk),
        9 => run_n::<9, E>((model, truth), analysis, req, exec, progress, memo, chunk),
        10 => run_n::<10, E>((model, truth), analysis, req, exec, progress, memo, chunk),
        11 => run_n::<11, E>((model, truth), analysis, req, exec, progress, memo, chunk),
        12 => run_n::<12, E>((model, truth), analysis, req, exec, progress, memo, chunk),
        _ => run_n::<0, E>((model, truth), analysis, req, exec, progress, memo, chunk),
    }
}

/// Steps per chunk: as many as make [`CHUNK_WORK`] by the work estimate of a step
/// (the plan's, [`crate::monte_carlo::work::plan_step`], and every run's,
/// [`crate::monte_carlo::work::run_step`]), 1 to [`CHUNK_STEPS`]. A chunk's length never
/// changes a result (each run's stream and sums go on across chunks).
pub fn chunk_steps(model: &CompiledModel, req: &MonteCarloRequest) -> usize {
    let step = crate::monte_carlo::work::plan_step(model, None)
        + req.runs as f64 * crate::monte_carlo::work::run_step(model, req.model_error);
    crate::work::fitting(CHUNK_WORK, step, CHUNK_STEPS as u64) as usize
}

/// The runs of the filter designed on `m` in the world `truth` (or `m`'s), N states.
fn run_n<const N: usize, E: Executor>(
    (m, truth): (&CompiledModel, Option<Mismatched>),
    analysis: &AnalysisResult,
    req: &MonteCarloRequest,
    exec: &E,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
    chunk_len: usize,
) -> Result<MonteCarloResult, Error> {
    let steps = analysis.steps;
    let runs = req.runs as usize;
    let mut plan = Plan::new(m, truth.map(|t| (t.truth, t.truth_is_model)), steps);
    // The world the runs imitate: the truth's, or the model's.
    let world = truth.map_or(m, |t| t.truth);
    let d = plan.d;
    let n = d.n;
    let nm = d.nm;
    let mismatched = truth.is_some();
    let with = if mismatched { n } else { 0 };
    let lay = Layout::new(d, mismatched);
    let sl = SumLayout::new(d);
    let w_sqrt = sqrt_psd(&world.w, d.nl);
    let v_sqrt = sqrt_psd(&world.v, d.ms);
    let c_nz = plan.inp.c_nz.clone();
    let wc_nz = match truth {
        Some(t) => crate::analysis::inputs::Inputs::new(t.truth, n, plan.dt).c_nz,
        None => c_nz.clone(),
    };
    let pattern = |tm: &crate::expr::TimeMatrix, diag: bool| -> Vec<(usize, usize)> {
        (0..tm.rows)
            .flat_map(|i| (0..tm.cols).map(move |j| (i, j)))
            .filter(|&(i, j)| {
                (diag && i == j) || tm.values[i * tm.cols + j] != 0.0 || tm.varies(i * tm.cols + j)
            })
            .collect()
    };
    let a_nz = pattern(&m.a, true);
    let wa_nz = pattern(&world.a, true);
    let bd_nz = pattern(&world.b, false);
    // Γ = C g in the seed's form: Γ's pattern is not g's; take it dense then.
    let g_nz = match &world.noise {
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
        wc_nz: &wc_nz,
        same_c: world.c == m.c,
        a_nz: &a_nz,
        wa_nz: &wa_nz,
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
        .map(|(first, len)| Block::new(first as u64, len, req.seed, (world, &m.y0), &sh))
        .collect();

    let rf = runs as f64;
    let nees_band = chi2_band(rf * n as f64, rf);
    let nis_bands: Vec<[f64; 2]> = (0..=nm).map(|a| chi2_band(rf * a as f64, rf)).collect();
    let var_band = chi2_band(rf, rf);
    let pair = &m.pair_of_state;

    let trace_points = req.trace_points.unwrap_or(m.trace_points);
    // The series: T_SERIES per state, NEES, NIS, then with a truth each state's
    // actual variance and bias.
    let mut rows = Rows::new(steps, n * T_SERIES + 2 + 2 * with, trace_points);
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
    let mut final_ = MonteCarloFinal {
        a_priori_sko: vec![0.0; n],
        measured_sko: vec![None; n],
        filtered_sko: vec![0.0; n],
        potential_sko: vec![0.0; n],
        chi: vec![0.0; n],
        actual_sko: None,
        actual_bias: None,
    };

    let mut chunk = vec![0.0; chunk_len * lay.size];
    let mut pot = vec![0.0; chunk_len * n];
    let mut chi = vec![0.0; chunk_len * n];
    let mut open = vec![0.0; chunk_len * n];
    // With a truth: the actual error variances and means of each step of the chunk,
    // and the sample variance (about the sample mean) judged against them.
    let mut act = vec![0.0; chunk_len * with];
    let mut bia = vec![0.0; chunk_len * with];
    let mut actual_sums = ActualSums::new(with, rf);
    let mut k0 = 1u64;

    // An earlier run's state (a restart): its values, and on from the chunk after it.
    let stamp = MonteCarloStamp::new(steps, (n, nm), req.runs, req.seed, chunk_len);
    let keeps = keeps_state(req.runs, n) && !mismatched;
    let block_runs: Vec<usize> = blocks.iter().map(|b| b.runs).collect();
    let series = n * T_SERIES + 2 + 2 * with;
    let earlier = memo
        .recall(STATE_KEY)
        .and_then(|text| MonteCarloState::from_text(&text, stamp, &block_runs, series));
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
                open[s * n + i] = plan.open[i].max(0.0);
            }
            if mismatched {
                act[s * n..(s + 1) * n].copy_from_slice(&plan.actual);
                bia[s * n..(s + 1) * n].copy_from_slice(&plan.bias);
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
                if mismatched {
                    let (av, ab) = (act[s * n + i], bia[s * n + i]);
                    rows.put(n * T_SERIES + 2 + 2 * i, av);
                    rows.put(n * T_SERIES + 3 + 2 * i, ab);
                    // The sample variance about the sample mean, (R − 1) s² / σ² ~ χ²_{R−1}.
                    let sv = (tot[sl.filt2 + i] - rf * mean_f * mean_f).max(0.0) / (rf - 1.0);
                    actual_sums.add(i, sv, mean_f, av, ab);
                    if k == steps {
                        actual_sums.last[i] = (av.max(0.0).sqrt(), ab);
                    }
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
            let state = MonteCarloState {
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
        states.push(MonteCarloStateTrace {
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
            actual_sko: None,
            actual_bias: None,
        });
    }
    if mismatched {
        for (i, st) in states.iter_mut().enumerate() {
            st.actual_sko = Some(sqrt_col(take(n * T_SERIES + 2 + 2 * i)));
            st.actual_bias = Some(plain(take(n * T_SERIES + 3 + 2 * i)));
        }
        final_.actual_sko = Some(actual_sums.last.iter().map(|l| l.0).collect());
        final_.actual_bias = Some(actual_sums.last.iter().map(|l| l.1).collect());
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
    if mismatched {
        warnings.push("truth: the runs imitate the truth and the filter is designed on the model; `consistency.per_state` and NEES and NIS judge what the filter believes, `per_state_actual` its actual error".into());
    }
    if nis_count == 0 {
        warnings.push("no measurement is available at any step, so the NIS check is undefined (its band and average are null)".into());
    }
    Ok(MonteCarloResult {
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
            per_state_actual: actual_sums.verdicts(&m.states),
        },
        final_,
        traces: MonteCarloTraces {
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
        let model = crate::model::model_from_value(json).unwrap();
        let compiled = crate::model::compile::compile(&model, &Overrides::new()).unwrap();
        let analysis = crate::analysis::run(&compiled, &mut crate::progress::NoProgress).unwrap();
        let req = MonteCarloRequest::new(40, 7);
        let json = |chunk: usize| {
            let r = run_n::<0, Sequential>(
                (&compiled, None),
                &analysis,
                &req,
                &Sequential,
                &mut crate::progress::NoProgress,
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
