//! kea-core: the filtering-effect analysis of METHOD.md, as a pure library.
//!
//! Architecture invariant: this crate knows nothing about HTTP, threads, files or the
//! browser. It takes a [`Model`] (plus parameter overrides), returns a result or an
//! [`Error`] naming the field path, and reports progress through [`Progress`], which
//! is also how a caller cancels.

pub mod analysis;
pub mod cost;
pub mod decimate;
pub mod error;
pub mod exec;
pub mod expr;
pub mod expr_block;
mod inputs;
pub mod json;
mod lanes;
pub mod linalg;
pub mod model;
pub mod presets;
pub mod report;
pub mod result;
pub mod resume;
pub mod riccati;
pub mod schedule;
pub mod simulation;
pub mod steps;
pub mod synthesis;
mod trig;
pub mod validate;

pub use error::{Error, FieldError};
pub use json::{from_value_at, parse_json};
pub use model::Model;
pub use result::AnalysisResult;

use std::collections::BTreeMap;
use std::ops::ControlFlow;

/// Parameter overrides (`--set name=value`): each must name an existing param.
pub type Overrides = BTreeMap<String, f64>;

/// Progress reports and cancellation: `report` is called with the fraction done (0..1)
/// after about every millisecond of work by the work estimate
/// ([`analysis::WORK_BETWEEN_REPORTS`]: every step of a costly model, every few
/// thousand of a cheap one); returning `ControlFlow::Break(())` cancels.
pub trait Progress {
    fn report(&mut self, fraction: f64) -> ControlFlow<()>;
}

/// No progress reporting, never cancels.
pub struct NoProgress;

impl Progress for NoProgress {
    fn report(&mut self, _fraction: f64) -> ControlFlow<()> {
        ControlFlow::Continue(())
    }
}

impl<F: FnMut(f64) -> ControlFlow<()>> Progress for F {
    fn report(&mut self, fraction: f64) -> ControlFlow<()> {
        self(fraction)
    }
}

/// Run the analysis of METHOD §1.2–§1.6 on a model with parameter overrides.
pub fn analyze(
    model: &Model,
    set: &Overrides,
    progress: &mut dyn Progress,
) -> Result<AnalysisResult, Error> {
    let compiled = validate::compile(model, set)?;
    analysis::run(&compiled, progress)
}

/// The filter's covariance recursion alone, (2.1)–(2.7) and the mean, with the
/// model's parameter overrides: R_D and p_D, equal bit for bit to the analysis's
/// `final.covariance` and `final.gain`. For timing kea against other filters on the
/// same recursion ([`analysis::covariance_recursion`]).
pub fn covariance_recursion(
    model: &Model,
    set: &Overrides,
    progress: &mut dyn Progress,
) -> Result<result::FinalCovariance, Error> {
    let compiled = validate::compile(model, set)?;
    analysis::covariance_recursion(&compiled, progress)
}

/// Validate a model without running it; every problem found is returned.
pub fn check(model: &Model, set: &Overrides) -> Result<(), Error> {
    validate::compile(model, set).map(|_| ())
}

/// How much work an analysis is, before running it (for limits and scheduling).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct WorkEstimate {
    /// Steps D (for `"auto"`: the cap, the worst case).
    pub steps: u64,
    /// State dimension N.
    pub states: usize,
    /// steps × [`step_cost`]`(N)`.
    pub work: f64,
}

/// The cost of one analysis step of an N-state model, N³ + 16 N² + 200: the Riccati
/// recursion's N³ multiply-adds, plus what every step pays per state (criteria, the
/// bound, the traces) and per step whatever N is. One unit is ≈ 1 ns on the reference
/// machine (measured, time-invariant chain, shortcut off: N = 1 195 ns per step against
/// 217 units, N = 3 572 against 371, N = 10 2 576 against 2 800, N = 30 29 µs
/// against 41 600); a bare N³ counted a one-state step as 1 unit, 200 times too little.
pub fn step_cost(n: usize) -> f64 {
    let n = n as f64;
    n * n * n + 16.0 * n * n + 200.0
}

/// Estimate the work of a model without running it. Validates the model.
pub fn estimate_work(model: &Model, set: &Overrides) -> Result<WorkEstimate, Error> {
    let compiled = validate::compile(model, set)?;
    let n = compiled.n_states();
    let steps = compiled.max_steps();
    Ok(WorkEstimate {
        steps,
        states: n,
        work: steps as f64 * step_cost(n),
    })
}

/// Parse a model from a JSON value, with serde errors located at their field path.
pub fn model_from_value(value: serde_json::Value) -> Result<Model, Error> {
    // Not an object, or without the required parts: say so for all of them at once
    // (serde would read an array as the fields in order, and name one missing field).
    let Some(object) = value.as_object() else {
        return Err(Error::invalid(
            "",
            format!(
                "a model is a JSON object ({{\"kea_model\": 1, \"time\": …, \"system\": …, \"measurement\": …}}), got {}",
                error::json_kind(&value)
            ),
        ));
    };
    let missing: Vec<FieldError> = ["time", "system", "measurement"]
        .into_iter()
        .filter(|k| !object.contains_key(*k))
        .map(|k| {
            FieldError::new(
                k,
                "missing: a model needs time, system and measurement (README, \"Model format\")",
            )
        })
        .collect();
    if !missing.is_empty() {
        // A misspelt section ("sytem") is the likely cause of a missing one: name it,
        // as serde would have had it reached it.
        let unknown = object
            .keys()
            .filter(|k| !MODEL_MEMBERS.contains(&k.as_str()))
            .map(|k| FieldError::new(k, unknown_model_member(k)));
        return Err(Error::Invalid(unknown.chain(missing).collect()));
    }
    from_value_at(value, &[])
}

/// The members of a model (`Model`'s fields; a test compares them with serde's list).
const MODEL_MEMBERS: [&str; 9] = [
    "kea_model",
    "name",
    "description",
    "params",
    "time",
    "system",
    "measurement",
    "criteria",
    "options",
];

/// The error at a top-level member a model does not have.
fn unknown_model_member(name: &str) -> String {
    let expected = format!("expected one of: {}", MODEL_MEMBERS.join(", "));
    if name == "model" {
        format!(
            "unknown member; a model's members are at its top level ({expected}), not inside \"model\" (`{{\"model\": …}}` is the shape of a request that carries a model, not of a model)"
        )
    } else {
        format!("unknown member; {expected}")
    }
}

/// Parse a model from JSON text, with serde errors located at their field path.
pub fn model_from_json(text: &str) -> Result<Model, Error> {
    let value = parse_json(text.as_bytes())
        .map_err(|e| Error::invalid("", format!("not valid JSON: {e}")))?;
    model_from_value(value)
}
