//! The kinds of run, and the one way into each: a request (JSON) is read strictly
//! once, with every problem at its path, and compiled once ([`prepare`]); what was
//! compiled gives the work estimate ([`Prepared::work`]) and runs with a caller's
//! executor, progress and memo ([`Prepared::run`]); the outcome renders itself as
//! JSON, a text report and CSV ([`Outcome`]). The server's jobs, the command line,
//! the wasm module and so the web page's worker all come in here.
//!
//! The kinds are listed once, in [`kinds!`]'s invocation below: a new kind is its
//! module (a type implementing [`Kind`]) and one line there.

pub mod request;

use crate::Progress;
use crate::analysis::result::Timing;
use crate::error::{Error, FieldError};
use crate::exec::{Executor, Memo};
use crate::work::Work;
use serde_json::{Map, Value};

/// One kind of run: how its request is read and compiled, estimated, run and shown.
pub trait Kind {
    /// The kind's name in a request (`"analysis"`).
    const NAME: &'static str;
    /// Older names still read as this kind (stored jobs, scripts).
    const ALIASES: &'static [&'static str];
    /// The members its request may have (`model_id`: a stored model, resolved to
    /// `model` by the server before the kind sees the request).
    const MEMBERS: &'static [&'static str];
    /// The request read and compiled, ready to run.
    type Request;
    /// What a run gives (its JSON is the result document).
    type Outcome: serde::Serialize;

    /// Read and compile a request (an object; paths into it: `model.system.a[0][1]`,
    /// `set.q`, `runs`).
    fn prepare(request: Map<String, Value>) -> Result<Self::Request, Error>;
    /// The work estimate of a prepared request.
    fn work(request: &Self::Request) -> Work;
    /// Run it; `Error::Cancelled` when `progress` said stop. `memo` keeps finished
    /// parts and states for a run of the same request after a restart, and holds those
    /// of an earlier run (`crate::resume`).
    fn run<E: Executor>(
        request: &Self::Request,
        exec: &E,
        progress: &mut dyn Progress,
        memo: &dyn Memo,
    ) -> Result<Self::Outcome, Error>;
    /// The outcome's timing (its wall-clock time is the caller's to fill in).
    fn timing(outcome: &mut Self::Outcome) -> &mut Timing;
    /// The plain-text report (`kea <kind>`'s table).
    fn text(outcome: &Self::Outcome) -> String;
    /// The traces as CSV, where the kind has them.
    fn csv(outcome: &Self::Outcome) -> Option<String>;
}

/// The registry: the [`Prepared`] and [`Outcome`] enums, with one variant per kind,
/// and [`NAMES`].
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

        /// The kind a request's `kind` names (its name or an alias), as its name.
        pub fn find(name: &str) -> Option<&'static str> {
            $(if name == <$kind as Kind>::NAME || <$kind as Kind>::ALIASES.contains(&name) {
                return Some(<$kind as Kind>::NAME);
            })*
            None
        }

        /// The members a kind's request may have.
        pub fn members(kind: &str) -> &'static [&'static str] {
            $(if Some(<$kind as Kind>::NAME) == find(kind) {
                return <$kind as Kind>::MEMBERS;
            })*
            &[]
        }

        /// Read and compile a request of the kind `kind` (a name or an alias).
        pub fn prepare(kind: &str, request: Value) -> Result<Prepared, Error> {
            let name = find(kind).ok_or_else(|| unknown(kind))?;
            let obj = request::object(request)?;
            $(if name == <$kind as Kind>::NAME {
                return <$kind as Kind>::prepare(obj).map(Prepared::$variant);
            })*
            Err(unknown(kind))
        }

        impl Prepared {
            /// The kind's name.
            pub fn kind(&self) -> &'static str {
                match self {
                    $(Prepared::$variant(_) => <$kind as Kind>::NAME,)*
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
}

/// The error for a `kind` that names none.
fn unknown(kind: &str) -> Error {
    Error::Invalid(vec![FieldError::new(
        "kind",
        format!("unknown job kind `{kind}`; known: {}", NAMES.join(", ")),
    )])
}
