//! An identification request, read strictly once: `{model, set?, data, estimate,
//! method?, max_iterations?}` (docs/identification.md). Every problem is named at its
//! path; the data are read against the model's grid and measurement names.

use super::data::{Grid, MAX_ROWS, from_csv, from_rows};
use super::minimise::Method;
use super::model::Data;
use crate::error::{Error, FieldError, got, member_path};
use crate::model::params::unknown_param;
use crate::model::{Model, Overrides};
use crate::request;
use serde_json::{Map, Value};

/// The most iterations a request may ask for.
pub const MAX_ITERATIONS: u64 = 10_000;
/// The most data values (steps × measurements) a request may hold (80 MB).
pub const MAX_DATA_VALUES: u64 = 10_000_000;
/// The most multiply-adds a simulation of the data may take (D · N · (N + L + m)).
pub const MAX_SIMULATION_WORK: u64 = 1_000_000_000;
/// The iterations when the request does not say.
pub const DEFAULT_MAX_ITERATIONS: usize = 100;

/// One estimated param: its initial value and bounds (±∞ when not given).
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    pub name: String,
    pub initial: f64,
    pub min: f64,
    pub max: f64,
}

/// An identification request, read and checked.
#[derive(Clone, Debug)]
pub struct IdentificationRequest {
    pub model: Model,
    /// The fixed overrides (`set`); the estimated params are not among them.
    pub set: Overrides,
    /// In name order (the order of the result's vectors and matrices).
    pub estimate: Vec<Estimate>,
    pub method: Method,
    pub max_iterations: usize,
    /// Further starting points (`starts`), each in `estimate`'s order.
    pub starts: Vec<Vec<f64>>,
    /// Whether the expected information and the Cramér–Rao bound are computed at θ̂
    /// (`expected_information`, default false: one pass wider than a fit's).
    pub expected_information: bool,
    pub data: Data,
}

impl IdentificationRequest {
    /// The estimated params' names, in order.
    pub fn names(&self) -> Vec<&str> {
        self.estimate.iter().map(|e| e.name.as_str()).collect()
    }

    /// The model's measurement names, the data's columns after `t`.
    pub fn measurement_names(&self) -> Vec<String> {
        self.model.measurement.names.clone()
    }

    /// `set` with the estimated params at `theta`.
    pub fn params_at(&self, theta: &[f64]) -> Overrides {
        let mut p = self.set.clone();
        for (e, x) in self.estimate.iter().zip(theta) {
            p.insert(e.name.clone(), *x);
        }
        p
    }
}

/// Read a request object (its members already checked against the kind's list).
pub fn read(obj: &Map<String, Value>) -> Result<IdentificationRequest, Error> {
    let mut errors = Vec::new();
    let (model, set) = request::model_and_set(obj, &mut errors);
    let method = match request::choice(
        obj,
        "method",
        &[
            ("scoring", "Fisher scoring with a line search, the default"),
            ("gradient", "gradient descent with step halving"),
            (
                "conjugate",
                "conjugate directions, restarted every p iterations",
            ),
        ],
        &mut errors,
    ) {
        Some(1) => Method::Gradient,
        Some(2) => Method::Conjugate,
        _ => Method::Scoring,
    };
    let max_iterations = match request::whole(
        obj,
        "max_iterations",
        &format!("a whole number of iterations, 1 to {MAX_ITERATIONS}"),
        &mut errors,
    ) {
        Some(k) if (1..=MAX_ITERATIONS).contains(&k) => k as usize,
        Some(k) => {
            errors.push(FieldError::new(
                "max_iterations",
                format!("expected 1 to {MAX_ITERATIONS} iterations, got {k}"),
            ));
            DEFAULT_MAX_ITERATIONS
        }
        None => DEFAULT_MAX_ITERATIONS,
    };
    let expected_information =
        request::flag(obj, "expected_information", &mut errors).unwrap_or(false);
    let Some(model) = model else {
        return Err(Error::Invalid(errors));
    };
    let estimate = estimates(obj.get("estimate"), &model, &set, &mut errors);
    let starts = starts(obj.get("starts"), &estimate, &mut errors);
    if !errors.is_empty() {
        return Err(Error::Invalid(errors));
    }
    // The model at the initial values: its errors under `model.`, its grid and names
    // for the data.
    let mut at_initial = set.clone();
    for e in &estimate {
        at_initial.insert(e.name.clone(), e.initial);
    }
    let compiled = super::discrete::compile(&model, &at_initial)
        .and_then(|c| super::discrete::check(&c).map(|()| c))
        .map_err(request::locate)?;
    if compiled.max_steps() > MAX_ROWS as u64 {
        return Err(Error::invalid(
            "model.time.steps",
            format!(
                "{} steps: the identification's data hold at most {MAX_ROWS} steps",
                compiled.max_steps()
            ),
        ));
    }
    // The data are held whole (D × m values) and a simulation is made here, before the
    // work estimate is checked: both bounded up front.
    let (d, nm) = (compiled.max_steps(), compiled.n_measurements() as u64);
    if d * nm > MAX_DATA_VALUES {
        return Err(Error::invalid(
            "model.time.steps",
            format!(
                "{d} steps × {nm} measurements = {} values: the identification's data hold at most {MAX_DATA_VALUES}",
                d * nm
            ),
        ));
    }
    let (n, l) = (compiled.n_states() as u64, compiled.b.cols as u64);
    let simulation = d * n * (n + l + nm);
    if obj.get("data").is_some_and(|v| v.get("simulate").is_some())
        && simulation > MAX_SIMULATION_WORK
    {
        return Err(Error::invalid(
            "data.simulate",
            format!(
                "simulating {d} steps of N = {n} states is {simulation} multiply-adds, more than the limit of {MAX_SIMULATION_WORK} (about a second): use fewer steps"
            ),
        ));
    }
    let grid = Grid::new(compiled.t0, compiled.t_end, compiled.max_steps() as usize);
    let data = data(
        obj.get("data"),
        &compiled.measurements,
        &grid,
        (&model, &set),
    )?;
    Ok(IdentificationRequest {
        model,
        set,
        estimate,
        method,
        max_iterations,
        starts,
        expected_information,
        data,
    })
}

