//! The nonlinear model (METHOD §4): what a user writes ([`NonlinearModel`], serde)
//! and what the filters run on ([`Compiled`]).
//!
//! ```text
//!     dx/dt = f(x, t) + noise of intensity W,   y_n = h(x(t_n)) + v_n,  v_n ~ N(0, V)
//! ```
//!
//! `system.f` (N texts) and `measurement.h` (n texts) are expressions in the state
//! names, `t` and the params; F = ∂f/∂x and H = ∂h/∂x come from them
//! ([`crate::expr::StateFn`]). The names are the linear model's where the concept is
//! the same: `y0` the initial mean x⁰, `eta0` its SKOs or `P0` its covariance, `phi`
//! the process noise's SKOs per state or `W` its intensity (Q_η of METHOD §4, per unit
//! time: a step adds W·Δt), `psi` the SKO of each measurement sample or `V` its
//! covariance (R = V, the seed's σ²). The grid: `time.t0`, `time.t_end`, `time.steps`
//! D, Δt = (t_end − t0)/D; a measurement may come at each t_n = t0 + nΔt, n = 1…D.

use crate::error::{Error, member_path};
use crate::expr::{StateFn, Value};
use crate::model::Overrides;
use crate::model::compile::Errors;
use crate::model::compile::matrices::const_vector;
use crate::model::compile::names::check_names;
use crate::model::compile::noise::noise_cov;
use crate::model::limits::MAX_STEPS;
use crate::text::is_identifier;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The version of the nonlinear model format this build reads.
pub const NONLINEAR_FORMAT_VERSION: u32 = 1;

/// The most states (and measurements): the filters' per-step cost grows as N³.
pub const MAX_NONLINEAR_STATES: usize = 32;

/// A nonlinear model as written.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NonlinearModel {
    /// Format version; absent means the current one.
    #[serde(default = "version")]
    pub kea_nonlinear: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// Named numbers usable in every expression.
    #[serde(default)]
    pub params: BTreeMap<String, f64>,
    pub time: Time,
    pub system: System,
    pub measurement: Measurement,
    /// The procedure's defaults (a request's `procedure` overrides them member by member).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub procedure: Option<Procedure>,
}

/// The procedure's settings (METHOD §4).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Procedure {
    /// The regularisation steps α_0 … α_{K−1} (K filters).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha: Option<Vec<f64>>,
    /// Which residuals of the earlier filters enter a later one's update.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub earlier_residuals: Option<super::bank::Residuals>,
}

fn version() -> u32 {
    NONLINEAR_FORMAT_VERSION
}

/// The grid: D steps from t0 to t_end.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Time {
    pub t0: f64,
    pub t_end: f64,
    pub steps: u64,
}

/// dx/dt = f(x, t) + process noise.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct System {
    /// State names; their count is N.
    pub states: Vec<String>,
    /// N expressions in the states, `t` and the params.
    pub f: Vec<Value>,
    /// The initial mean x⁰ (N).
    pub y0: Vec<Value>,
    /// The initial SKOs (N): P⁰ = diag(η0²) — or give `P0`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eta0: Option<Vec<Value>>,
    /// The initial covariance P⁰ (N×N), instead of `eta0`.
    #[serde(default, rename = "P0", skip_serializing_if = "Option::is_none")]
    pub p0: Option<Vec<Vec<Value>>>,
    /// The process noise's SKOs per state (N): W = diag(φ²) — or give `W`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phi: Option<Vec<Value>>,
    /// The process noise's intensity W (N×N, per unit time), instead of `phi`.
    #[serde(default, rename = "W", skip_serializing_if = "Option::is_none")]
    pub w: Option<Vec<Vec<Value>>>,
}

