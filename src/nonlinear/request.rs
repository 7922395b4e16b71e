//! A nonlinear run's request, read strictly once:
//!
//! ```text
//!     {"model": MODEL | "preset:NAME", "set": {…},
//!      "data": {"csv_text": "…"} | {"rows": [[t, y1, …], …]} | {"truth": {…}},
//!      "procedure": {"alpha": [α_0, …], "earlier_residuals": "posterior" | "prior"},
//!      "q_scale": [s, …], "checkpoints": [n, …], "trace_points": P}
//! ```
//!
//! (`data.csv`, a file's path, is the command line's: it reads the file and sends
//! `csv_text`.) `procedure` overrides the model's own `procedure` member by member;
//! without either, α = (1, 0.8, 0.6, 0.5, 0.4, 0.3), the seed's reference schedule.

use super::bank::Residuals;
use super::data::{self, Measured};
use super::model::{Compiled, NonlinearModel, compile, from_value};
use super::truth::{self, Truth};
use crate::error::{Error, FieldError, got};
use crate::model::Overrides;
use serde_json::{Map, Value};

/// The most filters of the procedure (K).
pub const MAX_FILTERS: usize = 16;
/// The most Q scales of the baseline.
pub const MAX_Q_SCALES: usize = 64;
/// The most checkpoints.
pub const MAX_CHECKPOINTS: usize = 1000;
/// The default trace points, and the most.
pub const DEFAULT_TRACE_POINTS: usize = 1000;
pub const MAX_TRACE_POINTS: usize = 100_000;
/// The default α schedule (the seed's reference scenarios').
pub const DEFAULT_ALPHA: [f64; 6] = [1.0, 0.8, 0.6, 0.5, 0.4, 0.3];

/// The Q scales of the baseline by default: 10^(−2 … 3) in steps of 0.25 decades.
pub fn default_q_scales() -> Vec<f64> {
    (0..=20)
        .map(|k| 10f64.powf(-2.0 + 0.25 * k as f64))
        .collect()
}

/// Where the data came from.
#[derive(Clone, Debug)]
pub enum Source {
    Csv,
    Rows,
    Truth(Box<Truth>),
}

/// A request read and compiled.
#[derive(Clone, Debug)]
pub struct NonlinearRequest {
    pub model: Compiled,
    /// The data read (empty for a truth: [`Source::Truth`] is simulated by the run).
    pub data: Measured,
    pub source: Source,
    pub alpha: Vec<f64>,
    pub residuals: Residuals,
    pub q_scales: Vec<f64>,
    pub checkpoints: Vec<usize>,
    pub trace_points: usize,
}

/// The preset models of this kind, by name.
pub fn preset(name: &str) -> Option<&'static str> {
    match name {
        "seed-002" => Some(include_str!("../../presets/nonlinear/seed-002.json")),
        _ => None,
    }
}

/// The names of the presets.
pub const PRESETS: &[&str] = &["seed-002"];

/// The model member: an object, or `"preset:NAME"`.
fn model_value(v: &Value) -> Result<Value, Error> {
    if let Value::String(s) = v {
        let Some(name) = s.strip_prefix("preset:") else {
            return Err(Error::invalid(
                "model",
                format!(
                    "expected a nonlinear model object or \"preset:NAME\" (presets: {}), got \"{s}\"",
                    PRESETS.join(", ")
                ),
            ));
        };
        let text = preset(name).ok_or_else(|| {
            Error::invalid(
                "model",
                format!(
                    "no nonlinear preset \"{name}\"; known: {}",
                    PRESETS.join(", ")
                ),
            )
        })?;
        return crate::json::parse_json(text.as_bytes())
            .map_err(|e| Error::invalid("model", format!("preset {name}: {e}")));
    }
    Ok(v.clone())
}