/// `estimate`: an object of params, each `{initial?, min?, max?}` (or `{}`: from the
/// model's value, unbounded).
fn estimates(
    v: Option<&Value>,
    model: &Model,
    set: &Overrides,
    errors: &mut Vec<FieldError>,
) -> Vec<Estimate> {
    let example =
        "an object of the params to estimate, e.g. {\"q\": {\"initial\": 0.5, \"min\": 0}}";
    let obj = match v {
        None => {
            errors.push(FieldError::new("estimate", format!("missing: {example}")));
            return Vec::new();
        }
        Some(Value::Object(o)) if !o.is_empty() => o,
        Some(other) => {
            errors.push(FieldError::new(
                "estimate",
                format!("expected {example}, got {}", got(other)),
            ));
            return Vec::new();
        }
    };
    let mut out = Vec::new();
    for (name, spec) in obj {
        let path = member_path("estimate", name);
        let Some(value) = model.params.get(name) else {
            errors.push(FieldError::new(&path, unknown_param(&model.params, name)));
            continue;
        };
        if set.contains_key(name) {
            errors.push(FieldError::new(
                &path,
                format!("\"{name}\" is both estimated and fixed by set.{name}: give it once"),
            ));
            continue;
        }
        let Value::Object(spec) = spec else {
            errors.push(FieldError::new(
                &path,
                format!(
                    "expected {{\"initial\": x, \"min\": lo, \"max\": hi}} (each optional), got {}",
                    got(spec)
                ),
            ));
            continue;
        };
        let before = errors.len();
        for k in spec.keys() {
            if !["initial", "min", "max"].contains(&k.as_str()) {
                errors.push(FieldError::new(
                    member_path(&path, k),
                    "unknown member; expected one of: initial, min, max",
                ));
            }
        }
        let mut number = |k: &str, default: f64| match spec.get(k) {
            None => default,
            Some(v) => match v.as_f64() {
                Some(x) if x.is_finite() => x,
                _ => {
                    errors.push(FieldError::new(
                        member_path(&path, k),
                        format!("expected a finite number, got {}", got(v)),
                    ));
                    default
                }
            },
        };
        let initial = number("initial", *value);
        let min = number("min", f64::NEG_INFINITY);
        let max = number("max", f64::INFINITY);
        if errors.len() == before {
            if min >= max {
                errors.push(FieldError::new(
                    member_path(&path, "max"),
                    format!("max ({max}) must be greater than min ({min})"),
                ));
            } else if !(min..=max).contains(&initial) {
                errors.push(FieldError::new(
                    member_path(&path, "initial"),
                    format!("the initial value {initial} is outside [min, max] = [{min}, {max}]"),
                ));
            }
        }
        out.push(Estimate {
            name: name.clone(),
            initial,
            min,
            max,
        });
    }
    out
}

