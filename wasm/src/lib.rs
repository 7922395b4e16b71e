//! kea in the browser: a thin wasm-bindgen adapter over `kea-core`.
//!
//! Architecture invariant: no estimation maths here. Every function parses its JSON
//! input, calls one core function, and returns JSON (or throws a JSON error object of
//! the same shape as the HTTP API's problem details: `{kind, title, errors:[{path,
//! message}]}`). It is meant to run inside a Web Worker (`web/worker.js`), so a long
//! analysis never blocks the page.

use kea_core::{Error, FieldError, Overrides};
use serde::Serialize;
use std::ops::ControlFlow;
use wasm_bindgen::prelude::*;

/// The error thrown to JavaScript, as a JSON string.
#[derive(Serialize)]
struct ErrorOut {
    /// `invalid`, `numerical` or `cancelled`.
    kind: &'static str,
    title: String,
    errors: Vec<FieldError>,
}

fn error_json(e: &Error) -> String {
    let kind = match e {
        Error::Invalid(_) => "invalid",
        Error::Numerical { .. } => "numerical",
        Error::Cancelled => "cancelled",
    };
    let out = ErrorOut {
        kind,
        title: e.to_string(),
        errors: e.field_errors(),
    };
    serde_json::to_string(&out).expect("error serialises")
}

fn to_js(e: &Error) -> JsValue {
    JsValue::from_str(&error_json(e))
}

/// Parse `{"name": value, ...}` overrides; an empty string means none.
fn overrides(set_json: &str) -> Result<Overrides, Error> {
    if set_json.trim().is_empty() {
        return Ok(Overrides::new());
    }
    serde_json::from_str(set_json)
        .map_err(|e| Error::invalid("set", format!("expected an object of numbers: {e}")))
}

/// Parse and validate a model: the list of problems as JSON (`[]` when valid).
/// Paths are the core's (`system.a[1][2]`), so the editor can mark the exact cell.
#[wasm_bindgen]
pub fn check(model_json: &str, set_json: &str) -> String {
    let result = kea_core::model_from_json(model_json)
        .and_then(|model| kea_core::check(&model, &overrides(set_json)?));
    let errors = match result {
        Ok(()) => Vec::new(),
        Err(e) => e.field_errors(),
    };
    serde_json::to_string(&errors).expect("errors serialise")
}

/// Check JSON text (its bytes, as read from a file or a link) as every way into kea
/// reads it ([`kea_core::parse_json`]: a key given twice, a number beyond f64, text
/// that is not UTF-8 are errors; a byte-order mark is skipped): nothing when it reads,
/// else a thrown `invalid` error whose title says what is wrong and where (`the key
/// "steps" appears twice in one object at line 6 column 59`). Text that passes reads
/// the same with JavaScript's JSON.parse, which keeps the objects' key order (the
/// core's map sorts it: a model's params would come back alphabetical).
#[wasm_bindgen]
pub fn check_json(text: &[u8]) -> Result<(), JsValue> {
    kea_core::parse_json(text).map_err(|e| to_js(&Error::invalid("", e.to_string())))?;
    Ok(())
}

/// A work estimate with the limit it is held to by default, as JSON.
#[derive(Serialize)]
struct WorkOut {
    #[serde(flatten)]
    work: kea_core::cost::Work,
    /// [`kea_core::cost::DEFAULT_MAX_WORK`]: what `kea serve` refuses by default.
    limit: f64,
}

fn work_json(work: kea_core::cost::Work) -> String {
    let out = WorkOut {
        work,
        limit: kea_core::cost::DEFAULT_MAX_WORK,
    };
    serde_json::to_string(&out).expect("work serialises")
}

