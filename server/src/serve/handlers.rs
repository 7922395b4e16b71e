//! Handlers for health, presets, stored models and synchronous analysis. Each parses,
//! calls the core (or the store), maps the error, and answers.

use super::jobs::{self, PreparedJob, Work};
use super::problem::{Problem, kind};
use super::request::{self, JsonBody};
use super::state::AppState;
use super::store::{ModelRecord, new_id, now_rfc3339};
use axum::Json;
use axum::extract::{RawQuery, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use kea_core::FieldError;
use serde_json::{Map, Value, json};
use std::ops::ControlFlow;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// `GET /healthz`.
pub async fn health() -> Json<Value> {
    Json(json!({ "status": "ok", "version": env!("CARGO_PKG_VERSION") }))
}

/// `GET /v1/limits`: what this server and the core accept — the server's own limits
/// (its `kea serve` options, as started) and the model's, the Monte Carlo's and the
/// synthesis's fixed ones — so a script or the web UI can check a request first. The
/// Monte Carlo's are also under `simulation`, the kind's former name, for older clients.
pub async fn limits(State(state): State<AppState>) -> Json<Value> {
    use kea_core::model::limits;
    use kea_core::{expr, monte_carlo, synthesis};
    let l = &state.config.limits;
    let monte_carlo_limits = json!({
        "max_runs": monte_carlo::MAX_RUNS,
        "max_work": monte_carlo::MAX_WORK,
    });
    Json(json!({
        "server": {
            "max_body_bytes": l.max_body_bytes,
            "read_timeout_s": l.read_timeout.as_secs(),
            "sync_work": l.sync_work,
            "max_work": l.max_work,
            "job_time_s": l.job_time.as_secs(),
            "sync_time_s": l.sync_time().as_secs(),
            "queue": l.queue,
            "shutdown_grace_s": l.shutdown_grace.as_secs(),
            "keep_finished_s": l.keep_finished.map(|d| d.as_secs()),
            "state_every_s": l.state_every.as_secs(),
            "workers": state.config.workers,
            "max_page": request::MAX_PAGE,
        },
        "model": {
            "max_states": limits::MAX_STATES,
            "max_sources": limits::MAX_SOURCES,
            "max_steps": limits::MAX_STEPS,
            "max_trace_points": limits::MAX_TRACE_POINTS,
            "max_trace_values": limits::MAX_TRACE_VALUES,
            "max_expression_chars": expr::MAX_EXPRESSION_CHARS,
            "max_time_expressions": expr::MAX_TIME_EXPRESSIONS,
            "max_time_expression_chars": expr::MAX_TIME_EXPRESSION_CHARS,
            "max_reported_errors": kea_core::error::MAX_REPORTED_ERRORS,
        },
        "monte_carlo": monte_carlo_limits,
        "simulation": monte_carlo_limits,
        "synthesis": {
            "max_points": synthesis::MAX_POINTS,
            "max_grid_params": synthesis::MAX_GRID_PARAMS,
        },
    }))
}

/// `GET /v1/presets`: every preset (one page; no query parameters).
pub async fn list_presets() -> Json<Value> {
    Json(json!({ "items": kea_core::presets::list() }))
}

/// `GET /v1/presets/{name}`: the model JSON exactly as shipped.
pub async fn get_preset(
    request::PresetName(name): request::PresetName,
) -> Result<Response, Problem> {
    let json = kea_core::presets::get_json(&name).ok_or_else(|| no_preset(&name))?;
    Ok(raw_json(StatusCode::OK, json.to_string()))
}

/// `GET /v1/presets/{name}/synthesis`: the preset's synthesis example (a request's
/// `target` and `mode`, no `model`) exactly as shipped.
pub async fn get_preset_synthesis(
    request::PresetName(name): request::PresetName,
) -> Result<Response, Problem> {
    let json = kea_core::presets::synthesis_json(&name).ok_or_else(|| no_preset(&name))?;
    Ok(raw_json(StatusCode::OK, json.to_string()))
}

/// The 404 of an unknown preset, with the known names.
fn no_preset(name: &str) -> Problem {
    Problem::not_found("preset", name).detail(format!(
        "there is no preset `{name}`; known: {}",
        kea_core::presets::names().join(", ")
    ))
}

/// A response whose body is JSON text already.
pub fn raw_json(status: StatusCode, body: String) -> Response {
    (
        status,
        [(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/json"),
        )],
        body,
    )
        .into_response()
}

/// `POST /v1/models`: the body is a model; it is validated, stored, and given an id.
pub async fn create_model(
    State(state): State<AppState>,
    JsonBody(body, bytes): JsonBody,
) -> Result<Response, Problem> {
    let model = tokio::task::spawn_blocking(move || {
        let model = kea_core::model_from_value(body)?;
        kea_core::check(&model, &Default::default())?;
        Ok::<_, kea_core::Error>(model)
    })
    .await
    .map_err(Problem::internal)?
    .map_err(Problem::from_core)?;
    let record = ModelRecord {
        id: new_id(),
        name: model.name.clone(),
        created_at: now_rfc3339(),
        // The text as sent (member order, number spellings, layout): GET returns it.
        // (UTF-8, as parse_json took it; a byte-order mark is not part of the text.)
        model_json: String::from_utf8_lossy(bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes))
            .into_owned(),
    };
    let view = json!({ "id": record.id, "name": record.name, "created_at": record.created_at });
    let location = format!("/v1/models/{}", record.id);
    state.db(move |s| s.insert_model(&record)).await?;
    let mut res = (StatusCode::CREATED, Json(view)).into_response();
    res.headers_mut().insert(
        header::LOCATION,
        HeaderValue::from_str(&location).expect("ids are ASCII"),
    );
    Ok(res)
}

