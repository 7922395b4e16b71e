//! Validation: a submitted [`Model`] plus overrides becomes a [`CompiledModel`] or a
//! list of errors, each naming the field path and what was expected.

use crate::error::{Error, FieldError, member_path};
use crate::error::{MAX_REPORTED_ERRORS, omitted_entry};
use crate::expr::{ExprBudget, TimeMatrix, compile_const};
use crate::model::Overrides;
use crate::model::limits::*;
use crate::model::{MODEL_FORMAT_VERSION, Model, PriorAt, Steps};
use crate::text::{is_identifier, num};
use std::collections::BTreeMap;

mod blind;
mod criteria;
pub(crate) mod matrices;
pub(crate) mod names;
pub(crate) mod noise;
use blind::blind_measurements;
use criteria::weights;
use matrices::{check_shape, const_matrix, const_vector, time_matrix, time_vector};
use names::check_names;
use noise::noise_cov;

#[derive(Clone, Debug)]
pub enum StepPlan {
    Fixed(u64),
    Auto {
        tolerance: f64,
        initial_steps: u64,
        max_steps: u64,
    },
}

/// A validated model, ready to run. Matrices are row-major.
#[derive(Clone, Debug)]
pub struct CompiledModel {
    pub states: Vec<String>,
    pub measurements: Vec<String>,
    pub t0: f64,
    pub t_end: f64,
    pub steps: StepPlan,
    /// a(t), N×N.
    pub a: TimeMatrix,
    /// Φ, N×N, of a discrete model ([`compile_discrete`]; `a` is then zero).
    pub transition: Option<Vec<f64>>,
    /// Where the initial state (y0, η0) sits.
    pub prior_at: PriorAt,
    /// u(t), N×1.
    pub u: TimeMatrix,
    /// b(t), N×L.
    pub b: TimeMatrix,
    /// C, n×N (constant).
    pub c: Vec<f64>,
    /// Γ(t), n×M — or, in the seed's form, g(t) N×M with Γ = C g.
    pub noise: MeasurementNoise,
    pub y0: Vec<f64>,
    pub eta0: Vec<f64>,
    /// W, L×L; φ_l = sqrt(W_ll).
    pub w: Vec<f64>,
    pub phi: Vec<f64>,
    /// V, M×M; ψ_m = sqrt(V_mm).
    pub v: Vec<f64>,
    pub psi: Vec<f64>,
    /// Measurement availability; None = every measurement at every step.
    pub schedule: Option<crate::model::schedule::Schedules>,
    /// For each state, its paired measurement (METHOD §1.1).
    pub pair_of_state: Vec<Option<usize>>,
    /// Weights per criterion (N each); None = equal over the states where defined.
    pub weights_yz: Option<Vec<f64>>,
    pub weights_zx: Option<Vec<f64>>,
    pub weights_yx: Option<Vec<f64>>,
    pub confidence: f64,
    pub trace_points: usize,
    pub steady_state_shortcut: bool,
    /// Parts of the model that were accepted but have no effect, said in the result's
    /// warnings (`time.auto` with an integer `steps`).
    pub notes: Vec<String>,
    /// Which entries depend on which params: the values above are at the params'
    /// values (a constant entry folded to its number), this says what each owes to
    /// which param (METHOD §3's ∂/∂θ; `crate::model::params`).
    pub param_dependence: crate::model::params::ParamDependence,
}

#[derive(Clone, Debug)]
pub enum MeasurementNoise {
    /// Γ(t), n×M.
    Gamma(TimeMatrix),
    /// g(t), N×M; Γ = C g.
    SeedG(TimeMatrix),
}

impl MeasurementNoise {
    pub fn sources(&self) -> usize {
        match self {
            MeasurementNoise::Gamma(m) | MeasurementNoise::SeedG(m) => m.cols,
        }
    }
    pub fn matrix(&self) -> &TimeMatrix {
        match self {
            MeasurementNoise::Gamma(m) | MeasurementNoise::SeedG(m) => m,
        }
    }
}