/// The estimated work of [`analyze`] on the same input, the server's estimate
/// (`{units, explain, path, limit}`, `limit` being the server's default `--max-work`),
/// so the page can say so before it runs for hours. Throws the model's errors.
#[wasm_bindgen]
pub fn analysis_work(model_json: &str, set_json: &str) -> Result<String, JsValue> {
    let model = kea_core::model_from_json(model_json).map_err(|e| to_js(&e))?;
    let set = overrides(set_json).map_err(|e| to_js(&e))?;
    let compiled = kea_core::validate::compile(&model, &set).map_err(|e| to_js(&e))?;
    Ok(work_json(kea_core::cost::analysis_work(
        &compiled,
        Some(&model),
    )))
}

/// The estimated work of [`synthesize`] on the same request, as [`analysis_work`] gives it.
#[wasm_bindgen]
pub fn synthesis_work(request_json: &str) -> Result<String, JsValue> {
    let request = kea_core::synthesis::request_from_json(request_json).map_err(|e| to_js(&e))?;
    let work = kea_core::cost::synthesis_work(&request).map_err(|e| to_js(&e))?;
    Ok(work_json(work))
}

/// The estimated work of [`simulate`] on the same request, as [`analysis_work`] gives it.
#[wasm_bindgen]
pub fn simulation_work(request_json: &str) -> Result<String, JsValue> {
    let (model, set, request) = simulation_input(request_json).map_err(|e| to_js(&e))?;
    let compiled =
        kea_core::validate::compile(&model, &set).map_err(|e| to_js(&model_located(e)))?;
    kea_core::simulation::check_request(&request, &compiled).map_err(|e| to_js(&e))?;
    Ok(work_json(kea_core::cost::simulation_work(
        &compiled,
        Some(&model),
        &request,
    )))
}

/// Run the analysis. `progress(fraction)` is called after about every millisecond of
/// work (every few thousand steps of a small model, every step of a large one); if it
/// returns `false` the run stops and this throws a `cancelled` error. Returns the
/// result JSON, with `timing.wall_ms` measured here (the core has no clock).
#[wasm_bindgen]
pub fn analyze(
    model_json: &str,
    set_json: &str,
    progress: &js_sys::Function,
) -> Result<String, JsValue> {
    let start = js_sys::Date::now();
    let model = kea_core::model_from_json(model_json).map_err(|e| to_js(&e))?;
    let set = overrides(set_json).map_err(|e| to_js(&e))?;
    let mut report = js_progress(progress);
    let mut result = kea_core::analyze(&model, &set, &mut report).map_err(|e| to_js(&e))?;
    result.timing.wall_ms = js_sys::Date::now() - start;
    serde_json::to_string(&result).map_err(|e| JsValue::from_str(&e.to_string()))
}

/// A progress callback as the core's `Progress`: `progress(fraction)` returning
/// `false` (or throwing) cancels.
fn js_progress(progress: &js_sys::Function) -> impl FnMut(f64) -> ControlFlow<()> + '_ {
    move |fraction: f64| match progress.call1(&JsValue::NULL, &JsValue::from_f64(fraction)) {
        Ok(v) if v == JsValue::FALSE => ControlFlow::Break(()),
        Err(_) => ControlFlow::Break(()),
        Ok(_) => ControlFlow::Continue(()),
    }
}

/// Run a synthesis request (`{model, set?, target, mode}`, docs/synthesis.md) with the
/// core's `Sequential` executor. Errors carry the request's paths (`model.system.a[0][0]`,
/// `mode.bisect.high`, `target.state`). Returns the result JSON, `timing.wall_ms` measured here.
#[wasm_bindgen]
pub fn synthesize(request_json: &str, progress: &js_sys::Function) -> Result<String, JsValue> {
    let start = js_sys::Date::now();
    let request = kea_core::synthesis::request_from_json(request_json).map_err(|e| to_js(&e))?;
    let mut report = js_progress(progress);
    let mut result =
        kea_core::synthesis::synthesize(&request, &kea_core::exec::Sequential, &mut report)
            .map_err(|e| to_js(&e))?;
    result.timing.wall_ms = js_sys::Date::now() - start;
    serde_json::to_string(&result).map_err(|e| JsValue::from_str(&e.to_string()))
}

