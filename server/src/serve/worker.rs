//! The worker pool: dedicated threads that take the oldest queued job from the
//! store, run it with progress and cancellation, and record how it ended.
//!
//! The store is the queue, so nothing submitted lives only in memory: a job that
//! was running when the process died is re-queued on start, and a graceful shutdown
//! lets running jobs finish for a grace period, then re-queues them.

use super::problem::{Problem, kind};
use super::store::{Enqueued, GiveUp, JobRecord, JobStatus, Outcome, Requeued, Store, now_rfc3339};
use axum::http::StatusCode;
use kea_core::Error;
use kea_core::exec::Memo;
use std::cell::Cell;
use std::collections::HashMap;
use std::ops::ControlFlow;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tokio::sync::watch;

/// A job's [`Memo`] in the store: what an earlier run of the job kept, read once at
/// its start, and what this run finishes, written in batches at most every
/// [`PERSIST_EVERY`] (one transaction each, not one per part: a synthesis may finish
/// hundreds of analyses a second) and at a shutdown. A crash loses at most the last
/// batch; a job's end drops them all ([`Store::finish_job`]).
///
/// What an earlier run kept is taken only if the same kea executable kept it
/// ([`BUILD_KEY`]): after an upgrade a job starts over, so that its result comes from
/// one build, not from the old one's parts and states and the new one's rest.
struct StoreMemo<'a> {
    store: &'a dyn Store,
    job: &'a str,
    earlier: HashMap<String, String>,
    pending: Mutex<(Vec<(String, String)>, Instant)>,
    /// When a long computation's state was last asked for ([`Memo::state_due`]), and
    /// how often it is.
    state_at: Mutex<Instant>,
    state_every: Duration,
}

impl<'a> StoreMemo<'a> {
    fn new(store: &'a dyn Store, job: &'a str, state_every: Duration, build: &str) -> Self {
        let mut earlier = store.checkpoints(job).unwrap_or_else(|e| {
            tracing::warn!(error = %e, "cannot read the job's checkpoints: it starts over");
            HashMap::new()
        });
        let kept_by = earlier.remove(BUILD_KEY);
        if !earlier.is_empty() {
            if kept_by.as_deref() == Some(build) {
                tracing::info!(
                    kept = earlier.len(),
                    "resuming from an earlier run's checkpoints"
                );
            } else {
                tracing::warn!(
                    kept = earlier.len(),
                    kept_by = kept_by
                        .as_deref()
                        .unwrap_or("a kea before builds were recorded"),
                    this = build,
                    "the job's checkpoints were kept by another kea executable: it starts over"
                );
                earlier.clear();
            }
        }
        StoreMemo {
            store,
            job,
            earlier,
            // (Written with the first batch: a job that keeps nothing writes nothing.)
            pending: Mutex::new((
                vec![(BUILD_KEY.to_string(), build.to_string())],
                Instant::now(),
            )),
            state_at: Mutex::new(Instant::now()),
            state_every,
        }
    }

    fn flush(&self) {
        let batch = match self.pending.lock() {
            Ok(mut p) => {
                p.1 = Instant::now();
                std::mem::take(&mut p.0)
            }
            Err(_) => return,
        };
        if !batch.is_empty()
            && let Err(e) = self.store.keep_checkpoints(self.job, &batch)
        {
            tracing::warn!(error = %e, "cannot record the job's checkpoints");
        }
    }
}

impl Memo for StoreMemo<'_> {
    fn recall(&self, key: &str) -> Option<String> {
        self.earlier.get(key).cloned()
    }

    fn keep(&self, key: &str, value: &str) {
        let due = match self.pending.lock() {
            Ok(mut p) => {
                p.0.push((key.to_string(), value.to_string()));
                p.1.elapsed() >= PERSIST_EVERY
            }
            Err(_) => false,
        };
        if due {
            self.flush();
        }
    }

    /// Written at once, with whatever is pending (in order: the later value of a key
    /// replaces the earlier).
    fn keep_state(&self, key: &str, value: &str) {
        if let Ok(mut p) = self.pending.lock() {
            p.0.push((key.to_string(), value.to_string()));
        }
        self.flush();
    }

    /// Every `state_every` (`kea serve --state-every`; the state then kept replaces
    /// the one before). A state is mostly the traces so far: near a run's end, 2 MB
    /// made in ≈ 1 ms at N = 10 with 1000 trace points, 32 MB in ≈ 55 ms at N = 200
    /// with 768 (BENCHMARKS.md), then written to the store.
    fn state_due(&self) -> bool {
        let Ok(mut at) = self.state_at.lock() else {
            return false;
        };
        if at.elapsed() < self.state_every {
            return false;
        }
        *at = Instant::now();
        true
    }
}

