//! Job kinds: what a job computes, independent of queues, storage and HTTP — the
//! core's kinds ([`kea_core::registry`]), each run here on a rayon pool. A request (the
//! `model_id` already resolved to `model`) is read and compiled by its kind into a
//! [`PreparedJob`], which estimates its work and runs on a worker thread with progress
//! and cancellation. A new kind is the core's: nothing here changes.

use crate::parallel::Rayon;
use kea_core::exec::Memo;
use kea_core::{Error, Progress};
use serde_json::Value;
use std::time::Instant;

/// A work estimate, in units of about a nanosecond of one core ([`kea_core::work`]).
pub use kea_core::work::Work;

/// A validated request, ready to run.
pub struct PreparedJob(kea_core::registry::Prepared);

/// What a finished job produced.
pub struct JobOutput {
    /// The result document (JSON text).
    pub result_json: String,
    /// Time series as CSV, when the kind has them.
    pub traces_csv: Option<String>,
}

/// Read, compile and check a request (the job body without `kind`) of the kind `kind` (a
/// name or an alias). Errors carry paths into the request body
/// (`model.system.a[0][1]`, `set.q`).
pub fn prepare(kind: &str, request: Value) -> Result<PreparedJob, Error> {
    kea_core::registry::prepare_checked(kind, request).map(PreparedJob)
}

/// The kind a request's `kind` names, as its name; `None` for none.
pub fn find(kind: &str) -> Option<&'static str> {
    kea_core::registry::find(kind)
}

/// Every kind's name, in the order errors list them.
pub fn names() -> &'static [&'static str] {
    kea_core::registry::NAMES
}

impl PreparedJob {
    /// The estimated work, used to choose sync vs job and to refuse the absurd.
    pub fn work(&self) -> Work {
        self.0.work()
    }

    /// Run to completion on every core, reporting progress; `Error::Cancelled` when
    /// progress said stop. `stop` says the same as progress's answer, from any thread:
    /// for computations running beside others, which do not report (a synthesis's
    /// analyses). `memo` keeps finished parts and states for a run of the same job
    /// after a restart, and holds those of an earlier run (`kea_core::resume`).
    pub fn run(
        self,
        progress: &mut dyn Progress,
        stop: &(dyn Fn() -> bool + Sync),
        memo: &dyn Memo,
    ) -> Result<JobOutput, Error> {
        let outcome = self.outcome(progress, stop, memo)?;
        Ok(JobOutput {
            result_json: outcome.to_json(),
            traces_csv: outcome.csv(),
        })
    }

    /// [`PreparedJob::run`] for a response that is the result alone (a synchronous
    /// analysis): its JSON text, without the traces CSV a job keeps.
    pub fn run_result(
        self,
        progress: &mut dyn Progress,
        stop: &(dyn Fn() -> bool + Sync),
        memo: &dyn Memo,
    ) -> Result<String, Error> {
        Ok(self.outcome(progress, stop, memo)?.to_json())
    }

    fn outcome(
        self,
        progress: &mut dyn Progress,
        stop: &(dyn Fn() -> bool + Sync),
        memo: &dyn Memo,
    ) -> Result<kea_core::registry::Outcome, Error> {
        let start = Instant::now();
        let exec = Rayon::new(None)
            .map_err(|e| Error::invalid("", e))?
            .stopping_when(stop);
        let mut outcome = self.0.run(&exec, progress, memo)?;
        outcome.timing().wall_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(outcome)
    }
}
