//! Persistence behind one small interface: models, jobs and job results.
//!
//! [`Store`] is all the rest of the server knows about storage. The default is
//! [`sqlite::SqliteStore`] (embedded, one file in the data directory). The job queue
//! *is* the store (`claim_next` takes the oldest queued job atomically), so a shared
//! database (e.g. PostgreSQL with `FOR UPDATE SKIP LOCKED`) can later feed several
//! kea instances by implementing this trait.

pub mod sqlite;

use serde::Serialize;
use std::fmt;

/// A storage failure: the server's fault (500), never the client's.
#[derive(Debug)]
pub struct StoreError(pub String);

impl fmt::Display for StoreError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "storage error: {}", self.0)
    }
}

impl std::error::Error for StoreError {}

pub type Result<T> = std::result::Result<T, StoreError>;

/// A job's lifecycle: queued → running → succeeded | failed | cancelled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum JobStatus {
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl JobStatus {
    pub const ALL: [JobStatus; 5] = [
        JobStatus::Queued,
        JobStatus::Running,
        JobStatus::Succeeded,
        JobStatus::Failed,
        JobStatus::Cancelled,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            JobStatus::Queued => "queued",
            JobStatus::Running => "running",
            JobStatus::Succeeded => "succeeded",
            JobStatus::Failed => "failed",
            JobStatus::Cancelled => "cancelled",
        }
    }

    pub fn parse(s: &str) -> Option<JobStatus> {
        JobStatus::ALL.into_iter().find(|x| x.as_str() == s)
    }

    /// Whether the job will not change any more.
    pub fn is_terminal(self) -> bool {
        matches!(
            self,
            JobStatus::Succeeded | JobStatus::Failed | JobStatus::Cancelled
        )
    }
}

/// A stored model (the JSON exactly as validated and stored).
#[derive(Clone, Debug)]
pub struct ModelRecord {
    pub id: String,
    pub name: Option<String>,
    pub created_at: String,
    pub model_json: String,
}

/// A model in a listing (without its body).
#[derive(Clone, Debug, Serialize)]
pub struct ModelSummary {
    pub id: String,
    pub name: Option<String>,
    pub created_at: String,
}

/// A job as stored. `request_json` is self-contained (a `model_id` was resolved to
/// the model at submission), so deleting a model never breaks a queued job.
#[derive(Clone, Debug)]
pub struct JobRecord {
    pub id: String,
    /// The kind's name (`jobs::find`); a job stored by an earlier kea may have a
    /// former name, an alias, which still reads as its kind (`simulation`).
    pub kind: String,
    pub status: JobStatus,
    pub progress: f64,
    pub request_json: String,
    /// The work estimate at submission (`jobs::cost`, about 1 ns of one core a unit).
    pub work: f64,
    pub created_at: String,
    pub started_at: Option<String>,
    pub finished_at: Option<String>,
    /// Problem-details JSON of a failed job.
    pub error_json: Option<String>,
    /// How many times a worker has started this job (re-queues count).
    pub attempts: u32,
    /// A cancel was asked for (`DELETE`), whether or not the job has stopped yet.
    pub cancel_requested: bool,
    /// The submitted model's `name`, if it has one (for a list of jobs).
    pub model_name: Option<String>,
}

/// How a job ended.
#[derive(Clone, Debug)]
pub enum Outcome {
    Succeeded {
        result_json: String,
        traces_csv: Option<String>,
    },
    Failed {
        error_json: String,
    },
    Cancelled,
}

/// What [`Store::enqueue_job`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Enqueued {
    Queued,
    /// Not inserted: this many jobs are queued (at least the limit).
    Full {
        queued: u64,
    },
}

/// What [`Store::delete_finished_job`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Deleted {
    Deleted,
    NotFound,
    /// Not deleted: the job is queued or running.
    NotFinished(JobStatus),
}

/// When [`Store::requeue_all_running`] stops running a job again.
#[derive(Clone, Debug)]
pub struct GiveUp {
    /// After this many interruptions (processes that ended while the job ran).
    pub after: u32,
    /// The failed job's problem document.
    pub error_json: String,
}

/// What [`Store::requeue_all_running`] did: how many jobs it re-queued, cancelled
/// (a cancel was asked for) and failed (interrupted too often).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Requeued {
    pub requeued: u64,
    pub cancelled: u64,
    pub failed: u64,
}

/// One page of a listing, newest first; `next_cursor` continues it.
#[derive(Clone, Debug)]
pub struct Page<T> {
    pub items: Vec<T>,
    pub next_cursor: Option<String>,
}