/// Read and compile a request (its members already checked against the kind's).
pub fn read(obj: &Map<String, Value>) -> Result<NonlinearRequest, Error> {
    let set: Overrides = crate::request::overrides(obj.get("set")).map_err(Error::Invalid)?;
    let Some(model) = obj.get("model") else {
        return Err(Error::invalid(
            "model",
            "missing: give `model` (a nonlinear model object, or \"preset:seed-002\")",
        ));
    };
    let written: NonlinearModel =
        from_value(model_value(model)?).map_err(|e| e.with_prefix("model"))?;
    let model = compile(&written, &set).map_err(crate::request::locate)?;

    let mut errors: Vec<FieldError> = Vec::new();
    let defaults = written.procedure.clone().unwrap_or_default();
    let (mut alpha, mut residuals) = (
        defaults.alpha.unwrap_or_else(|| DEFAULT_ALPHA.to_vec()),
        defaults.earlier_residuals.unwrap_or(Residuals::Posterior),
    );
    let mut alpha_path = "model.procedure.alpha".to_string();
    match obj.get("procedure") {
        None => {}
        Some(Value::Object(p)) => {
            for k in p
                .keys()
                .filter(|k| *k != "alpha" && *k != "earlier_residuals")
            {
                errors.push(FieldError::new(
                    format!("procedure.{k}"),
                    "unknown member; expected alpha, earlier_residuals",
                ));
            }
            if let Some(a) = p.get("alpha") {
                alpha_path = "procedure.alpha".into();
                match numbers(a) {
                    Some(a) => alpha = a,
                    None => errors.push(FieldError::new(
                        "procedure.alpha",
                        format!("expected an array of numbers α_0…α_(K−1), got {}", got(a)),
                    )),
                }
            }
            if let Some(r) = p.get("earlier_residuals") {
                match r.as_str() {
                    Some("posterior") => residuals = Residuals::Posterior,
                    Some("prior") => residuals = Residuals::Prior,
                    _ => errors.push(FieldError::new(
                        "procedure.earlier_residuals",
                        format!("expected \"posterior\" (y − h(x_i⁺), METHOD §4) or \"prior\" (y − h(x_i⁻)), got {}", got(r)),
                    )),
                }
            }
        }
        Some(other) => errors.push(FieldError::new(
            "procedure",
            format!("expected an object {{\"alpha\": […]}}, got {}", got(other)),
        )),
    }
    if let Err((sub, message)) = super::gamma::check(&alpha, MAX_FILTERS) {
        errors.push(FieldError::new(format!("{alpha_path}{sub}"), message));
    }
    let q_scales = match obj.get("q_scale") {
        None => default_q_scales(),
        Some(v) => match numbers(v) {
            Some(s) if s.len() <= MAX_Q_SCALES => {
                for (i, x) in s.iter().enumerate() {
                    if !(*x > 0.0 && x.is_finite()) {
                        errors.push(FieldError::new(
                            format!("q_scale[{i}]"),
                            format!(
                                "expected a scale > 0 of the model's W, got {}",
                                crate::text::num(*x)
                            ),
                        ));
                    }
                }
                s
            }
            _ => {
                errors.push(FieldError::new(
                    "q_scale",
                    format!("expected an array of at most {MAX_Q_SCALES} scales > 0 of W ([] for no Q-scale baseline), got {}", got(v)),
                ));
                Vec::new()
            }
        },
    };
    let d = model.steps;
    let mut checkpoints = Vec::new();
    if let Some(v) = obj.get("checkpoints") {
        match v.as_array().filter(|a| a.len() <= MAX_CHECKPOINTS) {
            None => errors.push(FieldError::new(
                "checkpoints",
                format!(
                    "expected an array of at most {MAX_CHECKPOINTS} step numbers 1…D, got {}",
                    got(v)
                ),
            )),
            Some(a) => {
                for (i, n) in a.iter().enumerate() {
                    match crate::json::whole_u64(n) {
                        Some(n) if n >= 1 && n as usize <= d => checkpoints.push(n as usize),
                        _ => errors.push(FieldError::new(
                            format!("checkpoints[{i}]"),
                            format!("expected a step number from 1 to D = {d}, got {}", got(n)),
                        )),
                    }
                }
            }
        }
    }
    checkpoints.sort_unstable();
    checkpoints.dedup();
    let trace_points = match obj.get("trace_points") {
        None => DEFAULT_TRACE_POINTS,
        Some(v) => match crate::json::whole_u64(v) {
            Some(p) if p as usize <= MAX_TRACE_POINTS => p as usize,
            _ => {
                errors.push(FieldError::new(
                    "trace_points",
                    format!(
                        "expected a whole number from 0 to {MAX_TRACE_POINTS}, got {}",
                        got(v)
                    ),
                ));
                0
            }
        },
    };
    if !errors.is_empty() {
        return Err(Error::Invalid(errors));
    }
    let (data, source) = read_data(obj.get("data"), &written, &set, &model)?;
    Ok(NonlinearRequest {
        model,
        data,
        source,
        alpha,
        residuals,
        q_scales,
        checkpoints,
        trace_points,
    })
}

/// An array of finite numbers.
fn numbers(v: &Value) -> Option<Vec<f64>> {
    v.as_array()?
        .iter()
        .map(|x| x.as_f64().filter(|x| x.is_finite()))
        .collect()
}

/// `data`: exactly one of `csv_text`, `rows`, `truth`.
fn read_data(
    v: Option<&Value>,
    written: &NonlinearModel,
    set: &Overrides,
    model: &Compiled,
) -> Result<(Measured, Source), Error> {
    const FORMS: &str =
        "{\"csv_text\": \"t,y\\n…\"}, {\"rows\": [[t, y1, …], …]} or {\"truth\": {\"seed\": 1, …}}";
    let Some(Value::Object(d)) = v else {
        return Err(Error::invalid(
            "data",
            match v {
                None => format!("missing: give the measurements, {FORMS}"),
                Some(other) => format!("expected an object, {FORMS}, got {}", got(other)),
            },
        ));
    };
    let grid = model.grid();
    let given: Vec<&String> = d.keys().collect();
    match given.as_slice() {
        [k] if *k == "csv_text" => {
            let Some(text) = d[*k].as_str() else {
                return Err(Error::invalid("data.csv_text", "expected the CSV's text"));
            };
            let m = data::from_csv(text, &model.names, &model.states, grid, "data.csv_text")?;
            Ok((m, Source::Csv))
        }
        [k] if *k == "csv" => Err(Error::invalid(
            "data.csv",
            "a file's path is read by the command line (kea nonlinear); a request to the server or the browser sends the file's text as data.csv_text",
        )),
        [k] if *k == "rows" => {
            let m = data::from_rows(&d[*k], &model.names, grid, "data.rows")?;
            Ok((m, Source::Rows))
        }
        [k] if *k == "truth" => {
            // (Simulated when the run starts: its cost is part of the work estimate.)
            let t = truth::read(&d[*k], written, set, "data.truth")?;
            Ok((Measured::default(), Source::Truth(Box::new(t))))
        }
        _ => Err(Error::invalid(
            "data",
            format!(
                "expected exactly one of csv_text, rows, truth ({FORMS}), got {}",
                if given.is_empty() {
                    "none".to_string()
                } else {
                    given
                        .iter()
                        .map(|s| s.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                }
            ),
        )),
    }
}
