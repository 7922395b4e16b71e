//! A nonlinear run's work estimate (`crate::work`): D steps × the bank's filters ×
//! a filter-step's cost, plus the truth's simulation when there is one.

use super::request::{NonlinearRequest, Source};
use crate::expr::StateFn;
use crate::work::Work;

/// One evaluation of an expression, about: a fixed cost and one per character
/// (exmex interprets its flat list of nodes; calibrated in BENCHMARKS.md).
fn evaluation(f: &StateFn) -> f64 {
    20.0 + 1.5 * f.text().len() as f64
}

/// One filter-step: f with its Jacobian (one evaluation per state each text names),
/// h with its Jacobian and once more at x⁺, the covariance products.
fn filter_step(r: &NonlinearRequest) -> f64 {
    let model = &r.model;
    let (n, m) = (model.n_states() as f64, model.n_measurements() as f64);
    let f: f64 = model
        .f
        .iter()
        .map(|f| evaluation(f) * f.used().len().max(1) as f64)
        .sum();
    let h: f64 = model
        .h
        .iter()
        .map(|h| evaluation(h) * (h.used().len().max(1) + 1) as f64)
        .sum();
    f + h + 4.0 * n * n * n + 4.0 * n * n * m + 2.0 * m * m * m + 60.0
}

/// The filters of the bank: K iterates, the EKF and one per Q scale (at most: the
/// run shares a filter between equal designs).
fn filters(r: &NonlinearRequest) -> usize {
    r.alpha.len() + 1 + r.q_scales.len()
}

/// The work of one step of the whole bank.
pub fn per_step(r: &NonlinearRequest) -> f64 {
    filters(r) as f64 * filter_step(r)
}

/// D × (the bank's step + the truth's substeps).
pub fn nonlinear_work(r: &NonlinearRequest) -> Work {
    let d = r.model.steps as f64;
    let bank = per_step(r);
    let truth = match &r.source {
        Source::Truth(t) => {
            let f: f64 = t.model.f.iter().map(evaluation).sum::<f64>()
                + t.input.iter().flatten().map(evaluation).sum::<f64>();
            t.substeps as f64 * (f + 20.0 * t.model.n_states() as f64)
        }
        _ => 0.0,
    };
    Work {
        units: d * (bank + truth),
        explain: format!(
            "D = {d} steps × ({} filters × {} per filter-step{})",
            filters(r),
            crate::text::short(filter_step(r)),
            if truth > 0.0 {
                format!(" + the truth's {}", crate::text::short(truth))
            } else {
                String::new()
            }
        ),
        path: "model.time.steps".into(),
    }
}
