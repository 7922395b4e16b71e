//! The kinds of run, and the one way into each: a request (JSON) is read strictly
//! once, with every problem at its path, and compiled once ([`prepare`]); what was
//! compiled gives the work estimate (`registry::Prepared::work`) and runs with a caller's
//! executor, progress and memo (`registry::Prepared::run`); the outcome renders itself
//! as JSON, a text report and CSV (`registry::Outcome`). The server's jobs, the command line,
//! the wasm module and so the web page's worker all come in here.
//!
//! The kinds are listed once, in [`crate::registry`]: a new kind is its module (a
//! type implementing [`Kind`]) and one line there.

use crate::error::Error;
use crate::exec::{Executor, Memo};
use crate::progress::Progress;
use crate::work::Work;
use serde::{Deserialize, Serialize};
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
    /// What the request asks that its kind cannot give (a Monte Carlo's runs beyond
    /// its limits, for the model's size), checked after the work is estimated: a
    /// request both too large and out of bounds is told of its work first.
    fn check(_request: &Self::Request) -> Result<(), Error> {
        Ok(())
    }
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

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Filled by the caller (the core has no clock: it also runs in wasm).
    pub wall_ms: f64,
    /// The run went on from the state an interrupted run of the same request kept
    /// after this step ([`crate::resume`]; a server's job after a restart): `wall_ms`
    /// is then the time from there. Absent for a run from the start.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resumed_from_step: Option<u64>,
}
