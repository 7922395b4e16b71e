//! The Monte Carlo's request (METHOD §1.8): what the filter is compared with ([`Truth`]),
//! how the model error is drawn ([`ModelError`]), the runs and the seed; its check
//! against a compiled model and the limits ([`MAX_RUNS`], [`MAX_WORK`]).

use super::rows::T_SERIES;
use crate::error::{Error, FieldError};
use crate::model::compile::CompiledModel;
use serde::{Deserialize, Serialize};

/// Largest accepted number of runs R.
pub const MAX_RUNS: u64 = 100_000;
/// Largest accepted work runs × steps × N² (about a minute on one core at 1e10).
pub const MAX_WORK: f64 = 1e11;

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

/// The seed of a request that gives none: the same in the API, `kea monte-carlo` and the
/// browser form, so one request gives the same numbers everywhere.
pub const DEFAULT_SEED: u64 = 1;

/// A Monte Carlo request (without the model).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MonteCarloRequest {
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

impl MonteCarloRequest {
    pub fn new(runs: u64, seed: u64) -> Self {
        MonteCarloRequest {
            runs,
            seed,
            truth: Truth::Process,
            model_error: ModelError::White,
            trace_points: None,
        }
    }
}

/// Validate a request against a compiled model (paths: `runs`, `trace_points`, …).
pub fn check_request(req: &MonteCarloRequest, model: &CompiledModel) -> Result<(), Error> {
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

/// runs × steps × N²: the Monte Carlo's cost in multiply-adds, up to a constant.
pub fn work(runs: u64, steps: u64, n: usize) -> f64 {
    runs as f64 * steps as f64 * (n * n) as f64
}
