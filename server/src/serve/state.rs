//! The configuration and the state shared by every handler.

use super::problem::Problem;
use super::store::Store;
use super::worker::Pool;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{Semaphore, watch};

/// The limits that keep work bounded; every one is a `kea serve` option.
#[derive(Clone, Debug)]
pub struct Limits {
    /// Largest request body, bytes.
    pub max_body_bytes: usize,
    /// How long a request's line and headers, and then its body, may each take to
    /// arrive.
    pub read_timeout: Duration,
    /// Largest work (the estimate of `jobs::cost`, ≈ ns) answered synchronously by
    /// `POST /v1/analyze`.
    pub sync_work: f64,
    /// Largest work accepted at all (a job above this is refused as absurd).
    pub max_work: f64,
    /// Wall-clock limit of one job.
    pub job_time: Duration,
    /// Most jobs waiting in the queue; more submissions get 429.
    pub queue: u64,
    /// How long a shutdown lets running jobs finish before re-queueing them.
    pub shutdown_grace: Duration,
    /// How long a finished job is kept (then deleted with its result); `None`: until
    /// it is purged.
    pub keep_finished: Option<Duration>,
    /// How often an analysis or Monte Carlo job keeps its state (what a restart loses).
    pub state_every: Duration,
}

/// The longest a synchronous analysis runs however low its estimate (the estimate
/// keeps it far below this; a model it undercounts is stopped here, not left running).
pub const SYNC_TIME_LIMIT: Duration = Duration::from_secs(60);

impl Limits {
    /// A synchronous analysis's wall-clock limit: [`SYNC_TIME_LIMIT`], or the job time
    /// limit where that is shorter.
    pub fn sync_time(&self) -> Duration {
        self.job_time.min(SYNC_TIME_LIMIT)
    }
}

#[derive(Clone, Debug)]
pub struct Config {
    pub token: Option<String>,
    /// Without a token (and without --allow-no-token): the names besides loopback's
    /// that a /v1 request's Host may give ([`super::auth::addressed_here`]); `None`:
    /// any Host.
    pub host_check: Option<Vec<String>>,
    /// The static web UI; `None` serves no UI.
    pub web_dir: Option<PathBuf>,
    pub cors_origins: Vec<String>,
    pub workers: usize,
    pub limits: Limits,
}

#[derive(Clone)]
pub struct AppState {
    pub config: Arc<Config>,
    pub store: Arc<dyn Store>,
    pub pool: Arc<Pool>,
    /// Bounds the synchronous analyses running at once (they share the cores).
    pub sync_permits: Arc<Semaphore>,
    /// Becomes true when the server shuts down (ends event streams).
    pub shutdown: watch::Receiver<bool>,
}

impl AppState {
    /// Run a store call on a blocking thread.
    pub async fn db<T: Send + 'static>(
        &self,
        f: impl FnOnce(&dyn Store) -> super::store::Result<T> + Send + 'static,
    ) -> Result<T, Problem> {
        let store = Arc::clone(&self.store);
        tokio::task::spawn_blocking(move || f(store.as_ref()))
            .await
            .map_err(Problem::internal)?
            .map_err(Problem::from)
    }
}