/// A Monte Carlo request as the server's job kind `simulation` takes it: the model, its
/// overrides, and the core's `SimulationRequest` members beside them.
#[derive(serde::Deserialize)]
struct SimulateIn {
    model: serde_json::Value,
    #[serde(default)]
    set: Overrides,
    #[serde(flatten)]
    request: serde_json::Map<String, serde_json::Value>,
}

/// Run a Monte Carlo simulation (`{model, set?, runs, seed?, truth?, model_error?,
/// trace_points?}`, docs/monte-carlo.md) with the core's `Sequential` executor; the
/// result is bit-identical to the server's for the same seed. Model errors are at
/// `model.…`, the simulation's at `runs`, `seed`, …, as on the server.
#[wasm_bindgen]
pub fn simulate(request_json: &str, progress: &js_sys::Function) -> Result<String, JsValue> {
    let start = js_sys::Date::now();
    let (model, set, request) = simulation_input(request_json).map_err(|e| to_js(&e))?;
    // Locate the errors as the server does: the model's under `model.`, then the run's own.
    let compiled =
        kea_core::validate::compile(&model, &set).map_err(|e| to_js(&model_located(e)))?;
    kea_core::simulation::check_request(&request, &compiled).map_err(|e| to_js(&e))?;
    let mut report = js_progress(progress);
    let mut result = kea_core::simulation::simulate(
        &model,
        &set,
        &request,
        &kea_core::exec::Sequential,
        &mut report,
    )
    .map_err(|e| to_js(&model_located(e)))?;
    result.timing.wall_ms = js_sys::Date::now() - start;
    serde_json::to_string(&result).map_err(|e| JsValue::from_str(&e.to_string()))
}

/// A Monte Carlo request's parts: the model (its errors under `model.`), its
/// overrides and the simulation's own members.
fn simulation_input(
    request_json: &str,
) -> Result<
    (
        kea_core::Model,
        Overrides,
        kea_core::simulation::SimulationRequest,
    ),
    Error,
> {
    let value = kea_core::parse_json(request_json.as_bytes())
        .map_err(|e| Error::invalid("", format!("not valid JSON: {e}")))?;
    let input: SimulateIn = kea_core::from_value_at(value, &[])?;
    let model = kea_core::model_from_value(input.model).map_err(|e| e.with_prefix("model"))?;
    let request = kea_core::from_value_at(serde_json::Value::Object(input.request), &[])?;
    Ok((model, input.set, request))
}

/// Prefix a model's error paths with `model.` (those under `set` stay).
fn model_located(e: Error) -> Error {
    match e {
        Error::Invalid(v) => Error::Invalid(
            v.into_iter()
                .flat_map(|f| {
                    if f.path == "set" || f.path.starts_with("set.") {
                        vec![f]
                    } else {
                        Error::Invalid(vec![f]).with_prefix("model").field_errors()
                    }
                })
                .collect(),
        ),
        other => other.with_prefix("model"),
    }
}

/// The traces of a Monte Carlo result (as returned by [`simulate`]) as CSV, same as the CLI's.
#[wasm_bindgen]
pub fn simulation_csv(result_json: &str) -> Result<String, JsValue> {
    let result: kea_core::simulation::SimulationResult = serde_json::from_str(result_json)
        .map_err(|e| {
            to_js(&Error::invalid(
                "",
                format!("not a kea simulation result: {e}"),
            ))
        })?;
    Ok(kea_core::simulation::traces_csv(&result))
}

/// The traces of a result (as returned by [`analyze`]) as CSV, same as the CLI's.
#[wasm_bindgen]
pub fn traces_csv(result_json: &str) -> Result<String, JsValue> {
    let result: kea_core::AnalysisResult = serde_json::from_str(result_json)
        .map_err(|e| to_js(&Error::invalid("", format!("not a kea result: {e}"))))?;
    Ok(kea_core::report::traces_csv(&result))
}