impl CompiledModel {
    pub fn n_states(&self) -> usize {
        self.states.len()
    }
    pub fn n_measurements(&self) -> usize {
        self.measurements.len()
    }
    /// D, or the cap of `"auto"`.
    pub fn max_steps(&self) -> u64 {
        match self.steps {
            StepPlan::Fixed(d) => d,
            StepPlan::Auto { max_steps, .. } => max_steps,
        }
    }
    /// Whether the covariance recursion's inputs (a, b, Γ) do not depend on t.
    pub fn is_time_invariant(&self) -> bool {
        self.a.is_constant()
            && self.b.is_constant()
            && self.noise.matrix().is_constant()
            && self.schedule.is_none()
    }
}

/// Collects errors; the first error per field is enough.
pub(crate) struct Errors(pub(crate) Vec<FieldError>);

impl Errors {
    pub(crate) fn push(&mut self, e: FieldError) {
        self.0.push(e);
    }
    /// The errors as `Error::Invalid`, at most [`MAX_REPORTED_ERRORS`] of them.
    pub(crate) fn into_error(mut self) -> Error {
        let more = self.0.len().saturating_sub(MAX_REPORTED_ERRORS);
        if more > 0 {
            self.0.truncate(MAX_REPORTED_ERRORS);
            self.0.push(omitted_entry(more));
        }
        Error::Invalid(self.0)
    }
    pub(crate) fn at(&mut self, path: &str, msg: impl Into<String>) {
        self.0.push(FieldError::new(path, msg));
    }
}

/// A model's form: continuous (`system.a`, discretised by the analysis, METHOD §1.2)
/// or discrete (`system.transition`, Φ per step, METHOD §3 (1.4.1)).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Form {
    Continuous,
    Discrete,
}

/// Validate and compile a continuous model (`system.a`) with parameter overrides: the
/// analysis's, the Monte Carlo's and the synthesis's.
pub fn compile(model: &Model, set: &Overrides) -> Result<CompiledModel, Error> {
    compile_form(model, set, Form::Continuous)
}

/// Validate and compile a discrete model (`system.transition`) with parameter
/// overrides: the identification's. Its Φ is [`CompiledModel::transition`]; `a` is
/// zero.
pub fn compile_discrete(model: &Model, set: &Overrides) -> Result<CompiledModel, Error> {
    compile_form(model, set, Form::Discrete)
}

/// A model's `params` with the overrides `set` applied, every problem with either
/// pushed to `errs`: a name that is not an identifier, `t` or a name of the expression
/// language, a value that is not finite, an override of no declared param. (Shared with
/// the nonlinear model, `crate::nonlinear::model`.)
pub(crate) fn params_with(
    declared: &BTreeMap<String, f64>,
    set: &Overrides,
    errs: &mut Errors,
) -> BTreeMap<String, f64> {
    let mut params = declared.clone();
    for (name, value) in declared {
        let path = member_path("params", name);
        if !is_identifier(name) {
            errs.at(&path, "a parameter name must be an identifier (letters, digits, _; not starting with a digit)");
        } else if name == "t" {
            errs.at(
                &path,
                "\"t\" is the time variable and cannot be a parameter",
            );
        } else if crate::expr::is_reserved(name) {
            errs.at(
                &path,
                format!("\"{name}\" is a function or constant of the expression language and cannot be a parameter"),
            );
        }
        if !value.is_finite() {
            errs.at(&path, "expected a finite number");
        }
    }
    for (name, value) in set {
        let path = member_path("set", name);
        if !declared.contains_key(name) {
            errs.at(&path, crate::model::params::unknown_param(declared, name));
        } else if !value.is_finite() {
            errs.at(&path, "expected a finite number");
        } else {
            params.insert(name.clone(), *value);
        }
    }
    params
}

/// `time.t0` and `time.t_end` finite, t_end > t0 (the linear and the nonlinear model's).
pub(crate) fn check_interval(t0: f64, t_end: f64, errs: &mut Errors) {
    if !t0.is_finite() {
        errs.at("time.t0", "expected a finite number");
    }
    if !t_end.is_finite() {
        errs.at("time.t_end", "expected a finite number");
    } else if t0.is_finite() && t_end <= t0 {
        errs.at(
            "time.t_end",
            format!(
                "t_end ({}) must be greater than t0 ({})",
                num(t_end),
                num(t0)
            ),
        );
    }
}