/// The checkpoint that names the kea executable that kept a job's other checkpoints.
const BUILD_KEY: &str = "kea-build";

/// This kea executable: its version, and its file's size and modification time (read
/// once, at start). A rebuilt or upgraded kea differs; the version alone where the
/// file cannot be read.
fn this_build() -> String {
    let version = env!("CARGO_PKG_VERSION");
    let file = std::env::current_exe().and_then(std::fs::metadata);
    match file.and_then(|m| Ok((m.len(), m.modified()?))) {
        Ok((len, modified)) => {
            let since = modified
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap_or_default();
            format!(
                "{version} {len} bytes, modified {}.{:09}",
                since.as_secs(),
                since.subsec_nanos()
            )
        }
        Err(_) => version.to_string(),
    }
}

/// A job's state as seen live (between store writes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Snapshot {
    pub status: JobStatus,
    pub progress: f64,
}

/// The in-memory side of a queued or running job of this process.
pub struct LiveJob {
    cancel: AtomicBool,
    tx: watch::Sender<Snapshot>,
}

impl LiveJob {
    fn new(status: JobStatus, progress: f64) -> Arc<LiveJob> {
        Arc::new(LiveJob {
            cancel: AtomicBool::new(false),
            tx: watch::Sender::new(Snapshot { status, progress }),
        })
    }

    pub fn subscribe(&self) -> watch::Receiver<Snapshot> {
        self.tx.subscribe()
    }

    pub fn snapshot(&self) -> Snapshot {
        *self.tx.borrow()
    }
}

/// What `cancel` did.
#[derive(Debug, PartialEq)]
pub enum CancelOutcome {
    /// It was queued and is now cancelled.
    Cancelled,
    /// It is running; it stops at its next progress report.
    Requested,
    /// It had already finished.
    AlreadyFinished(JobStatus),
    NotFound,
}

const RUNNING: u8 = 0;
/// Take no new jobs; let running ones finish.
const DRAINING: u8 = 1;
/// Interrupt running jobs and re-queue them.
const STOPPING: u8 = 2;

/// How often a running job's progress is written to the store.
const PERSIST_EVERY: Duration = Duration::from_millis(500);
/// Idle workers look at the store this often even without a wake-up (another
/// instance sharing the store may have queued work).
const POLL_EVERY: Duration = Duration::from_secs(1);

pub struct Pool {
    store: Arc<dyn Store>,
    job_time_limit: Duration,
    /// How often an analysis or Monte Carlo job keeps its state ([`StoreMemo`]).
    state_every: Duration,
    /// This kea executable ([`this_build`]), named with what a job keeps.
    build: String,
    /// Live jobs by id. Claims, submissions and cancellations take this lock so a
    /// cancellation never slips between "claimed in the store" and "known here".
    live: Mutex<HashMap<String, Arc<LiveJob>>>,
    /// Requests compiled at submission, by job id, so that a worker runs them without
    /// compiling them again: at most one per worker (the next to run; a compiled
    /// model may be far larger than its JSON), the rest compiled when claimed — as
    /// are jobs after a restart, or queued by another instance.
    prepared: Mutex<HashMap<String, super::jobs::PreparedJob>>,
    workers: usize,
    wake: Mutex<u64>,
    cond: Condvar,
    state: AtomicU8,
    busy: AtomicUsize,
    threads: Mutex<Vec<JoinHandle<()>>>,
}

/// Why a running job was asked to stop.
#[derive(Clone, Copy, PartialEq)]
enum Stop {
    Cancelled,
    TimeLimit,
    Shutdown,
}