/// y_n = h(x(t_n)) + v_n.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Measurement {
    /// Measurement names; their count is n.
    pub names: Vec<String>,
    /// n expressions in the states, `t` and the params.
    pub h: Vec<Value>,
    /// The SKO of each sample (n): V = diag(ψ²) — or give `V`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psi: Option<Vec<Value>>,
    /// The samples' covariance V (n×n), instead of `psi`.
    #[serde(default, rename = "V", skip_serializing_if = "Option::is_none")]
    pub v: Option<Vec<Vec<Value>>>,
}

/// A model ready to run.
#[derive(Clone, Debug)]
pub struct Compiled {
    pub states: Vec<String>,
    pub names: Vec<String>,
    /// f (N); `system.f[i]` is f[i]'s path.
    pub f: Vec<StateFn>,
    pub h: Vec<StateFn>,
    pub y0: Vec<f64>,
    /// N×N row-major.
    pub p0: Vec<f64>,
    /// N×N, per unit time.
    pub w: Vec<f64>,
    /// n×n, positive definite.
    pub v: Vec<f64>,
    pub t0: f64,
    pub dt: f64,
    pub steps: usize,
    pub params: BTreeMap<String, f64>,
}

impl Compiled {
    /// N.
    pub fn n_states(&self) -> usize {
        self.states.len()
    }
    /// n.
    pub fn n_measurements(&self) -> usize {
        self.names.len()
    }
    /// t_k = t0 + k·Δt.
    pub fn t(&self, k: usize) -> f64 {
        self.t0 + k as f64 * self.dt
    }
    /// The grid the data sit on.
    pub fn grid(&self) -> super::data::Grid {
        super::data::Grid {
            t0: self.t0,
            dt: self.dt,
            steps: self.steps,
        }
    }
}

/// A model from JSON, every serde error at its path.
pub fn from_value(value: serde_json::Value) -> Result<NonlinearModel, Error> {
    if !value.is_object() {
        return Err(Error::invalid(
            "",
            format!(
                "a nonlinear model is a JSON object ({{\"kea_nonlinear\": 1, \"time\": …, \"system\": …, \"measurement\": …}}), got {}",
                crate::error::json_kind(&value)
            ),
        ));
    }
    crate::json::from_value_at(value, &[])
}