/// Name, title, description and sizes of every preset, as JSON.
#[wasm_bindgen]
pub fn presets() -> String {
    serde_json::to_string(&kea_core::presets::list()).expect("presets serialise")
}

/// One preset's model JSON, exactly as shipped; `undefined` for an unknown name.
#[wasm_bindgen]
pub fn preset(name: &str) -> Option<String> {
    kea_core::presets::get_json(name).map(str::to_string)
}

/// One preset's synthesis example (a request's `target` and `mode`, no `model`),
/// exactly as shipped; `undefined` for an unknown name.
#[wasm_bindgen]
pub fn preset_synthesis(name: &str) -> Option<String> {
    kea_core::presets::synthesis_json(name).map(str::to_string)
}

/// The version of kea this build comes from.
#[wasm_bindgen]
pub fn version() -> String {
    env!("CARGO_PKG_VERSION").to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_points_at_the_bad_cell() {
        let mut model: serde_json::Value =
            serde_json::from_str(kea_core::presets::get_json("cv-tracker").unwrap()).unwrap();
        model["system"]["a"][0][1] = serde_json::json!("1 +* q");
        let errors: Vec<serde_json::Value> =
            serde_json::from_str(&check(&model.to_string(), "")).unwrap();
        assert!(!errors.is_empty());
        assert_eq!(errors[0]["path"], "system.a[0][1]");
    }

    #[test]
    fn check_accepts_every_preset_and_rejects_unknown_overrides() {
        for p in kea_core::presets::names() {
            assert_eq!(check(kea_core::presets::get_json(p).unwrap(), "{}"), "[]");
        }
        let seed = kea_core::presets::get_json("seed-example").unwrap();
        let errors: Vec<serde_json::Value> =
            serde_json::from_str(&check(seed, r#"{"nope": 1}"#)).unwrap();
        assert_eq!(errors.len(), 1);
        let bad: Vec<serde_json::Value> = serde_json::from_str(&check(seed, "[1]")).unwrap();
        assert_eq!(bad[0]["path"], "set");
    }

    #[test]
    fn check_json_is_the_cores_strict_reader() {
        assert!(check_json(b"\xEF\xBB\xBF{\"a\": [1, 2.5e-3]}").is_ok());
        // The errors (thrown as JsValue) need a JS host; the core's reader is the one used.
        assert!(kea_core::parse_json(br#"{"a": 1, "a": 2}"#).is_err());
    }

    #[test]
    fn work_is_the_servers_estimate_with_its_default_limit() {
        let model = kea_core::presets::get_json("cv-tracker").unwrap();
        let out: serde_json::Value =
            serde_json::from_str(&analysis_work(model, "").unwrap()).unwrap();
        let parsed = kea_core::model_from_json(model).unwrap();
        let compiled = kea_core::validate::compile(&parsed, &Overrides::new()).unwrap();
        let expected = kea_core::cost::analysis_work(&compiled, Some(&parsed));
        assert_eq!(out["units"], expected.units);
        assert_eq!(out["explain"], expected.explain);
        assert_eq!(out["limit"], kea_core::cost::DEFAULT_MAX_WORK);
        let request = format!(r#"{{"model": {model}, "runs": 10}}"#);
        let sim: serde_json::Value =
            serde_json::from_str(&simulation_work(&request).unwrap()).unwrap();
        assert!(sim["units"].as_f64().unwrap() > expected.units);
        assert_eq!(sim["path"], "runs");
    }

    #[test]
    fn presets_list_names_and_texts() {
        let list: Vec<serde_json::Value> = serde_json::from_str(&presets()).unwrap();
        assert_eq!(list.len(), kea_core::presets::names().len());
        assert_eq!(list[0]["name"], "seed-example");
        assert!(preset("seed-example").unwrap().contains("\"kea_model\""));
        assert!(preset("no-such").is_none());
        assert!(
            preset_synthesis("cv-tracker")
                .unwrap()
                .contains("\"target\"")
        );
        assert!(preset_synthesis("no-such").is_none());
    }
}