impl Pool {
    /// Re-queue jobs a previous process left running, then start `workers` threads.
    pub fn start(
        store: Arc<dyn Store>,
        workers: usize,
        job_time_limit: Duration,
        state_every: Duration,
    ) -> Result<Arc<Pool>, super::store::StoreError> {
        let give_up = GiveUp {
            after: MAX_INTERRUPTIONS,
            error_json: interrupted_problem(),
        };
        let Requeued {
            requeued,
            cancelled,
            failed,
        } = store.requeue_all_running(&give_up)?;
        if failed > 0 {
            tracing::error!(
                failed,
                "failed jobs that were running when kea stopped, {MAX_INTERRUPTIONS} times each: not run again"
            );
        }
        if requeued > 0 {
            tracing::warn!(
                requeued,
                "re-queued jobs that were running when kea stopped"
            );
        }
        if cancelled > 0 {
            tracing::warn!(
                cancelled,
                "cancelled jobs that were asked to cancel while running when kea stopped"
            );
        }
        let pool = Arc::new(Pool {
            store,
            job_time_limit,
            state_every,
            build: this_build(),
            live: Mutex::new(HashMap::new()),
            prepared: Mutex::new(HashMap::new()),
            workers: workers.max(1),
            wake: Mutex::new(0),
            cond: Condvar::new(),
            state: AtomicU8::new(RUNNING),
            busy: AtomicUsize::new(0),
            threads: Mutex::new(Vec::new()),
        });
        let mut threads = pool.threads.lock().unwrap();
        for i in 0..workers.max(1) {
            let p = Arc::clone(&pool);
            threads.push(
                std::thread::Builder::new()
                    .name(format!("kea-worker-{i}"))
                    .spawn(move || p.work_loop())
                    .expect("spawn worker thread"),
            );
        }
        drop(threads);
        Ok(pool)
    }

    /// Store a new queued job, unless `queue_limit` jobs are queued already (checked
    /// and inserted at once), and wake a worker. `prepared` is its request as the
    /// submission compiled it, kept for the worker while there is room ([`Pool::prepared`]).
    pub fn submit(
        &self,
        job: &JobRecord,
        queue_limit: u64,
        prepared: super::jobs::PreparedJob,
    ) -> Result<Enqueued, super::store::StoreError> {
        {
            let mut live = self.live.lock().unwrap();
            let outcome = self.store.enqueue_job(job, queue_limit)?;
            if outcome != Enqueued::Queued {
                return Ok(outcome);
            }
            live.insert(
                job.id.clone(),
                LiveJob::new(JobStatus::Queued, job.progress),
            );
            let mut kept = self.prepared.lock().unwrap();
            if kept.len() < self.workers {
                kept.insert(job.id.clone(), prepared);
            }
        }
        self.wake_one();
        Ok(Enqueued::Queued)
    }

    pub fn live(&self, id: &str) -> Option<Arc<LiveJob>> {
        self.live.lock().unwrap().get(id).cloned()
    }

    /// Every live job's snapshot at once (for a list: taken before its records are
    /// read, as [`Self::live`] is for one job).
    pub fn live_snapshots(&self) -> std::collections::HashMap<String, Snapshot> {
        self.live
            .lock()
            .unwrap()
            .iter()
            .map(|(id, job)| (id.clone(), job.snapshot()))
            .collect()
    }

    pub fn cancel(&self, id: &str) -> Result<CancelOutcome, super::store::StoreError> {
        let mut live = self.live.lock().unwrap();
        if self.store.cancel_queued(id, &now_rfc3339())? {
            self.prepared.lock().unwrap().remove(id);
            if let Some(job) = live.remove(id) {
                job.tx.send_replace(Snapshot {
                    status: JobStatus::Cancelled,
                    progress: job.snapshot().progress,
                });
            }
            return Ok(CancelOutcome::Cancelled);
        }
        match self.store.get_job(id)? {
            None => Ok(CancelOutcome::NotFound),
            Some(j) if j.status.is_terminal() => Ok(CancelOutcome::AlreadyFinished(j.status)),
            Some(_) => {
                // Recorded first: if the process stops before the job sees the flag,
                // the job is cancelled, not run again.
                self.store.request_cancel(id)?;
                if let Some(job) = live.get(id) {
                    job.cancel.store(true, Ordering::SeqCst);
                }
                Ok(CancelOutcome::Requested)
            }
        }
    }

    /// Jobs running now.
    pub fn busy(&self) -> usize {
        self.busy.load(Ordering::SeqCst)
    }

    fn wake_one(&self) {
        *self.wake.lock().unwrap() += 1;
        self.cond.notify_one();
    }

    fn wake_all(&self) {
        *self.wake.lock().unwrap() += 1;
        self.cond.notify_all();
    }

