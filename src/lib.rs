//! kea-core: the filtering-effect analysis of METHOD.md, as a pure library.
//!
//! Architecture invariant: this crate knows nothing about HTTP, threads, files, clocks,
//! the environment or the browser. It takes a [`Model`] (plus parameter overrides),
//! returns a result or an [`Error`] naming the field path, and reports progress through
//! [`Progress`], which is also how a caller cancels.
//!
//! The modules, from the bottom up: the words and encodings every part shares
//! ([`error`], [`json`], [`text`], [`resume`], [`work`], [`progress`], [`exec`],
//! [`cpu`]); the expressions ([`expr`]) and the model ([`model`]: its format, its
//! compilation, the measurement schedule); the numerical kernels ([`numerics`]); the
//! kinds of run, each in its folder ([`analysis`], [`monte_carlo`], [`synthesis`]);
//! the [`presets`].

pub mod cpu;
pub mod error;
pub mod exec;
pub mod json;
pub mod progress;
pub mod request;
pub mod resume;
pub mod text;
pub mod work;

pub mod expr;
pub mod model;
pub mod numerics;

pub mod kind;

pub mod analysis;
pub mod identification;
pub mod monte_carlo;
pub mod nonlinear;
pub mod sensitivity;
pub mod synthesis;

pub mod registry;

pub mod presets;

pub use analysis::result::AnalysisResult;
pub use error::{Error, FieldError};
pub use json::{from_value_at, parse_json};
pub use model::{Model, model_from_json, model_from_value};
pub use progress::{NoProgress, Progress};

pub use model::Overrides;

/// Run the analysis of METHOD §1.2–§1.6 on a model with parameter overrides.
pub fn analyze(
    model: &Model,
    set: &Overrides,
    progress: &mut dyn Progress,
) -> Result<AnalysisResult, Error> {
    analysis::analyze(model, set, progress)
}

/// The filter's covariance recursion alone, (2.1)–(2.7) and the mean, with the
/// model's parameter overrides: R_D and p_D, equal bit for bit to the analysis's
/// `final.covariance` and `final.gain`. For timing kea against other filters on the
/// same recursion ([`analysis::covariance_recursion`]).
pub fn covariance_recursion(
    model: &Model,
    set: &Overrides,
    progress: &mut dyn Progress,
) -> Result<analysis::result::FinalCovariance, Error> {
    let compiled = model::compile(model, set)?;
    analysis::covariance_recursion(&compiled, progress)
}

/// Validate a model without running it; every problem found is returned.
pub fn check(model: &Model, set: &Overrides) -> Result<(), Error> {
    model::check(model, set)
}
