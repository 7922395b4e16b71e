//! Job kinds: what a job computes, independent of queues, storage and HTTP.
//!
//! A kind parses a self-contained request (the `model_id` already resolved to
//! `model`) into a [`PreparedJob`], which estimates its work and runs on a worker
//! thread with progress and cancellation. The kinds are `analysis`, `simulation`
//! (Monte Carlo) and `synthesis`; adding one is one module implementing [`JobKind`]
//! plus one line in [`registry`].

pub mod analysis;
pub mod simulation;
pub mod synthesis;

pub use kea_core::cost;
use kea_core::exec::Memo;
use kea_core::{Error, Progress};
use serde_json::Value;
use std::sync::Arc;

/// One kind of computation a job can run.
pub trait JobKind: Send + Sync + 'static {
    /// The `kind` member of a job request, e.g. `"analysis"`.
    fn name(&self) -> &'static str;
    /// Validate a request (the job body without `kind`) and prepare the work.
    /// Errors carry paths into the request body (`model.system.a[0][1]`, `set.q`).
    fn prepare(&self, request: &Value) -> Result<Box<dyn PreparedJob>, Error>;
}

/// A validated request, ready to run.
pub trait PreparedJob: Send {
    /// The estimated work, used to choose sync vs job and to refuse the absurd.
    fn work(&self) -> Work;
    /// Run to completion, reporting progress; `Error::Cancelled` when progress said stop.
    /// `stop` says the same as progress's answer, from any thread: for computations
    /// running beside others, which do not report (a synthesis's analyses). `memo`
    /// keeps finished parts and states for a run of the same job after a restart, and
    /// holds those of an earlier run (a synthesis keeps its analyses, an analysis its
    /// step loop's state, a Monte Carlo its runs' state: `kea_core::resume`).
    fn run(
        self: Box<Self>,
        progress: &mut dyn Progress,
        stop: &(dyn Fn() -> bool + Sync),
        memo: &dyn Memo,
    ) -> Result<JobOutput, Error>;
}

/// A work estimate, in units of about a nanosecond of one core ([`cost`]).
pub use kea_core::cost::Work;

/// What a finished job produced.
pub struct JobOutput {
    /// The result document (JSON text).
    pub result_json: String,
    /// Time series as CSV, when the kind has them.
    pub traces_csv: Option<String>,
}

/// The job kinds this server runs.
#[derive(Clone)]
pub struct Registry {
    kinds: Arc<Vec<Box<dyn JobKind>>>,
}

/// Every kind, in the order they are listed in errors.
pub fn registry() -> Registry {
    Registry {
        kinds: Arc::new(vec![
            Box::new(analysis::Analysis),
            Box::new(simulation::Simulation),
            Box::new(synthesis::Synthesis),
            // A new kind is one more line here.
        ]),
    }
}

impl Registry {
    pub fn get(&self, name: &str) -> Option<&dyn JobKind> {
        self.kinds
            .iter()
            .find(|k| k.name() == name)
            .map(|k| k.as_ref())
    }

    pub fn names(&self) -> Vec<&'static str> {
        self.kinds.iter().map(|k| k.name()).collect()
    }
}