    /// Stop taking jobs; give running ones `grace` to finish, then interrupt and
    /// re-queue them; join the threads.
    pub fn shutdown(&self, grace: Duration) {
        self.state.store(DRAINING, Ordering::SeqCst);
        self.wake_all();
        let deadline = Instant::now() + grace;
        while self.busy() > 0 && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        if self.busy() > 0 {
            tracing::warn!(
                running = self.busy(),
                "grace period over: re-queueing running jobs"
            );
        }
        self.state.store(STOPPING, Ordering::SeqCst);
        self.wake_all();
        let threads = std::mem::take(&mut *self.threads.lock().unwrap());
        for t in threads {
            let _ = t.join();
        }
    }

    fn work_loop(self: Arc<Self>) {
        while self.state.load(Ordering::SeqCst) == RUNNING {
            let seen = *self.wake.lock().unwrap();
            match self.claim() {
                Ok(Some((job, live))) => {
                    self.busy.fetch_add(1, Ordering::SeqCst);
                    self.run_job(job, live);
                    self.busy.fetch_sub(1, Ordering::SeqCst);
                }
                Ok(None) => {
                    let guard = self.wake.lock().unwrap();
                    if *guard == seen && self.state.load(Ordering::SeqCst) == RUNNING {
                        let _ = self.cond.wait_timeout(guard, POLL_EVERY);
                    }
                }
                Err(e) => {
                    tracing::error!(error = %e, "cannot claim a job");
                    std::thread::sleep(POLL_EVERY);
                }
            }
        }
    }

    fn claim(&self) -> Result<Option<(JobRecord, Arc<LiveJob>)>, super::store::StoreError> {
        let mut live = self.live.lock().unwrap();
        let Some(job) = self.store.claim_next(&now_rfc3339())? else {
            return Ok(None);
        };
        // A job run again (after a restart) keeps the progress it had reached: it
        // shows that until the new run passes it, so progress never goes back.
        let entry = live
            .entry(job.id.clone())
            .or_insert_with(|| LiveJob::new(JobStatus::Running, job.progress))
            .clone();
        entry.tx.send_modify(|s| {
            s.status = JobStatus::Running;
            s.progress = s.progress.max(job.progress);
        });
        Ok(Some((job, entry)))
    }