/// `data`: `{"rows": [[t, z1, …], …]}` or `{"csv_text": "t,z1,…\n…"}` (a file's
/// content; the command line reads `{"csv": PATH}` into it).
fn data(
    v: Option<&Value>,
    names: &[String],
    grid: &Grid,
    (model, set): (&Model, &Overrides),
) -> Result<Data, Error> {
    let forms = "{\"rows\": [[t, z1, …], …]}, {\"csv_text\": \"t,z1,…\"} or {\"simulate\": {\"seed\": 1, \"set\": {…}}} (the command line also reads {\"csv\": \"FILE\"})";
    let obj = match v {
        None => {
            return Err(Error::invalid(
                "data",
                format!("missing: the measurements, as {forms}"),
            ));
        }
        Some(Value::Object(o)) => o,
        Some(other) => {
            return Err(Error::invalid(
                "data",
                format!("expected {forms}, got {}", got(other)),
            ));
        }
    };
    let keys: Vec<&str> = obj.keys().map(String::as_str).collect();
    match keys.as_slice() {
        ["rows"] => from_rows(&obj["rows"], names, grid, "data.rows"),
        ["csv_text"] => match &obj["csv_text"] {
            Value::String(text) => from_csv(text, names, grid, "data.csv_text"),
            other => Err(Error::invalid(
                "data.csv_text",
                format!(
                    "expected the CSV file's content as a string, got {}",
                    got(other)
                ),
            )),
        },
        ["simulate"] => simulated(&obj["simulate"], grid, model, set),
        ["csv"] => Err(Error::invalid(
            "data.csv",
            "a file is read by the command line (kea identify); in a request sent to the server or the browser, give the file's content as data.csv_text",
        )),
        _ => Err(Error::invalid(
            "data",
            format!("expected exactly one of rows, csv_text, simulate: {forms}"),
        )),
    }
}

/// `data.simulate`: `{"seed": s, "set": {...}}`, data drawn from the model at its params
/// with `set` and then the truth's own `set` (the estimated params' initial values play
/// no part: the truth is what the fit should find).
fn simulated(v: &Value, grid: &Grid, model: &Model, set: &Overrides) -> Result<Data, Error> {
    let path = "data.simulate";
    let Value::Object(obj) = v else {
        return Err(Error::invalid(
            path,
            format!(
                "expected {{\"seed\": 1, \"set\": {{…}}}} (both optional), got {}",
                got(v)
            ),
        ));
    };
    // Every problem at its path inside `data.simulate`, prefixed once at the end.
    let mut errors = request::unknown_members(obj, &["seed", "set"]);
    let seed = request::whole(
        obj,
        "seed",
        "a whole number ≥ 0 (the random stream's seed)",
        &mut errors,
    )
    .unwrap_or(1);
    let truth = request::overrides(obj.get("set")).unwrap_or_else(|e| {
        errors.extend(e);
        Overrides::new()
    });
    let named = obj
        .get("set")
        .and_then(Value::as_object)
        .into_iter()
        .flat_map(|m| m.keys());
    for name in named.filter(|name| !model.params.contains_key(*name)) {
        errors.push(FieldError::new(
            member_path("set", name),
            unknown_param(&model.params, name),
        ));
    }
    if !errors.is_empty() {
        return Err(Error::Invalid(errors).with_prefix(path));
    }
    let mut at = set.clone();
    at.extend(truth);
    let (discrete, prior, _) = super::discrete::at(model, &at, &[]).map_err(request::locate)?;
    super::simulate::simulate(&discrete, &prior, grid, seed).map_err(request::locate)
}

/// The most further starts a request may give.
pub const MAX_STARTS: usize = 100;

/// `starts`: `[{"PARAM": x, …}, …]`, each a further starting point; a param it leaves
/// out starts at its `initial`. Each value inside the param's bounds.
fn starts(v: Option<&Value>, estimate: &[Estimate], errors: &mut Vec<FieldError>) -> Vec<Vec<f64>> {
    let Some(v) = v else {
        return Vec::new();
    };
    let Value::Array(list) = v else {
        errors.push(FieldError::new(
            "starts",
            format!("expected an array of starting points, e.g. [{{\"q\": 0.1}}, {{\"q\": 10}}], got {}", got(v)),
        ));
        return Vec::new();
    };
    if list.len() > MAX_STARTS {
        errors.push(FieldError::new(
            "starts",
            format!("{} starts: at most {MAX_STARTS}", list.len()),
        ));
        return Vec::new();
    }
    let mut out = Vec::new();
    for (k, s) in list.iter().enumerate() {
        let path = format!("starts[{k}]");
        let Value::Object(s) = s else {
            errors.push(FieldError::new(
                &path,
                format!("expected an object of param values, got {}", got(s)),
            ));
            continue;
        };
        for name in s.keys() {
            if !estimate.iter().any(|e| &e.name == name) {
                errors.push(FieldError::new(
                    member_path(&path, name),
                    "not an estimated param: a start gives values of the params in `estimate`",
                ));
            }
        }
        let point: Vec<f64> = estimate
            .iter()
            .map(|e| match s.get(&e.name) {
                None => e.initial,
                Some(v) => match v.as_f64() {
                    Some(x) if x.is_finite() && (e.min..=e.max).contains(&x) => x,
                    _ => {
                        errors.push(FieldError::new(
                            member_path(&path, &e.name),
                            format!(
                                "expected a number in [min, max] = [{}, {}], got {}",
                                e.min,
                                e.max,
                                got(v)
                            ),
                        ));
                        e.initial
                    }
                },
            })
            .collect();
        out.push(point);
    }
    out
}