/// `GET /v1/models?limit&cursor`: newest first.
pub async fn list_models(
    State(state): State<AppState>,
    RawQuery(raw): RawQuery,
) -> Result<Json<Value>, Problem> {
    let q = request::list_query(raw, &[])?;
    let page = state
        .db(move |s| s.list_models(q.cursor.as_deref(), q.limit))
        .await?;
    Ok(Json(
        json!({ "items": page.items, "next_cursor": page.next_cursor }),
    ))
}

/// `GET /v1/models/{id}`.
pub async fn get_model(
    State(state): State<AppState>,
    request::ModelId(id): request::ModelId,
) -> Result<Response, Problem> {
    let key = id.clone();
    let record = state
        .db(move |s| s.get_model(&key))
        .await?
        .ok_or_else(|| Problem::not_found("model", &id))?;
    // The model's text goes in as it was sent (valid JSON: it was parsed on the way
    // in), not re-serialised: a Value would sort its members and respell 1e3 as 1000.0.
    let head = json!({ "id": record.id, "name": record.name, "created_at": record.created_at });
    let head = head.to_string();
    let body = format!(
        "{},\"model\":{}}}",
        &head[..head.len() - 1],
        record.model_json.trim()
    );
    Ok(([(header::CONTENT_TYPE, "application/json")], body).into_response())
}

/// `DELETE /v1/models/{id}`: 204. Jobs submitted with this model keep their copy.
pub async fn delete_model(
    State(state): State<AppState>,
    request::ModelId(id): request::ModelId,
) -> Result<StatusCode, Problem> {
    let key = id.clone();
    if state.db(move |s| s.delete_model(&key)).await? {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(Problem::not_found("model", &id))
    }
}

/// Replace `model_id` by the stored model, so the request is self-contained; returns
/// the id (for [`prepare`]'s messages) when there was one.
pub async fn resolve_model_id(
    state: &AppState,
    obj: &mut Map<String, Value>,
) -> Result<Option<String>, Problem> {
    let Some(idv) = obj.remove("model_id") else {
        return Ok(None);
    };
    if obj.contains_key("model") {
        let message = if idv.is_null() {
            "null beside `model`: leave `model_id` out when the request gives its model"
        } else {
            "give either `model` or `model_id`, not both"
        };
        return Err(Problem::invalid(vec![FieldError::new("model_id", message)]));
    }
    let Value::String(id) = idv else {
        return Err(Problem::invalid(vec![FieldError::new(
            "model_id",
            format!(
                "expected a model id (a string), got {}",
                request::json_kind(&idv)
            ),
        )]));
    };
    let id = request::canonical_id(id);
    let key = id.clone();
    let record = state.db(move |s| s.get_model(&key)).await?.ok_or_else(|| {
        Problem::invalid(vec![FieldError::new(
            "model_id",
            format!("there is no stored model with id `{id}` (see GET /v1/models)"),
        )])
    })?;
    let model: Value = serde_json::from_str(&record.model_json).map_err(Problem::internal)?;
    obj.insert("model".into(), model);
    Ok(Some(id))
}

