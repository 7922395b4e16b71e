//! Handlers for `/v1/jobs`: submit, inspect, list, cancel, results and progress events.

use super::handlers::{check_work, prepare, raw_json, resolve_model_id};
use super::problem::{Problem, kind};
use super::request::{self, JobId, JsonBody};
use super::state::AppState;
use super::store::{Deleted, Enqueued, JobRecord, JobStatus, new_id, now_rfc3339};
use super::worker::{CancelOutcome, Snapshot};
use axum::Json;
use axum::extract::{RawQuery, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use futures_util::Stream;
use kea_core::FieldError;
use serde_json::{Value, json};
use std::convert::Infallible;
use std::time::Duration;

/// The public view of a job: the stored record, with the live progress when this
/// process runs it (fresher than the store's, written every 500 ms). Both only grow,
/// so the larger is the latest, whichever was read first.
pub fn job_view(job: &JobRecord, live: Option<Snapshot>) -> Value {
    let progress = live.map_or(job.progress, |s| s.progress.max(job.progress));
    let mut v = json!({
        "id": job.id,
        "kind": kind_name(&job.kind),
        "model_name": job.model_name,
        "status": job.status,
        "progress": progress,
        "cancel_requested": job.cancel_requested,
        "work": job.work,
        "created_at": job.created_at,
        "started_at": job.started_at,
        "finished_at": job.finished_at,
    });
    if let Some(e) = &job.error_json {
        v["error"] = serde_json::from_str(e).unwrap_or(Value::String(e.clone()));
    }
    v
}

/// A stored job's kind by its name: a job stored under a kind's former name (an alias,
/// such as `simulation` for `monte_carlo`) is shown under the kind's name.
fn kind_name(stored: &str) -> &str {
    super::jobs::find(stored).unwrap_or(stored)
}

async fn load(state: &AppState, id: &str) -> Result<JobRecord, Problem> {
    let key = id.to_string();
    state
        .db(move |s| s.get_job(&key))
        .await?
        .ok_or_else(|| Problem::not_found("job", id))
}

/// A job's view, its live progress read *before* its record: the worker writes the
/// final record before it drops the live job, so a job that ends between the two reads
/// is seen with its final record. (Record first, then live, could pair a stale record
/// with no live progress: GET showed 0.0826, then 0.0472.)
async fn load_view(state: &AppState, id: &str) -> Result<Value, Problem> {
    let live = state.pool.live(id).map(|l| l.snapshot());
    let job = load(state, id).await?;
    Ok(job_view(&job, live))
}

/// `POST /v1/jobs`: `{kind, model | model_id, set?}` → 202 with the queued job.
pub async fn submit(
    State(state): State<AppState>,
    JsonBody(body, _): JsonBody,
) -> Result<Response, Problem> {
    let mut obj = request::object(body)?;
    let names = super::jobs::names().join(", ");
    let kind_name = match obj.remove("kind") {
        Some(Value::String(k)) => k,
        Some(other) => {
            return Err(Problem::invalid(vec![FieldError::new(
                "kind",
                format!(
                    "expected a string (one of: {names}), got {}",
                    request::json_kind(&other)
                ),
            )]));
        }
        None => {
            return Err(Problem::invalid(vec![FieldError::new(
                "kind",
                format!("missing: the job kind, one of: {names}"),
            )]));
        }
    };
    // Stored under the kind's name, whether the request gave it or an alias.
    let Some(kind_name) = super::jobs::find(&kind_name) else {
        return Err(Problem::from_core(kea_core::registry::unknown(&kind_name)));
    };
    let stored = resolve_model_id(&state, &mut obj).await?;
    let model_name = obj
        .get("model")
        .and_then(|m| m.get("name"))
        .and_then(Value::as_str)
        .map(str::to_owned);
    let request = Value::Object(obj);
    let request_json = request.to_string();
    let prepared = prepare(kind_name, request, stored.as_deref()).await?;
    let work = prepared.work();
    check_work(
        &work,
        state.config.limits.max_work,
        kind::TOO_MUCH_WORK,
        "reduce the steps or the state dimension (server option --max-work)",
    )?;
    let job = JobRecord {
        id: new_id(),
        kind: kind_name.to_string(),
        status: JobStatus::Queued,
        progress: 0.0,
        request_json,
        work: work.units,
        created_at: now_rfc3339(),
        started_at: None,
        finished_at: None,
        error_json: None,
        attempts: 0,
        cancel_requested: false,
        model_name,
    };
    let pool = state.pool.clone();
    let stored = job.clone();
    let queue_limit = state.config.limits.queue;
    let outcome = tokio::task::spawn_blocking(move || pool.submit(&stored, queue_limit, prepared))
        .await
        .map_err(Problem::internal)??;
    if let Enqueued::Full { queued } = outcome {
        return Err(Problem::new(
            StatusCode::TOO_MANY_REQUESTS,
            kind::QUEUE_FULL,
            "the job queue is full",
        )
        .detail(format!(
            "{queued} jobs are waiting (limit {queue_limit}); retry later"
        ))
        .header(header::RETRY_AFTER, "5"));
    }
    let mut res = (StatusCode::ACCEPTED, Json(job_view(&job, None))).into_response();
    res.headers_mut().insert(
        header::LOCATION,
        HeaderValue::from_str(&format!("/v1/jobs/{}", job.id)).expect("ids are ASCII"),
    );
    Ok(res)
}

/// `GET /v1/jobs/{id}`.
pub async fn get(State(state): State<AppState>, JobId(id): JobId) -> Result<Json<Value>, Problem> {
    Ok(Json(load_view(&state, &id).await?))
}

/// `GET /v1/jobs?status&limit&cursor`: newest first.
pub async fn list(
    State(state): State<AppState>,
    RawQuery(raw): RawQuery,
) -> Result<Json<Value>, Problem> {
    let q = request::list_query(raw, &["status"])?;
    let status = match q.rest.get("status") {
        None => None,
        Some(s) => Some(JobStatus::parse(s).ok_or_else(|| {
            request::query_problem(vec![FieldError::new(
                "status",
                format!(
                    "expected one of: {}; got `{s}`",
                    JobStatus::ALL.map(|s| s.as_str()).join(", ")
                ),
            )])
        })?),
    };
    // Live progress first, then the records (see `load_view`).
    let live = state.pool.live_snapshots();
    let page = state
        .db(move |s| s.list_jobs(status, q.cursor.as_deref(), q.limit))
        .await?;
    let items: Vec<Value> = page
        .items
        .iter()
        .map(|j| job_view(j, live.get(&j.id).copied()))
        .collect();
    Ok(Json(
        json!({ "items": items, "next_cursor": page.next_cursor }),
    ))
}

/// `DELETE /v1/jobs/{id}`: cancel. 200 with the job (cancelled, or still running
/// with the cancellation requested); 409 if it had already finished.
/// `?purge=true`: delete a finished job and its result instead (204; 409 while it
/// is queued or running).
pub async fn cancel(
    State(state): State<AppState>,
    JobId(id): JobId,
    RawQuery(raw): RawQuery,
) -> Result<Response, Problem> {
    if request::flag_query(raw, "purge")? {
        return purge(&state, &id).await;
    }
    let pool = state.pool.clone();
    let key = id.clone();
    let outcome = tokio::task::spawn_blocking(move || pool.cancel(&key))
        .await
        .map_err(Problem::internal)??;
    match outcome {
        CancelOutcome::NotFound => Err(Problem::not_found("job", &id)),
        CancelOutcome::AlreadyFinished(s) => Err(Problem::conflict(
            "the job has already finished",
            format!("job `{id}` is {}; there is nothing to cancel", s.as_str()),
        )),
        CancelOutcome::Cancelled | CancelOutcome::Requested => {
            let mut v = load_view(&state, &id).await?;
            v["cancel_requested"] = Value::Bool(true);
            Ok((StatusCode::OK, Json(v)).into_response())
        }
    }
}

/// Delete the finished job `id` with its result.
async fn purge(state: &AppState, id: &str) -> Result<Response, Problem> {
    let key = id.to_string();
    match state.db(move |s| s.delete_finished_job(&key)).await? {
        Deleted::Deleted => Ok(StatusCode::NO_CONTENT.into_response()),
        Deleted::NotFound => Err(Problem::not_found("job", id)),
        Deleted::NotFinished(s) => Err(Problem::conflict(
            "the job has not finished",
            format!(
                "job `{id}` is {}: only a finished job (succeeded, failed or cancelled) is \
                 purged; cancel it first (DELETE /v1/jobs/{id}), then purge it once it has \
                 stopped",
                s.as_str()
            ),
        )),
    }
}

/// The finished job, or 409 while it is not (and for a failed or cancelled job).
async fn finished(state: &AppState, id: &str) -> Result<(String, Option<String>), Problem> {
    let job = load(state, id).await?;
    if job.status != JobStatus::Succeeded {
        let detail = match job.status {
            JobStatus::Queued | JobStatus::Running => format!(
                "job `{id}` is {}; poll GET /v1/jobs/{id} or follow /v1/jobs/{id}/events",
                job.status.as_str()
            ),
            s => format!("job `{id}` is {} and has no result", s.as_str()),
        };
        return Err(Problem::conflict("the job has no result (yet)", detail));
    }
    let key = id.to_string();
    state
        .db(move |s| s.get_result(&key))
        .await?
        .ok_or_else(|| Problem::internal(format!("job {id} succeeded without a stored result")))
}

/// `GET /v1/jobs/{id}/request`: the request as stored — the submitted one with a
/// `model_id` replaced by the model it named then, and a `kind` given by an alias by
/// the kind's name — so that it can be read, opened or submitted again as it is.
pub async fn request(State(state): State<AppState>, JobId(id): JobId) -> Result<Response, Problem> {
    let job = load(&state, &id).await?;
    let mut stored: serde_json::Map<String, Value> = serde_json::from_str(&job.request_json)
        .map_err(|e| Problem::internal(format!("job {id}'s stored request: {e}")))?;
    stored.insert("kind".into(), kind_name(&job.kind).into());
    Ok(Json(Value::Object(stored)).into_response())
}

/// `GET /v1/jobs/{id}/result`.
pub async fn result(State(state): State<AppState>, JobId(id): JobId) -> Result<Response, Problem> {
    let (json, _) = finished(&state, &id).await?;
    Ok(raw_json(StatusCode::OK, json))
}

/// `GET /v1/jobs/{id}/traces.csv`.
pub async fn traces(State(state): State<AppState>, JobId(id): JobId) -> Result<Response, Problem> {
    let (_, csv) = finished(&state, &id).await?;
    let csv = csv.ok_or_else(|| {
        Problem::not_found("traces", &id).detail(format!("job `{id}`'s kind has no traces"))
    })?;
    Ok((
        StatusCode::OK,
        [
            (
                header::CONTENT_TYPE,
                HeaderValue::from_static("text/csv; charset=utf-8"),
            ),
            (
                header::CONTENT_DISPOSITION,
                HeaderValue::from_static("attachment; filename=\"traces.csv\""),
            ),
        ],
        csv,
    )
        .into_response())
}

/// `GET /v1/jobs/{id}/events`: server-sent events. `progress` events
/// (`{status, progress}`) while the job is queued or running, then one `status` event
/// with the whole job when it has finished; then the stream ends.
pub async fn events(
    State(state): State<AppState>,
    JobId(id): JobId,
) -> Result<Sse<impl Stream<Item = Result<Event, Infallible>>>, Problem> {
    // Subscribe before reading the store, so no change between the two is missed.
    let rx = state.pool.live(&id).map(|l| l.subscribe());
    let job = load(&state, &id).await?;
    let stream = EventStream {
        state,
        id,
        rx,
        first: Some(job),
        last: None,
        done: false,
    };
    let s = futures_util::stream::unfold(stream, |mut s| async move {
        s.next_event().await.map(|e| (Ok(e), s))
    });
    Ok(Sse::new(s).keep_alive(KeepAlive::new().interval(Duration::from_secs(15))))
}

struct EventStream {
    state: AppState,
    id: String,
    rx: Option<tokio::sync::watch::Receiver<Snapshot>>,
    first: Option<JobRecord>,
    last: Option<(JobStatus, f64)>,
    done: bool,
}

impl EventStream {
    async fn next_event(&mut self) -> Option<Event> {
        if self.done {
            return None;
        }
        loop {
            let job = match self.first.take() {
                Some(j) => j,
                None => {
                    if self.wait().await.is_none() {
                        // The stream would end without its `status` event, which a
                        // client could not tell from a finished job: say why it ends.
                        self.done = true;
                        let (status, progress) = self.last.unwrap_or((JobStatus::Queued, 0.0));
                        let data = json!({
                            "status": status,
                            "progress": progress,
                            "message": "the server is stopping: an unfinished job is re-queued and runs when it starts again; follow it again then",
                        });
                        return Some(Event::default().event("shutdown").data(data.to_string()));
                    }
                    load(&self.state, &self.id).await.ok()?
                }
            };
            let live = self.rx.as_ref().map(|r| *r.borrow());
            let v = job_view(&job, live);
            if job.status.is_terminal() {
                self.done = true;
                return Some(Event::default().event("status").data(v.to_string()));
            }
            let now = (job.status, v["progress"].as_f64().unwrap_or(0.0));
            if self.last != Some(now) {
                self.last = Some(now);
                let data = json!({ "status": now.0, "progress": now.1 });
                return Some(Event::default().event("progress").data(data.to_string()));
            }
        }
    }

    /// Wait for a live change (or a poll interval); `None` when the server shuts down.
    async fn wait(&mut self) -> Option<()> {
        let mut shutdown = self.state.shutdown.clone();
        if *shutdown.borrow() {
            return None;
        }
        let changed = async {
            match self.rx.as_mut() {
                Some(rx) => {
                    if rx.changed().await.is_err() {
                        // The live job is gone (finished): the store has the outcome.
                        self.rx = None;
                    }
                    // Coalesce bursts of progress into one event per 100 ms.
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
                None => tokio::time::sleep(Duration::from_millis(500)).await,
            }
        };
        tokio::select! {
            _ = changed => Some(()),
            _ = shutdown.changed() => None,
        }
    }
}