    fn run_job(&self, job: JobRecord, live: Arc<LiveJob>) {
        let span = tracing::info_span!("job", id = %job.id, kind = %job.kind);
        let _enter = span.enter();
        tracing::info!(attempt = job.attempts, "job started");
        let started = Instant::now();
        let stop = Cell::new(None::<Stop>);
        let result = std::panic::catch_unwind(AssertUnwindSafe(|| {
            let kept = self.prepared.lock().unwrap().remove(&job.id);
            let prepared = match kept {
                Some(p) => p,
                None => {
                    let request: serde_json::Value = serde_json::from_str(&job.request_json)
                        .map_err(|e| {
                            Error::invalid("", format!("stored request unreadable: {e}"))
                        })?;
                    super::jobs::prepare(&job.kind, request)?
                }
            };
            let memo = StoreMemo::new(&*self.store, &job.id, self.state_every, &self.build);
            let mut last_persist = Instant::now();
            let mut progress = |fraction: f64| {
                // Never backwards, whatever order the core's parts report in.
                let fraction = fraction.clamp(0.0, 1.0);
                if fraction > live.snapshot().progress {
                    live.tx
                        .send_modify(|s| s.progress = s.progress.max(fraction));
                }
                if last_persist.elapsed() >= PERSIST_EVERY {
                    last_persist = Instant::now();
                    if let Err(e) = self.store.set_progress(&job.id, live.snapshot().progress) {
                        tracing::warn!(error = %e, "cannot record progress");
                    }
                }
                let reason = if live.cancel.load(Ordering::Relaxed) {
                    Some(Stop::Cancelled)
                } else if self.state.load(Ordering::Relaxed) == STOPPING {
                    Some(Stop::Shutdown)
                } else if started.elapsed() > self.job_time_limit {
                    Some(Stop::TimeLimit)
                } else {
                    None
                };
                match reason {
                    Some(r) => {
                        stop.set(Some(r));
                        ControlFlow::Break(())
                    }
                    None => ControlFlow::Continue(()),
                }
            };
            // The same reasons, for the computations that run beside others.
            let stop_requested = || {
                live.cancel.load(Ordering::Relaxed)
                    || self.state.load(Ordering::Relaxed) == STOPPING
                    || started.elapsed() > self.job_time_limit
            };
            let out = prepared.run(&mut progress, &stop_requested, &memo);
            if matches!(stop.get(), Some(Stop::Shutdown)) {
                // Re-queued next: what this run finished is kept for the next one.
                memo.flush();
            }
            out
        }));
        let outcome = match result {
            Ok(Ok(out)) => Outcome::Succeeded {
                result_json: out.result_json,
                traces_csv: out.traces_csv,
            },
            Ok(Err(Error::Cancelled)) => match stop.get() {
                Some(Stop::Shutdown) => {
                    tracing::info!("interrupted by shutdown: re-queued");
                    // Recorded before re-queueing: the next run shows it until it passes.
                    let reached = live.snapshot().progress;
                    if let Err(e) = self.store.set_progress(&job.id, reached) {
                        tracing::warn!(error = %e, "cannot record progress");
                    }
                    self.forget(&job.id, JobStatus::Queued);
                    if let Err(e) = self.store.requeue(&job.id) {
                        tracing::error!(error = %e, "cannot re-queue job");
                    }
                    return;
                }
                Some(Stop::TimeLimit) => failed(
                    Problem::new(
                        StatusCode::UNPROCESSABLE_ENTITY,
                        kind::TOO_MUCH_WORK,
                        "the job exceeded its time limit",
                    )
                    .detail(format!(
                        "stopped after {:.0} s (server option --job-time-limit); reduce \
                         the steps or the state dimension",
                        self.job_time_limit.as_secs_f64()
                    )),
                ),
                _ => Outcome::Cancelled,
            },
            Ok(Err(e)) => failed(Problem::from_core(e)),
            Err(_) => failed(Problem::internal("the job panicked")),
        };
        let status = match &outcome {
            Outcome::Succeeded { .. } => JobStatus::Succeeded,
            Outcome::Failed { .. } => JobStatus::Failed,
            Outcome::Cancelled => JobStatus::Cancelled,
        };
        let reached = match status {
            JobStatus::Succeeded => 1.0,
            _ => live.snapshot().progress,
        };
        if let Err(e) = self
            .store
            .finish_job(&job.id, &outcome, reached, &now_rfc3339())
        {
            tracing::error!(error = %e, "cannot record the job's outcome");
        }
        tracing::info!(
            status = status.as_str(),
            ms = started.elapsed().as_secs_f64() * 1e3,
            "job finished"
        );
        self.forget(&job.id, status);
    }

    /// Publish the final state of a live job and drop it from the live set.
    fn forget(&self, id: &str, status: JobStatus) {
        self.prepared.lock().unwrap().remove(id);
        if let Some(job) = self.live.lock().unwrap().remove(id) {
            let progress = if status == JobStatus::Succeeded {
                1.0
            } else {
                job.snapshot().progress
            };
            job.tx.send_replace(Snapshot { status, progress });
        }
    }
}

/// A failed job's error document: the problem without its HTTP status.
/// A job found running at start-up this many times (each time the process ended
/// without finishing or re-queuing it: a crash, a kill, the machine's power) fails
/// instead of running again — so that a job that brings the server down (its memory,
/// say) does not do so at every start. A graceful shutdown's re-queue is not counted.
pub const MAX_INTERRUPTIONS: u32 = 3;

/// The problem document of a job failed after [`MAX_INTERRUPTIONS`].
fn interrupted_problem() -> String {
    let p = Problem::new(
        StatusCode::INTERNAL_SERVER_ERROR,
        kind::INTERRUPTED,
        "the server stopped while running this job, too many times",
    )
    .detail(format!(
        "kea ended without finishing or re-queuing this job {MAX_INTERRUPTIONS} times while \
         it ran (a crash, a kill or a power loss), so it is not run again: if it is what \
         brought the server down (its memory, say), reduce its steps or its state \
         dimension; otherwise submit it again"
    ));
    problem_json(p)
}

fn failed(p: Problem) -> Outcome {
    Outcome::Failed {
        error_json: problem_json(p),
    }
}

/// A stored job's problem document: without `status` (the job's own says it failed).
fn problem_json(p: Problem) -> String {
    let mut v = serde_json::to_value(&p).expect("problem serialises");
    if let Some(o) = v.as_object_mut() {
        o.remove("status");
    }
    v.to_string()
}
