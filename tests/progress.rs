//! Progress reports come after a bounded amount of work, not a fixed count of steps:
//! a model whose steps are costly reports (and can be cancelled) every few steps, well
//! before the end, in the analysis, the Monte Carlo and a synthesis's batch.

mod common;

use kea_core::monte_carlo::{self, MonteCarloRequest};
use kea_core::synthesis;
use kea_core::{Error, Model, Overrides};
use serde_json::json;
use std::ops::ControlFlow;

/// A chain of `n` states whose a(t) varies with t (every step costs about N³ units of
/// work, ≈ 1 ms at N = 100), over `steps` steps, with a parameter `psi`.
fn costly(n: usize, steps: u64) -> Model {
    let a = common::chain_a(n, |_| json!("-1 - 0.1*sin(t)"), json!(0.5));
    let mut c = vec![0.0; n];
    c[0] = 1.0;
    kea_core::model_from_value(json!({
        "kea_model": 1,
        "params": {"psi": 0.1},
        "time": {"t0": 0, "t_end": 1, "steps": steps},
        "system": {
            "states": (0..n).map(|i| format!("x{i}")).collect::<Vec<_>>(),
            "a": a,
            "b": vec![vec![1.0]; n],
            "phi": [1]
        },
        "measurement": {"names": ["z"], "c": [c], "gamma": [[1]], "psi": ["psi"]}
    }))
    .expect("valid model")
}

/// The fractions reported until the end, or until `stop_at` reports (then stopping).
fn reports_of(
    stop_at: Option<usize>,
    run: impl FnOnce(&mut dyn FnMut(f64) -> ControlFlow<()>) -> Result<(), Error>,
) -> (Vec<f64>, Result<(), Error>) {
    let mut seen = Vec::new();
    let outcome = run(&mut |f: f64| {
        seen.push(f);
        if Some(seen.len()) == stop_at {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    });
    (seen, outcome)
}

#[test]
fn a_costly_analysis_reports_every_few_steps_and_stops_when_told() {
    // 200 steps, far fewer than the 16 384 steps that were once between two reports.
    let model = costly(100, 200);
    let analyze = |p: &mut dyn FnMut(f64) -> ControlFlow<()>| {
        kea_core::analyze(&model, &Overrides::new(), &mut { p }).map(|_| ())
    };
    let (seen, outcome) = reports_of(None, analyze);
    outcome.expect("the analysis runs");
    assert!(seen.len() >= 50, "{} reports: {seen:?}", seen.len());
    // Told to stop at the third report: it stops there, 3 steps in.
    let (seen, outcome) = reports_of(Some(3), analyze);
    assert!(matches!(outcome, Err(Error::Cancelled)), "{outcome:?}");
    assert_eq!(seen.len(), 3);
    assert!(seen[2] < 0.1, "stopped at {}", seen[2]);
}

#[test]
fn a_costly_monte_carlo_reports_within_a_chunk_of_steps_and_stops_when_told() {
    let model = costly(100, 64);
    let req = MonteCarloRequest::new(8, 1);
    let simulate = |p: &mut dyn FnMut(f64) -> ControlFlow<()>| {
        monte_carlo::simulate(
            &model,
            &Overrides::new(),
            &req,
            &monte_carlo::Sequential,
            &mut { p },
        )
        .map(|_| ())
    };
    // The Monte Carlo's own reports follow the analysis's 5 %.
    let (seen, outcome) = reports_of(None, simulate);
    outcome.expect("the simulation runs");
    let own = seen.iter().filter(|&&f| f > 0.05).count();
    assert!(own >= 8, "{own} reports after the analysis: {seen:?}");
    // Stopped at its first report after the analysis: well before the end.
    let first_own = seen.iter().position(|&f| f > 0.05).unwrap() + 1;
    let (seen, outcome) = reports_of(Some(first_own), simulate);
    assert!(matches!(outcome, Err(Error::Cancelled)), "{outcome:?}");
    assert!(
        seen[first_own - 1] < 0.5,
        "stopped at {}",
        seen[first_own - 1]
    );
}

#[test]
fn a_seed_search_batch_of_costly_analyses_reports_between_them() {
    let model = costly(100, 100);
    let req = synthesis::request_from_value(json!({
        "model": serde_json::to_value(&model).unwrap(),
        "target": {"criterion": "yx", "threshold": 1e300},
        "mode": {"seed_search": {"params": [
            {"name": "psi", "low": 0.0125, "high": 0.1, "shrink": 0.5}
        ], "batch": 4}}
    }))
    .expect("valid request");
    let search = |p: &mut dyn FnMut(f64) -> ControlFlow<()>| {
        synthesis::synthesize(&req, &kea_core::exec::Sequential, &mut { p }).map(|_| ())
    };
    // One batch of 4 analyses: a report before each on one thread, and one at its end.
    let (seen, outcome) = reports_of(None, search);
    outcome.expect("the search runs");
    assert!(seen.len() >= 5, "{seen:?}");
    // Told to stop at the second report: after one analysis of the four.
    let (seen, outcome) = reports_of(Some(2), search);
    assert!(matches!(outcome, Err(Error::Cancelled)), "{outcome:?}");
    assert!(seen[1] <= 0.25 + 1e-9, "stopped at {}", seen[1]);
}