/// Validate and compile `model` with the param overrides `set`; every problem at its
/// path in the model (`system.f[1]`, `measurement.psi[0]`; `set.b` for an override).
pub fn compile(model: &NonlinearModel, set: &Overrides) -> Result<Compiled, Error> {
    let mut errs = Errors(Vec::new());
    if model.kea_nonlinear != NONLINEAR_FORMAT_VERSION {
        errs.at(
            "kea_nonlinear",
            format!(
                "unsupported nonlinear model format version {}; this kea reads version {NONLINEAR_FORMAT_VERSION}",
                model.kea_nonlinear
            ),
        );
        return Err(errs.into_error());
    }
    let params = crate::model::compile::params_with(&model.params, set, &mut errs);
    if !errs.0.is_empty() {
        return Err(errs.into_error());
    }

    // --- time
    let t = &model.time;
    crate::model::compile::check_interval(t.t0, t.t_end, &mut errs);
    if !(1..=MAX_STEPS).contains(&t.steps) {
        errs.at(
            "time.steps",
            format!("expected 1 to {MAX_STEPS} steps, got {}", t.steps),
        );
    }

    // --- names
    let sys = &model.system;
    let meas = &model.measurement;
    let n = sys.states.len();
    let m = meas.names.len();
    for (len, path, what) in [
        (n, "system.states", "state"),
        (m, "measurement.names", "measurement"),
    ] {
        if len == 0 {
            errs.at(path, format!("expected at least one {what} name"));
        } else if len > MAX_NONLINEAR_STATES {
            errs.at(
                path,
                format!("{len} {what}s; the limit is {MAX_NONLINEAR_STATES}"),
            );
        }
    }
    check_names(&sys.states, "system.states", &mut errs);
    check_names(&meas.names, "measurement.names", &mut errs);
    for (i, s) in sys.states.iter().enumerate() {
        let path = format!("system.states[{i}]");
        if !is_identifier(s) {
            errs.at(
                &path,
                format!("a state name is used in f and h, so it must be an identifier (letters, digits, _; not starting with a digit), got \"{s}\""),
            );
        } else if s == "t" {
            errs.at(&path, "\"t\" is the time variable and cannot be a state");
        } else if crate::expr::is_reserved(s) {
            errs.at(
                &path,
                format!("\"{s}\" is a function or constant of the expression language and cannot be a state"),
            );
        } else if params.contains_key(s) {
            errs.at(
                &path,
                format!(
                    "\"{s}\" is also a param ({}): a name means one thing in an expression",
                    member_path("params", s)
                ),
            );
        }
    }
    if !errs.0.is_empty()
        || n == 0
        || m == 0
        || n > MAX_NONLINEAR_STATES
        || m > MAX_NONLINEAR_STATES
    {
        return Err(errs.into_error());
    }

    // --- f and h
    let f = state_fns(&sys.f, n, "system.f", "N", &sys.states, &params, &mut errs);
    let h = state_fns(
        &meas.h,
        m,
        "measurement.h",
        "n",
        &sys.states,
        &params,
        &mut errs,
    );

    // --- the initial state and the noises
    let y0 = if sys.y0.len() == n {
        const_vector(
            Some(&sys.y0),
            n,
            "system.y0",
            "N",
            &params,
            &mut errs,
            false,
        )
    } else {
        errs.at(
            "system.y0",
            format!("has {} entries, expected {n} (N = {n})", sys.y0.len()),
        );
        vec![0.0; n]
    };
    let (p0, _) = noise_cov(
        sys.eta0.as_deref(),
        sys.p0.as_deref(),
        n,
        ("system.eta0", "system.P0", "N"),
        &params,
        &mut errs,
    );
    let (w, _) = noise_cov(
        sys.phi.as_deref(),
        sys.w.as_deref(),
        n,
        ("system.phi", "system.W", "N"),
        &params,
        &mut errs,
    );
    let (v, _) = noise_cov(
        meas.psi.as_deref(),
        meas.v.as_deref(),
        m,
        ("measurement.psi", "measurement.V", "n"),
        &params,
        &mut errs,
    );
    if errs.0.is_empty() {
        let mut l = v.clone();
        if !crate::numerics::linalg::cholesky(&mut l, m) {
            let path = if meas.psi.is_some() {
                "measurement.psi"
            } else {
                "measurement.V"
            };
            errs.at(
                path,
                "the measurement noise must be positive definite (every SKO > 0): a filter step divides by it",
            );
        }
    }
    let (f, h) = match (f, h) {
        (Some(f), Some(h)) if errs.0.is_empty() => (f, h),
        _ => return Err(errs.into_error()),
    };
    let steps = t.steps as usize;
    Ok(Compiled {
        states: sys.states.clone(),
        names: meas.names.clone(),
        f,
        h,
        y0,
        p0,
        w,
        v,
        t0: t.t0,
        dt: (t.t_end - t.t0) / steps as f64,
        steps,
        params,
    })
}

/// `values` (`len` of them, at `path`) compiled as expressions in the states.
fn state_fns(
    values: &[Value],
    len: usize,
    path: &str,
    sym: &str,
    states: &[String],
    params: &BTreeMap<String, f64>,
    errs: &mut Errors,
) -> Option<Vec<StateFn>> {
    if values.len() != len {
        errs.at(
            path,
            format!(
                "has {} expressions, expected {len} ({sym} = {len})",
                values.len()
            ),
        );
        return None;
    }
    let mut out = Vec::with_capacity(len);
    let mut ok = true;
    for (i, v) in values.iter().enumerate() {
        match StateFn::compile(v, states, params, &format!("{path}[{i}]")) {
            Ok(f) => out.push(f),
            Err(e) => {
                errs.push(e);
                ok = false;
            }
        }
    }
    ok.then_some(out)
}