fn compile_form(model: &Model, set: &Overrides, form: Form) -> Result<CompiledModel, Error> {
    let mut errs = Errors(Vec::new());

    if model.kea_model != MODEL_FORMAT_VERSION {
        errs.at(
            "kea_model",
            format!(
                "unsupported model format version {}; this kea reads version {MODEL_FORMAT_VERSION}",
                model.kea_model
            ),
        );
    }

    // --- params and overrides
    let params = params_with(&model.params, set, &mut errs);
    // Errors in the version or the params stop here (every expression depends on the
    // params); an unknown `set` name does not: the model's own errors are listed with it.
    if errs.0.iter().any(|e| {
        e.path == "kea_model" || e.path.starts_with("params.") || e.path.starts_with("params[")
    }) {
        return Err(errs.into_error());
    }

    // --- time
    let t = &model.time;
    check_interval(t.t0, t.t_end, &mut errs);
    let mut notes = Vec::new();
    if let (Steps::Fixed(d), Some(_)) = (&t.steps, &t.auto) {
        notes.push(format!(
            "time.auto has no effect: steps is {d}, not \"auto\" (set steps to \"auto\" for the step-size selection, or leave time.auto out)"
        ));
    }
    let steps = match &t.steps {
        Steps::Fixed(0) => {
            errs.at("time.steps", "steps must be at least 1");
            StepPlan::Fixed(1)
        }
        Steps::Fixed(d) if *d > MAX_STEPS => {
            errs.at(
                "time.steps",
                format!("{d} steps is more than the limit of {MAX_STEPS}"),
            );
            StepPlan::Fixed(1)
        }
        Steps::Fixed(d) => StepPlan::Fixed(*d),
        Steps::Auto(s) if s == "auto" => {
            let auto = t.auto.clone().unwrap_or_default();
            if !(auto.tolerance.is_finite() && auto.tolerance > 0.0) {
                errs.at("time.auto.tolerance", "expected a positive number");
            }
            if auto.initial_steps == 0 {
                errs.at("time.auto.initial_steps", "must be at least 1");
            }
            if auto.max_steps > MAX_STEPS {
                errs.at(
                    "time.auto.max_steps",
                    format!("must not exceed the limit of {MAX_STEPS}"),
                );
            }
            if auto.initial_steps > MAX_STEPS {
                errs.at(
                    "time.auto.initial_steps",
                    format!("must not exceed the limit of {MAX_STEPS}"),
                );
            } else if auto.max_steps < auto.initial_steps {
                errs.at("time.auto.max_steps", "must be at least initial_steps");
            }
            StepPlan::Auto {
                tolerance: auto.tolerance,
                initial_steps: auto.initial_steps.max(1),
                max_steps: auto.max_steps.clamp(1, MAX_STEPS),
            }
        }
        Steps::Auto(s) => {
            errs.at(
                "time.steps",
                format!("expected a positive integer or \"auto\", got \"{s}\""),
            );
            StepPlan::Fixed(1)
        }
    };
    // The grid t0 + kΔt must be representable: a finite span, and a finest step that
    // moves t at both ends (t_end = 5e-324 gave Δt = 0; t0 = −1e308, t_end = 1e308 an
    // infinite span).
    if t.t0.is_finite() && t.t_end.is_finite() && t.t_end > t.t0 {
        let span = t.t_end - t.t0;
        let finest = match steps {
            StepPlan::Fixed(d) => d,
            StepPlan::Auto { max_steps, .. } => max_steps,
        };
        let dt = span / finest as f64;
        if !span.is_finite() {
            errs.at(
                "time.t_end",
                format!(
                    "t_end − t0 = {} − ({}) overflows f64",
                    num(t.t_end),
                    num(t.t0)
                ),
            );
        } else if !(t.t0 + dt > t.t0 && t.t_end - dt < t.t_end) {
            errs.at(
                "time.steps",
                format!(
                    "the step Δt = (t_end − t0)/D = {}/{finest} = {} is below f64's resolution of t on [{}, {}]: use fewer steps or a wider interval",
                    num(span),
                    num(dt),
                    num(t.t0),
                    num(t.t_end)
                ),
            );
        }
    }
    let t0 = if t.t0.is_finite() { t.t0 } else { 0.0 };

    // --- system
    let sys = &model.system;
    let n = sys.states.len();
    // (Errors in the sizes stop the validation: everything after is sized by them.)
    let before = errs.0.len();
    if n == 0 {
        errs.at("system.states", "at least one state is needed");
    } else if n > MAX_STATES {
        errs.at(
            "system.states",
            format!("{n} states is more than the limit of {MAX_STATES}"),
        );
    }
    check_names(&sys.states, "system.states", &mut errs);
    if errs.0.len() > before {
        return Err(errs.into_error());
    }

    // Noise sources: W and V are L×L and M×M, so these are bounded before anything
    // is sized by them.
    let sources = [
        ("system.b[0]", "L (columns of b)", sys.b.first()),
        (
            "measurement.gamma[0]",
            "M (columns of gamma)",
            model.measurement.gamma.as_ref().and_then(|g| g.first()),
        ),
        (
            "measurement.g[0]",
            "M (columns of g)",
            model.measurement.g.as_ref().and_then(|g| g.first()),
        ),
    ];
    let before = errs.0.len();
    for (path, what, row) in sources {
        if let Some(row) = row
            && row.len() > MAX_SOURCES
        {
            errs.at(
                path,
                format!(
                    "{what} = {}: more than the limit of {MAX_SOURCES} noise sources",
                    row.len()
                ),
            );
        }
    }
    if errs.0.len() > before {
        return Err(errs.into_error());
    }

    // What the model's distinct time-dependent expressions use (expr::MAX_TIME_*).
    let mut exprs = ExprBudget::default();
    let (a, transition) = match form {
        Form::Continuous => {
            if sys.transition.is_some() {
                errs.at(
                    "system.transition",
                    "a discrete-time model (transition, Φ) is read by the identification only; the analysis, the Monte Carlo and the synthesis need the continuous a",
                );
            } else if sys.a.is_empty() {
                errs.at("system.a", "missing: give a (N×N)");
            }
            if sys.prior_at == Some(PriorAt::FirstMeasurement) {
                errs.at(
                    "system.prior_at",
                    "\"first_measurement\" is for a discrete model (transition); a continuous model's initial state is at t0",
                );
            }
            let a = if sys.a.is_empty() {
                TimeMatrix::constant(n, n, vec![0.0; n * n])
            } else {
                time_matrix(
                    &sys.a,
                    n,
                    Some(n),
                    "system.a",
                    "N",
                    &params,
                    t0,
                    &mut exprs,
                    &mut errs,
                )
            };
            (a, None)
        }
        Form::Discrete => {
            if !sys.a.is_empty() {
                errs.at(
                    "system.a",
                    "a discrete model gives transition (Φ, N×N), not a: give one of them",
                );
            }
            let transition = match &sys.transition {
                None => {
                    errs.at(
                        "system.transition",
                        "missing: give transition (Φ, N×N: x_k = Φ x_{k−1} + u + b F)",
                    );
                    None
                }
                Some(m) => Some(const_matrix(m, n, "system.transition", &params, &mut errs)),
            };
            (TimeMatrix::constant(n, n, vec![0.0; n * n]), transition)
        }
    };
    let u = match &sys.u {
        Some(u) => time_vector(u, n, "system.u", "N", &params, t0, &mut exprs, &mut errs),
        None => TimeMatrix::constant(n, 1, vec![0.0; n]),
    };
    // b: N rows, L columns (L from the first row).
    let l = sys.b.first().map(|r| r.len()).unwrap_or(0);
    if sys.b.len() == n && l == 0 {
        errs.at("system.b[0]", "b needs at least one column (L ≥ 1)");
    }
    let b = time_matrix(
        &sys.b,
        n,
        Some(l.max(1)),
        "system.b",
        "N",
        &params,
        t0,
        &mut exprs,
        &mut errs,
    );
    let y0 = const_vector(
        sys.y0.as_deref(),
        n,
        "system.y0",
        "N",
        &params,
        &mut errs,
        false,
    );
    let eta0 = const_vector(
        sys.eta0.as_deref(),
        n,
        "system.eta0",
        "N",
        &params,
        &mut errs,
        true,
    );
    let (w, phi) = noise_cov(
        sys.phi.as_deref(),
        sys.w.as_deref(),
        l.max(1),
        ("system.phi", "system.W", "L"),
        &params,
        &mut errs,
    );

    // --- measurement
    let meas = &model.measurement;
    let nm = meas.names.len();
    if nm == 0 {
        errs.at("measurement.names", "at least one measurement is needed");
    } else if nm > n {
        errs.at(
            "measurement.names",
            format!("{nm} measurements but only {n} states: kea needs n ≤ N"),
        );
    }
    check_names(&meas.names, "measurement.names", &mut errs);
    let mut c = vec![0.0; nm * n];
    check_shape(&meas.c, nm, Some(n), "measurement.c", "n", "N", &mut errs);
    for (i, row) in meas.c.iter().enumerate().take(nm) {
        for (j, v) in row.iter().enumerate().take(n) {
            let path = format!("measurement.c[{i}][{j}]");
            match compile_const(v, &params, &path) {
                Ok(x) => c[i * n + j] = x,
                Err(e) => errs.push(e),
            }
        }
    }
    let noise = match (&meas.gamma, &meas.g) {
        (Some(_), Some(_)) => {
            errs.at(
                "measurement.g",
                "give either gamma (n×M) or g (N×M, the seed's form), not both",
            );
            None
        }
        (None, None) => {
            errs.at(
                "measurement.gamma",
                "missing: give gamma (n×M) or g (N×M, the seed's form)",
            );
            None
        }
        (Some(gm), None) => {
            let mcols = gm.first().map(|r| r.len()).unwrap_or(0);
            if mcols == 0 && gm.len() == nm {
                // (Only this: the shape check would add "0 entries, expected 1".)
                errs.at(
                    "measurement.gamma[0]",
                    "gamma needs at least one column (M ≥ 1)",
                );
                None
            } else {
                Some(MeasurementNoise::Gamma(time_matrix(
                    gm,
                    nm,
                    Some(mcols.max(1)),
                    "measurement.gamma",
                    "n",
                    &params,
                    t0,
                    &mut exprs,
                    &mut errs,
                )))
            }
        }
        (None, Some(g)) => {
            let mcols = g.first().map(|r| r.len()).unwrap_or(0);
            if mcols == 0 && g.len() == n {
                errs.at("measurement.g[0]", "g needs at least one column (M ≥ 1)");
                None
            } else {
                Some(MeasurementNoise::SeedG(time_matrix(
                    g,
                    n,
                    Some(mcols.max(1)),
                    "measurement.g",
                    "N",
                    &params,
                    t0,
                    &mut exprs,
                    &mut errs,
                )))
            }
        }
    };
    let m_sources = noise.as_ref().map(|x| x.sources()).unwrap_or(1);
    let (v, psi) = noise_cov(
        meas.psi.as_deref(),
        meas.v.as_deref(),
        m_sources,
        ("measurement.psi", "measurement.V", "M"),
        &params,
        &mut errs,
    );
    if let Some(noise) = &noise {
        blind_measurements(&c, noise, &v, &meas.names, n, &mut errs, &mut notes);
    }

    let schedule = meas
        .schedule
        .as_ref()
        .and_then(|s| crate::model::schedule::compile(s, nm, &params, t0, &mut exprs, &mut errs.0));

    // --- pairs (METHOD §1.1)
    let mut pair_of_state: Vec<Option<usize>> = vec![None; n];
    match &meas.pairs {
        Some(pairs) => {
            let mut used_m = vec![false; nm];
            for (k, p) in pairs.iter().enumerate() {
                let si = sys.states.iter().position(|s| *s == p.state);
                let mi = meas.names.iter().position(|s| *s == p.measurement);
                match (si, mi) {
                    (None, _) => errs.at(
                        &format!("measurement.pairs[{k}].state"),
                        format!(
                            "no state named \"{}\" (states: {})",
                            p.state,
                            sys.states.join(", ")
                        ),
                    ),
                    (_, None) => errs.at(
                        &format!("measurement.pairs[{k}].measurement"),
                        format!(
                            "no measurement named \"{}\" (measurements: {})",
                            p.measurement,
                            meas.names.join(", ")
                        ),
                    ),
                    (Some(si), Some(mi)) => {
                        if pair_of_state[si].is_some() {
                            errs.at(
                                &format!("measurement.pairs[{k}].state"),
                                format!("state \"{}\" is paired twice", p.state),
                            );
                        } else if used_m[mi] {
                            errs.at(
                                &format!("measurement.pairs[{k}].measurement"),
                                format!("measurement \"{}\" is paired twice", p.measurement),
                            );
                        } else if c.get(mi * n + si) == Some(&0.0) {
                            // (ZX and YZ compare a state with a measurement of it.)
                            errs.at(
                                &format!("measurement.pairs[{k}]"),
                                format!(
                                    "measurement \"{}\" does not measure state \"{}\" (its entry of c is 0); pair a state with a measurement of it",
                                    p.measurement, p.state
                                ),
                            );
                        } else {
                            pair_of_state[si] = Some(mi);
                            used_m[mi] = true;
                        }
                    }
                }
            }
        }
        None => {
            // Row j of C with a single non-zero entry, in column i, pairs state i with j.
            for j in 0..nm {
                let nz: Vec<usize> = (0..n).filter(|&i| c[j * n + i] != 0.0).collect();
                if nz.len() == 1 && pair_of_state[nz[0]].is_none() {
                    pair_of_state[nz[0]] = Some(j);
                }
            }
        }
    }

    // --- criteria
    let cr = &model.criteria;
    if !(cr.confidence > 0.0 && cr.confidence < 1.0) {
        errs.at(
            "criteria.confidence",
            format!(
                "expected a probability strictly between 0 and 1, got {}",
                num(cr.confidence)
            ),
        );
    }
    let paired: Vec<bool> = pair_of_state.iter().map(|p| p.is_some()).collect();
    let weights_yz = weights(
        cr.weights.yz.as_deref(),
        n,
        Some(&paired),
        "criteria.weights.yz",
        &sys.states,
        &mut errs,
    );
    let weights_zx = weights(
        cr.weights.zx.as_deref(),
        n,
        Some(&paired),
        "criteria.weights.zx",
        &sys.states,
        &mut errs,
    );
    let weights_yx = weights(
        cr.weights.yx.as_deref(),
        n,
        None,
        "criteria.weights.yx",
        &sys.states,
        &mut errs,
    );

    // --- options
    let op = &model.options;
    // The result's series (`traces.states[i]`, and t): 13 for a paired state, 8 for
    // one without a measurement (no ζ, σ_Z, rel_z, local YZ or ZX).
    let n_paired = paired.iter().filter(|&&p| p).count();
    let series = 1 + 13 * n_paired + 8 * (n - n_paired);
    let max_rows = max_trace_rows(series);
    if op.trace_points == 1 || op.trace_points > max_rows {
        let why = if max_rows < MAX_TRACE_POINTS {
            format!(
                " (the traces hold {series} series — t, 13 for each of the {n_paired} paired states, 8 for each of the other {} — and at most {MAX_TRACE_VALUES} values in all)",
                n - n_paired
            )
        } else {
            String::new()
        };
        errs.at(
            "options.trace_points",
            format!(
                "expected 0 (no traces) or 2 to {max_rows}, got {}{why}",
                op.trace_points
            ),
        );
    }

    if !errs.0.is_empty() {
        return Err(errs.into_error());
    }
    Ok(CompiledModel {
        states: sys.states.clone(),
        measurements: meas.names.clone(),
        t0,
        t_end: t.t_end,
        steps,
        a,
        transition,
        prior_at: sys.prior_at.unwrap_or_default(),
        u,
        b,
        c,
        noise: noise.expect("checked above"),
        y0,
        eta0,
        w,
        phi,
        v,
        psi,
        schedule,
        pair_of_state,
        weights_yz,
        weights_zx,
        weights_yx,
        confidence: cr.confidence,
        trace_points: op.trace_points,
        steady_state_shortcut: op.steady_state_shortcut,
        notes,
        param_dependence: crate::model::params::ParamDependence::of(model),
    })
}
