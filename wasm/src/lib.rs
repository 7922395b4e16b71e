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

/// Parse `{"name": value, ...}` overrides (as every request's `set`); an empty
/// string means none.
fn overrides(set_json: &str) -> Result<Overrides, Error> {
    if set_json.trim().is_empty() {
        return Ok(Overrides::new());
    }
    // The strict reader and the one reading of `set` every way in shares.
    let value = kea_core::parse_json(set_json.as_bytes())
        .map_err(|e| Error::invalid("set", format!("not valid JSON: {e}")))?;
    kea_core::request::overrides(Some(&value)).map_err(Error::Invalid)
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

/// [`check`] of a discrete model (`system.transition`, Φ per step: the form the
/// identification reads, [`kea_core::model::compile_discrete`]): its problems as JSON
/// (`[]` when valid), at the model's own paths. The editor checks a discrete model so,
/// where [`check`] (the analysis's) would only say that it is not a continuous one.
#[wasm_bindgen]
pub fn check_discrete(model_json: &str, set_json: &str) -> String {
    let result = kea_core::model_from_json(model_json).and_then(|model| {
        kea_core::model::compile_discrete(&model, &overrides(set_json)?).map(|_| ())
    });
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
    work: kea_core::work::Work,
    /// [`kea_core::work::DEFAULT_MAX_WORK`]: what `kea serve` refuses by default.
    limit: f64,
}

fn work_json(work: kea_core::work::Work) -> String {
    let out = WorkOut {
        work,
        limit: kea_core::work::DEFAULT_MAX_WORK,
    };
    serde_json::to_string(&out).expect("work serialises")
}

/// A request (JSON text) of the kind `kind` read and compiled by the core
/// ([`kea_core::registry`]), as the server's job of that kind reads it.
fn prepare(kind: &str, request_json: &str) -> Result<kea_core::registry::Prepared, Error> {
    let value = kea_core::parse_json(request_json.as_bytes())
        .map_err(|e| Error::invalid("", format!("not valid JSON: {e}")))?;
    kea_core::registry::prepare_checked(kind, value)
}

/// The estimated work of [`run`] on the same kind and request, the server's estimate
/// (`{units, explain, path, limit}`, `limit` being the server's default `--max-work`),
/// so the page can say so before it runs for hours. Throws the request's errors.
#[wasm_bindgen]
pub fn work(kind: &str, request_json: &str) -> Result<String, JsValue> {
    let prepared = prepare(kind, request_json).map_err(|e| to_js(&e))?;
    Ok(work_json(prepared.work()))
}

/// Run a request of the kind `kind` (`analysis`, `monte_carlo`, `synthesis`: the
/// server's job kinds, or an alias such as `simulation`, with the same request JSON)
/// with the core's `Sequential`
/// executor; the result is bit-identical to the server's. `progress(fraction)` is
/// called after about every millisecond of work; if it returns `false` the run stops
/// and this throws a `cancelled` error. Errors carry the request's paths
/// (`model.system.a[0][0]`, `runs`, `mode.bisect.high`). Returns the result JSON, with
/// `timing.wall_ms` measured here (the core has no clock).
#[wasm_bindgen]
pub fn run(kind: &str, request_json: &str, progress: &js_sys::Function) -> Result<String, JsValue> {
    run_as(kind, request_json, progress).map_err(|e| to_js(&e))
}

fn run_as(kind: &str, request_json: &str, progress: &js_sys::Function) -> Result<String, Error> {
    let start = js_sys::Date::now();
    let prepared = prepare(kind, request_json)?;
    let mut report = js_progress(progress);
    let mut outcome = prepared.run(
        &kea_core::exec::Sequential,
        &mut report,
        &kea_core::exec::Forgetful,
    )?;
    outcome.timing().wall_ms = js_sys::Date::now() - start;
    Ok(outcome.to_json())
}

/// The analysis request of a model and its overrides (JSON texts; an empty `set` is
/// none), with the request's other members from `options_json` (an object, e.g.
/// `{"budget": true, "truth": {"set": {"sd": 10}}}`; empty: none).
fn analysis_request(model_json: &str, set_json: &str, options_json: &str) -> Result<String, Error> {
    let set = overrides(set_json)?;
    let set = serde_json::to_string(&set).expect("overrides serialise");
    let options = if options_json.trim().is_empty() {
        String::new()
    } else {
        let parsed = kea_core::parse_json(options_json.as_bytes())
            .map_err(|e| Error::invalid("", format!("the analysis's options: {e}")))?;
        match parsed {
            serde_json::Value::Object(o) if o.contains_key("model") || o.contains_key("set") => {
                return Err(Error::invalid(
                    "",
                    "the analysis's options give the request's other members, not `model` or `set`",
                ));
            }
            serde_json::Value::Object(o) => o
                .iter()
                .map(|(k, v)| format!(", {}: {v}", serde_json::Value::from(k.as_str())))
                .collect(),
            _ => return Err(Error::invalid("", "the analysis's options are an object")),
        }
    };
    Ok(format!(
        r#"{{"model": {model_json}, "set": {set}{options}}}"#
    ))
}

/// [`work`] of a synthesis request (an alias kept for older pages).
#[wasm_bindgen]
pub fn synthesis_work(request_json: &str) -> Result<String, JsValue> {
    work("synthesis", request_json)
}

/// [`work`] of a Monte Carlo request.
#[wasm_bindgen]
pub fn monte_carlo_work(request_json: &str) -> Result<String, JsValue> {
    work("monte_carlo", request_json)
}

/// [`monte_carlo_work`] under its former name (kept for older pages).
#[wasm_bindgen]
pub fn simulation_work(request_json: &str) -> Result<String, JsValue> {
    monte_carlo_work(request_json)
}

/// [`work`] of the analysis of a model with overrides (and the request's other members,
/// `options_json`: `budget`, `truth`), its errors at the model's own paths
/// (`system.a[1][2]`).
#[wasm_bindgen]
pub fn analysis_work(
    model_json: &str,
    set_json: &str,
    options_json: &str,
) -> Result<String, JsValue> {
    let request = analysis_request(model_json, set_json, options_json).map_err(|e| to_js(&e))?;
    let prepared = prepare("analysis", &request).map_err(|e| to_js(&e.without_prefix("model")))?;
    Ok(work_json(prepared.work()))
}

/// [`run`] of the analysis of a model with overrides (and the request's other members,
/// `options_json`: `budget`, `truth`), its errors at the model's own paths
/// (`system.a[1][2]`), for the editor's cells.
#[wasm_bindgen]
pub fn analyze(
    model_json: &str,
    set_json: &str,
    options_json: &str,
    progress: &js_sys::Function,
) -> Result<String, JsValue> {
    analysis_request(model_json, set_json, options_json)
        .and_then(|request| run_as("analysis", &request, progress))
        .map_err(|e| to_js(&e.without_prefix("model")))
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

/// The traces of a Monte Carlo result (as [`run`] of `monte_carlo` returns it) as CSV,
/// same as the CLI's.
#[wasm_bindgen]
pub fn monte_carlo_csv(result_json: &str) -> Result<String, JsValue> {
    let result: kea_core::monte_carlo::MonteCarloResult = serde_json::from_str(result_json)
        .map_err(|e| {
            to_js(&Error::invalid(
                "",
                format!("not a kea Monte Carlo result: {e}"),
            ))
        })?;
    Ok(kea_core::monte_carlo::traces_csv(&result))
}

/// [`monte_carlo_csv`] under its former name (kept for older pages).
#[wasm_bindgen]
pub fn simulation_csv(result_json: &str) -> Result<String, JsValue> {
    monte_carlo_csv(result_json)
}

/// The traces of a result (as returned by [`analyze`]) as CSV, same as the CLI's.
#[wasm_bindgen]
pub fn traces_csv(result_json: &str) -> Result<String, JsValue> {
    let result: kea_core::AnalysisResult = serde_json::from_str(result_json)
        .map_err(|e| to_js(&Error::invalid("", format!("not a kea result: {e}"))))?;
    Ok(kea_core::analysis::report::traces_csv(&result))
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

/// One nonlinear preset's model JSON (`presets/nonlinear/NAME.json`, what a request's
/// `"model": "preset:NAME"` reads), exactly as shipped; `undefined` for an unknown name.
#[wasm_bindgen]
pub fn nonlinear_preset(name: &str) -> Option<String> {
    kea_core::nonlinear::request::preset(name).map(str::to_string)
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
    fn check_discrete_reads_the_identifications_form() {
        let mut model: serde_json::Value =
            serde_json::from_str(kea_core::presets::get_json("cv-tracker").unwrap()).unwrap();
        // A continuous model is not a discrete one, and a discrete one not a continuous one.
        let errors: Vec<serde_json::Value> =
            serde_json::from_str(&check_discrete(&model.to_string(), "")).unwrap();
        assert!(errors.iter().any(|e| e["path"] == "system.transition"));
        let a = model["system"]
            .as_object_mut()
            .unwrap()
            .remove("a")
            .unwrap();
        model["system"]["transition"] = a;
        assert_eq!(check_discrete(&model.to_string(), ""), "[]");
        // (`check` reads a model in its own form, as a stored model is checked.)
        assert_eq!(check(&model.to_string(), ""), "[]");
        model["system"]["transition"][0][1] = serde_json::json!("1 +* q");
        let errors: Vec<serde_json::Value> =
            serde_json::from_str(&check_discrete(&model.to_string(), "")).unwrap();
        assert_eq!(errors[0]["path"], "system.transition[0][1]");
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
            serde_json::from_str(&analysis_work(model, "", "").unwrap()).unwrap();
        let parsed = kea_core::model_from_json(model).unwrap();
        let compiled = kea_core::model::compile(&parsed, &Overrides::new()).unwrap();
        let expected = kea_core::analysis::work::analysis_work(&compiled, Some(&parsed));
        assert_eq!(out["units"], expected.units);
        assert_eq!(out["explain"], expected.explain);
        assert_eq!(out["limit"], kea_core::work::DEFAULT_MAX_WORK);
        let request = format!(r#"{{"model": {model}, "runs": 10}}"#);
        let sim: serde_json::Value =
            serde_json::from_str(&monte_carlo_work(&request).unwrap()).unwrap();
        assert!(sim["units"].as_f64().unwrap() > expected.units);
        assert_eq!(sim["path"], "runs");
        // The former names, the kind's and the function's, give the same estimate.
        let parsed = |text: String| serde_json::from_str::<serde_json::Value>(&text).unwrap();
        assert_eq!(parsed(simulation_work(&request).unwrap()), sim);
        assert_eq!(parsed(work("simulation", &request).unwrap()), sim);
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

    #[test]
    fn nonlinear_preset_is_the_file_shipped() {
        assert_eq!(
            nonlinear_preset("seed-002").as_deref(),
            Some(include_str!("../../presets/nonlinear/seed-002.json"))
        );
        assert!(nonlinear_preset("seed-example").is_none());
    }
}