/// An error in a stored model (a request with `model_id`): its paths stay those of
/// the resolved request (`model.system.phi[0]`, as a job's stored request reads), and
/// each such message says which stored model it is in, since the request as sent had
/// no `model`.
pub fn in_stored_model(err: kea_core::Error, id: Option<&str>) -> kea_core::Error {
    let Some(id) = id else { return err };
    let of_model = |path: &str| path == "model" || path.starts_with("model.");
    let note = |message: String| format!("{message} (in the stored model `{id}`)");
    match err {
        kea_core::Error::Invalid(errors) => kea_core::Error::Invalid(
            errors
                .into_iter()
                .map(|e| {
                    if of_model(&e.path) {
                        FieldError::new(e.path, note(e.message))
                    } else {
                        e
                    }
                })
                .collect(),
        ),
        kea_core::Error::Numerical {
            step,
            t,
            path,
            message,
        } if of_model(&path) => kea_core::Error::Numerical {
            step,
            t,
            path,
            message: note(message),
        },
        other => other,
    }
}

/// Read and compile a request of the job kind `kind` (a known one) on a blocking
/// thread: a large model takes long enough to stall the async workers, and every
/// other request (`/healthz` too) with them. `stored`: the `model_id` it gave.
pub async fn prepare(
    kind: &str,
    request: Value,
    stored: Option<&str>,
) -> Result<PreparedJob, Problem> {
    let kind = kind.to_string();
    tokio::task::spawn_blocking(move || jobs::prepare(&kind, request))
        .await
        .map_err(Problem::internal)?
        .map_err(|e| Problem::from_core(in_stored_model(e, stored)))
}

/// Refuse work above `limit`; `advice` says what to do instead.
pub fn check_work(
    work: &Work,
    limit: f64,
    type_: &'static str,
    advice: &str,
) -> Result<(), Problem> {
    if work.units <= limit {
        return Ok(());
    }
    let message = format!(
        "estimated work {:.3e} ({}) is above the limit of {:.3e}; {advice}",
        work.units, work.explain, limit
    );
    Err(Problem::new(
        StatusCode::UNPROCESSABLE_ENTITY,
        type_,
        "too much work for this request",
    )
    .detail(message.clone())
    .error(work.path.clone(), message))
}

/// `POST /v1/analyze`: `{model | model_id, set?}` → the analysis result, for small work.
pub async fn analyze(
    State(state): State<AppState>,
    JsonBody(body, _): JsonBody,
) -> Result<Response, Problem> {
    let mut obj = request::object(body)?;
    let stored = resolve_model_id(&state, &mut obj).await?;
    let prepared = prepare("analysis", Value::Object(obj), stored.as_deref()).await?;
    let limits = &state.config.limits;
    check_work(
        &prepared.work(),
        limits.max_work,
        kind::TOO_MUCH_WORK,
        "reduce the steps or the state dimension",
    )?;
    check_work(
        &prepared.work(),
        limits.sync_work,
        kind::USE_A_JOB,
        "submit it as a job instead: POST /v1/jobs with {\"kind\": \"analysis\", \"model\": …}",
    )?;
    let _permit = state
        .sync_permits
        .clone()
        .acquire_owned()
        .await
        .map_err(Problem::internal)?;
    // The run stops when the client goes (axum drops this future, and with it the
    // flag's guard) or at the synchronous time limit: never left running for nobody.
    let gone = Arc::new(AtomicBool::new(false));
    let _guard = SetOnDrop(gone.clone());
    let limit = limits.sync_time();
    let estimate = prepared.work();
    let (out, timed_out) = tokio::task::spawn_blocking(move || {
        let started = Instant::now();
        let stop = || gone.load(Ordering::Relaxed) || started.elapsed() > limit;
        let mut progress = |_: f64| {
            if stop() {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        };
        // The result alone: the response has no use for the traces CSV a job keeps.
        let out = prepared.run_result(&mut progress, &stop, &kea_core::exec::Forgetful);
        (out, started.elapsed() > limit)
    })
    .await
    .map_err(Problem::internal)?;
    let out = match out {
        Err(kea_core::Error::Cancelled) if timed_out => {
            let message = format!(
                "stopped after {} s, the limit of a synchronous analysis: its estimated work {:.3e} ({}) undercounts this model; submit it as a job instead: POST /v1/jobs with {{\"kind\": \"analysis\", \"model\": …}}",
                limit.as_secs(),
                estimate.units,
                estimate.explain
            );
            return Err(Problem::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                kind::USE_A_JOB,
                "too much work for this request",
            )
            .detail(message.clone())
            .error(estimate.path.clone(), message));
        }
        out => out.map_err(|e| Problem::from_core(in_stored_model(e, stored.as_deref())))?,
    };
    Ok(raw_json(StatusCode::OK, out))
}

/// Sets its flag when dropped: the synchronous analysis's request is gone.
struct SetOnDrop(Arc<AtomicBool>);

impl Drop for SetOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}