/// Everything the server stores. Implementations must be safe to call from many
/// threads; every method is one short transaction, but [`Store::reclaim_free_space`],
/// a series of them. What a delete removes goes back to the file system, up to a bound
/// at once (a delete stays fast); [`Store::reclaim_free_space`] gives back the rest.
pub trait Store: Send + Sync + 'static {
    fn insert_model(&self, model: &ModelRecord) -> Result<()>;
    fn get_model(&self, id: &str) -> Result<Option<ModelRecord>>;
    /// Newest first; `cursor` is the last id of the previous page.
    fn list_models(&self, cursor: Option<&str>, limit: usize) -> Result<Page<ModelSummary>>;
    /// Whether a model was deleted.
    fn delete_model(&self, id: &str) -> Result<bool>;

    fn insert_job(&self, job: &JobRecord) -> Result<()>;
    /// Insert a queued job unless `queue_limit` jobs are queued already: the count and
    /// the insert in one transaction, so concurrent submissions cannot pass the limit.
    fn enqueue_job(&self, job: &JobRecord, queue_limit: u64) -> Result<Enqueued>;
    fn get_job(&self, id: &str) -> Result<Option<JobRecord>>;
    /// Delete the finished jobs (with their results) that finished before `cutoff`
    /// (RFC 3339); how many.
    fn purge_finished_before(&self, cutoff: &str) -> Result<u64>;
    /// Give all the space that deletes freed back to the file system (after a batch of
    /// deletes); how many bytes. In steps, each its own short transaction, so that
    /// other calls go on between them.
    fn reclaim_free_space(&self) -> Result<u64>;
    /// Newest first, optionally only one status. The records come without their
    /// request (`request_json` empty): a listing shows jobs, and a page of jobs with
    /// requests of up to 2 MiB each would read up to 100 MiB for it.
    fn list_jobs(
        &self,
        status: Option<JobStatus>,
        cursor: Option<&str>,
        limit: usize,
    ) -> Result<Page<JobRecord>>;
    fn count_jobs(&self, status: JobStatus) -> Result<u64>;
    /// Atomically take the oldest queued job and mark it running.
    fn claim_next(&self, started_at: &str) -> Result<Option<JobRecord>>;
    /// Record a running job's progress; it never decreases (a lower value is ignored).
    fn set_progress(&self, id: &str, progress: f64) -> Result<()>;
    /// Record how a running job ended (with its result, if any) and how far it got
    /// (1 for a success; never below the progress recorded before).
    fn finish_job(
        &self,
        id: &str,
        outcome: &Outcome,
        progress: f64,
        finished_at: &str,
    ) -> Result<()>;
    /// Keep what a running job has finished, under keys (one transaction); a run of
    /// the job after a restart reads them back with [`Store::checkpoints`].
    /// [`Store::finish_job`] drops them.
    fn keep_checkpoints(&self, id: &str, entries: &[(String, String)]) -> Result<()>;
    /// What [`Store::keep_checkpoints`] kept for a job.
    fn checkpoints(&self, id: &str) -> Result<std::collections::HashMap<String, String>>;
    /// Record that a cancel was asked for while the job runs (kept with the job, so a
    /// process that stops first does not run it again); false if it is not running.
    fn request_cancel(&self, id: &str) -> Result<bool>;
    /// Put a running job back in the queue (shutdown, crash recovery of one job), or
    /// mark it cancelled if a cancel was asked for. Its progress is kept: a run again
    /// shows it until the new run passes it, so progress never goes back.
    fn requeue(&self, id: &str) -> Result<()>;
    /// At start-up, the jobs a process that died left running: each counts one more
    /// interruption; one whose cancel was asked for is cancelled, one interrupted
    /// `give_up.after` times fails with `give_up.error_json`, any other is re-queued.
    fn requeue_all_running(&self, give_up: &GiveUp) -> Result<Requeued>;
    /// Cancel a queued job (recording that a cancel was asked for); false if it was
    /// not queued.
    fn cancel_queued(&self, id: &str, finished_at: &str) -> Result<bool>;
    /// Delete a finished job (succeeded, failed or cancelled) with its result, in one
    /// transaction; a job still queued or running is left as it is.
    fn delete_finished_job(&self, id: &str) -> Result<Deleted>;
    /// A finished job's result JSON and traces CSV.
    fn get_result(&self, id: &str) -> Result<Option<(String, Option<String>)>>;
}

/// The current time, RFC 3339 (UTC).
pub fn now_rfc3339() -> String {
    time::OffsetDateTime::now_utc()
        .format(&time::format_description::well_known::Rfc3339)
        .expect("RFC 3339 formatting of the current time")
}

/// A new unique, time-ordered id.
pub fn new_id() -> String {
    uuid::Uuid::now_v7().to_string()
}
