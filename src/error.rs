//! Errors the core reports: each names the field path in the submitted JSON
//! (`measurement.c[1][2]`) and says what was expected.

use serde::Serialize;
use std::fmt;

/// One problem with a submitted model, at `path` (empty for the whole document).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FieldError {
    pub path: String,
    pub message: String,
}

impl FieldError {
    pub fn new(path: impl Into<String>, message: impl Into<String>) -> Self {
        FieldError {
            path: path.into(),
            message: message.into(),
        }
    }
}

impl fmt::Display for FieldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.path.is_empty() {
            write!(f, "{}", self.message)
        } else {
            write!(f, "{}: {}", self.path, self.message)
        }
    }
}

/// Everything that can stop an analysis. None of these is a panic or a NaN.
#[derive(Clone, Debug, PartialEq)]
pub enum Error {
    /// The model (or a request around it) is invalid; every problem found is listed.
    Invalid(Vec<FieldError>),
    /// The model is valid but the computation cannot go on at step k (time t),
    /// e.g. a singular innovation covariance or a diverging covariance.
    Numerical {
        step: u64,
        t: f64,
        path: String,
        message: String,
    },
    /// The caller asked to stop (progress callback returned `Break`).
    Cancelled,
}

impl Error {
    pub fn invalid(path: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Invalid(vec![FieldError::new(path, message)])
    }

    /// A serde error, with the path where it happened, under `prefix`.
    pub fn from_serde(prefix: &str, e: &serde_json::Error) -> Self {
        let msg = e.to_string();
        Error::invalid(prefix.to_string(), msg)
    }

    /// The field errors of this error (a numerical error is one error at its path).
    pub fn field_errors(&self) -> Vec<FieldError> {
        match self {
            Error::Invalid(v) => v.clone(),
            Error::Numerical {
                path,
                message,
                step,
                t,
                ..
            } => vec![FieldError::new(
                path.clone(),
                format!("{message} (at step {step}, t = {t})"),
            )],
            Error::Cancelled => vec![FieldError::new("", "cancelled")],
        }
    }

    /// Prefix every path with `prefix` (e.g. `model`), joining with a dot.
    pub fn with_prefix(self, prefix: &str) -> Self {
        let join = |p: &str| {
            if prefix.is_empty() {
                p.to_string()
            } else if p.is_empty() {
                prefix.to_string()
            } else if p.starts_with('[') {
                format!("{prefix}{p}")
            } else {
                format!("{prefix}.{p}")
            }
        };
        match self {
            Error::Invalid(v) => Error::Invalid(
                v.into_iter()
                    .map(|e| FieldError::new(join(&e.path), e.message))
                    .collect(),
            ),
            Error::Numerical {
                step,
                t,
                path,
                message,
            } => Error::Numerical {
                step,
                t,
                path: join(&path),
                message,
            },
            Error::Cancelled => Error::Cancelled,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Invalid(v) => {
                for (i, e) in v.iter().enumerate() {
                    if i > 0 {
                        writeln!(f)?;
                    }
                    write!(f, "{e}")?;
                }
                Ok(())
            }
            Error::Numerical {
                step,
                t,
                path,
                message,
            } => {
                if path.is_empty() {
                    write!(f, "{message} (at step {step}, t = {t})")
                } else {
                    write!(f, "{path}: {message} (at step {step}, t = {t})")
                }
            }
            Error::Cancelled => write!(f, "cancelled"),
        }
    }
}

impl std::error::Error for Error {}
