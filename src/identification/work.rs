//! The identification's work estimate (`crate::work`): an upper bound, every iteration
//! of the limit spent.

use super::request::IdentificationRequest;
use crate::work::Work;

/// Evaluations per iteration counted: the step's and its line search's (scoring
/// usually needs one or two; the bound allows for a few halvings).
const EVALUATIONS_PER_ITERATION: f64 = 3.0;

/// D steps × the SRIF's cost of a step with its derivative blocks × the evaluations
/// that `max_iterations` allows, plus the statistics at θ̂ (4p gradients).
pub fn identification_work(r: &IdentificationRequest) -> Work {
    let n = r.model.system.states.len() as f64;
    let l = r.model.system.b.first().map_or(1, Vec::len) as f64;
    let m = r.model.measurement.names.len() as f64;
    let p = r.estimate.len() as f64;
    let d = r.data.rows() as f64;
    // The time update's Householder pass over (L + N) rows of (L + N + 1)(1 + p)
    // columns dominates; ≈ 1100 ns at N = L = 2, m = 1, p = 3 (BENCHMARKS.md).
    let step = 2.0 * (n + l + 1.0).powi(2) * (n + l + m + 1.0) * (1.0 + p) + 50.0;
    let starts = (1 + r.starts.len()) as f64;
    let evaluations = starts * EVALUATIONS_PER_ITERATION * r.max_iterations as f64 + 4.0 * p + 1.0;
    // The expected information's one pass (identification::expected): an SRIF step,
    // then N(1 + p) + N + m realisation rows of N(1 + p) values updated and compressed
    // by a Householder triangularisation.
    let (expected, also) = if r.expected_information {
        let keep = n * (1.0 + p);
        let pass = step + 2.0 * (keep + n + m) * keep * keep;
        (
            pass,
            format!(
                " + the expected information's pass ({} per step)",
                crate::text::short(pass)
            ),
        )
    } else {
        (0.0, String::new())
    };
    Work {
        units: d * (step * evaluations + expected),
        explain: format!(
            "D = {d} steps × {} per SRIF step × {evaluations} evaluations (max_iterations = {} from each of {starts} starts){also}",
            crate::text::short(step),
            r.max_iterations
        ),
        path: "max_iterations".into(),
    }
}
