//! The registry of the kinds of run ([`crate::kind::Kind`]): every kind listed once,
//! in [`kinds!`]'s invocation, and the one way in for every shell — [`prepare`] a
//! request of a kind named in it, estimate its work, run it, render its outcome.

use crate::analysis::result::Timing;
use crate::error::{Error, FieldError};
use crate::exec::{Executor, Memo};
use crate::kind::Kind;
use crate::progress::Progress;
use crate::request;
use crate::work::Work;
use serde_json::Value;

/// The registry: the [`Prepared`] and [`Outcome`] enums, with one variant per kind,
/// [`NAMES`] and [`ALIASES`].
macro_rules! kinds {
    ($($variant:ident => $kind:ty,)*) => {
        /// A request read and compiled by its kind, ready to run.
        pub enum Prepared {
            $($variant(<$kind as Kind>::Request),)*
        }

        /// What a run gave.
        pub enum Outcome {
            $($variant(<$kind as Kind>::Outcome),)*
        }

        /// Every kind's name, in the order errors list them.
        pub const NAMES: &[&str] = &[$(<$kind as Kind>::NAME,)*];

        /// Every kind's name with its aliases ([`Kind::ALIASES`]: former names, still
        /// read as the kind), in [`NAMES`]' order.
        pub const ALIASES: &[(&str, &[&str])] =
            &[$((<$kind as Kind>::NAME, <$kind as Kind>::ALIASES),)*];

        /// The kind a request's `kind` names (its name or an alias), as its name.
        pub fn find(name: &str) -> Option<&'static str> {
            ALIASES
                .iter()
                .find(|(kind, former)| *kind == name || former.contains(&name))
                .map(|(kind, _)| *kind)
        }

        /// Read and compile a request of the kind `kind` (a name or an alias); its kind's
        /// own checks are [`Prepared::check`]'s (see [`prepare_checked`]).
        pub fn prepare(kind: &str, request: Value) -> Result<Prepared, Error> {
            let name = find(kind).ok_or_else(|| unknown(kind))?;
            let obj = request::object(request)?;
            $(if name == <$kind as Kind>::NAME {
                return <$kind as Kind>::prepare(obj).map(Prepared::$variant);
            })*
            Err(unknown(kind))
        }

        impl Prepared {
            /// The kind's own checks of the request ([`Kind::check`]).
            pub fn check(&self) -> Result<(), Error> {
                match self {
                    $(Prepared::$variant(r) => <$kind as Kind>::check(r),)*
                }
            }

            /// The work estimate, from what was compiled.
            pub fn work(&self) -> Work {
                match self {
                    $(Prepared::$variant(r) => <$kind as Kind>::work(r),)*
                }
            }

            /// Run it ([`Kind::run`]).
            pub fn run<E: Executor>(
                &self,
                exec: &E,
                progress: &mut dyn Progress,
                memo: &dyn Memo,
            ) -> Result<Outcome, Error> {
                match self {
                    $(Prepared::$variant(r) => {
                        <$kind as Kind>::run(r, exec, progress, memo).map(Outcome::$variant)
                    })*
                }
            }
        }

        impl Outcome {
            /// The result document, as JSON text.
            pub fn to_json(&self) -> String {
                match self {
                    $(Outcome::$variant(o) => serde_json::to_string(o),)*
                }
                .expect("a result of numbers and texts serialises")
            }

            /// The result document, as pretty-printed JSON text.
            pub fn to_json_pretty(&self) -> String {
                match self {
                    $(Outcome::$variant(o) => serde_json::to_string_pretty(o),)*
                }
                .expect("a result of numbers and texts serialises")
            }

            /// The plain-text report.
            pub fn text(&self) -> String {
                match self {
                    $(Outcome::$variant(o) => <$kind as Kind>::text(o),)*
                }
            }

            /// The traces as CSV, where the kind has them.
            pub fn csv(&self) -> Option<String> {
                match self {
                    $(Outcome::$variant(o) => <$kind as Kind>::csv(o),)*
                }
            }

            /// The run's timing, whose wall-clock time the caller fills in.
            pub fn timing(&mut self) -> &mut Timing {
                match self {
                    $(Outcome::$variant(o) => <$kind as Kind>::timing(o),)*
                }
            }
        }
    };
}

kinds! {
    Analysis => crate::analysis::kind::Analysis,
    MonteCarlo => crate::monte_carlo::kind::MonteCarlo,
    Synthesis => crate::synthesis::kind::Synthesis,
    Identification => crate::identification::kind::Identification,
    Nonlinear => crate::nonlinear::kind::Nonlinear,
    Sensitivity => crate::sensitivity::kind::Sensitivity,
}

/// The error for a `kind` that names none (at the request's `kind`).
pub fn unknown(kind: &str) -> Error {
    Error::Invalid(vec![FieldError::new(
        "kind",
        format!("unknown job kind `{kind}`; known: {}", NAMES.join(", ")),
    )])
}

/// [`prepare`] and [`Prepared::check`]: a request read, compiled and checked.
pub fn prepare_checked(kind: &str, request: Value) -> Result<Prepared, Error> {
    let prepared = prepare(kind, request)?;
    prepared.check()?;
    Ok(prepared)
}
