//! The Monte Carlo's work estimate: the analysis it starts with, then per step the
//! plan and every run (units of [`crate::work`]; measured against `kea monte-carlo` in
//! `crate::analysis::work`'s notes).

use super::{ModelError, MonteCarloRequest};
use crate::analysis::work::{AnalysisStep, analysis_work};
use crate::model::Model;
use crate::model::compile::{CompiledModel, MeasurementNoise};
use crate::work::Work;

/// The Monte Carlo plan's step, computed once for all runs (plan.rs, `Plan`):
/// the inputs and expressions as in the analysis, and a dense Riccati step with the
/// open-loop covariance, 2N³ + 4N²n + 2Nn² + n³, plus 300 of bookkeeping.
/// Measured: N = 1 330 ns against 303; N = 6, n = 4 1.56 µs against 1.56; N = 30,
/// n = 5 44 µs against 74; N = 100, n = 5 1.5 ms against 2.2.
pub fn plan_step(compiled: &CompiledModel, model: Option<&Model>) -> f64 {
    let step = AnalysisStep::of(compiled, model);
    let n = compiled.n_states() as f64;
    let nm = compiled.n_measurements() as f64;
    step.inputs
        + step.expressions.units()
        + 2.0 * n * n * n
        + 4.0 * n * n * nm
        + 2.0 * n * nm * nm
        + nm * nm * nm
        + 300.0
}

/// One run's step (runs.rs, `Block::advance`): the normal draws (≈ 5 ns
/// each) times the lower-triangular square roots of W and V (L(L+1)/2 and M(M+1)/2
/// sequential terms, ≈ 1 ns each), and the products over the runs, vectorised (≈ 0.5
/// ns a term): A Y and A X, bΔt F, Γ Φ, C, the gain, the errors, NEES and NIS. F is
/// drawn at every step for a white model error only.
/// Measured (ns): N = 1 22 against 17; N = 6, n = 4 88 against 113; N = 10,
/// L = M = 20 768 against 927; N = 30, L = M = n = 5 473 against 620; N = 10,
/// L = M = 200 40 400 against 42 000.
pub fn run_step(compiled: &CompiledModel, model_error: ModelError) -> f64 {
    let n = compiled.n_states();
    let nm = compiled.n_measurements();
    let l = match model_error {
        ModelError::White => compiled.b.cols as f64,
        ModelError::Constant => 0.0,
    };
    let ms = compiled.noise.sources() as f64;
    let pattern = |m: &crate::expr::TimeMatrix, diag: bool| {
        (0..m.rows * m.cols)
            .filter(|&i| (diag && i / m.cols == i % m.cols) || m.values[i] != 0.0 || m.varies(i))
            .count()
    };
    let nnz_gamma = match &compiled.noise {
        MeasurementNoise::Gamma(g) => pattern(g, false),
        MeasurementNoise::SeedG(_) => nm * compiled.noise.sources(),
    };
    let nnz_c = compiled.c.iter().filter(|c| **c != 0.0).count();
    let products = 2 * pattern(&compiled.a, true)
        + pattern(&compiled.b, false)
        + nnz_gamma
        + nnz_c
        + n * nm
        + 3 * n
        + n * (n + 1) / 2
        + nm * (nm + 1) / 2;
    6.0 + 5.0 * (l + ms) + (l * (l + 1.0) + ms * (ms + 1.0)) / 2.0 + 0.5 * products as f64
}

/// What a run costs once: its initial state and, for a constant model error, F.
pub fn run_start(compiled: &CompiledModel, model_error: ModelError) -> f64 {
    let n = compiled.n_states() as f64;
    let l = compiled.b.cols as f64;
    let f = match model_error {
        ModelError::White => 0.0,
        ModelError::Constant => 5.0 * l + l * (l + 1.0) / 2.0,
    };
    100.0 + 5.0 * n + f
}

/// The work of a Monte Carlo `sim` on a compiled model (`model`: its
/// expressions' texts): the analysis it starts with, then per step the plan (the
/// inputs and a dense Riccati step, [`plan_step`]) and every run's step
/// ([`run_step`]).
pub fn monte_carlo_work(
    compiled: &CompiledModel,
    model: Option<&Model>,
    sim: &MonteCarloRequest,
) -> Work {
    let analysis = analysis_work(compiled, model);
    let steps = compiled.max_steps();
    let plan = plan_step(compiled, model);
    let run = run_step(compiled, sim.model_error);
    let per_run_once = run_start(compiled, sim.model_error);
    let runs = sim.runs as f64;
    Work {
        units: analysis.units + steps as f64 * (plan + runs * run) + runs * per_run_once,
        explain: format!(
            "the analysis {:.3e} + D = {steps} steps × (the plan {plan:.0} + runs R = {} × {run:.0} per run)",
            analysis.units, sim.runs
        ),
        path: "runs".into(),
    }
}

/// A truth's share (a mismatched filter): the mismatch's recursion stepped beside the
/// plan, D × its step ([`crate::analysis::mismatch::pass_step`]). Its units and how
/// they were computed.
pub fn truth_work(design: &CompiledModel) -> (f64, String) {
    let steps = design.max_steps();
    let step = crate::analysis::mismatch::pass_step(design);
    (
        steps as f64 * step,
        format!("D = {steps} steps × the mismatch's step {step:.0}"),
    )
}
