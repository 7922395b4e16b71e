//! The mismatched filter (`"truth": {...}`): a filter designed on the model — its
//! gains from the model's Riccati recursion, what it *believes* — run in a world that
//! is the `truth`: the same model with some params replaced (`truth.set`), or a whole
//! second model of the same dimensions (`truth.model`). Its *actual* error covariance
//! ([`pass`]), the criteria computed from it (the `actual` set), and what the mismatch
//! costs against the filter designed on the truth (the truth's own analysis, its
//! potential accuracy: the `optimal`).

use crate::analysis::criteria::{Avg, SetSums, criteria_set};
use crate::analysis::result::{
    AnalysisResult, CriteriaSet, Mismatch, MismatchState, MismatchTrace, MismatchTraces,
};
use crate::error::{Error, FieldError, got};
use crate::model::compile::CompiledModel;
use crate::model::{Model, Overrides};
use crate::progress::Progress;
use serde_json::{Map, Value};

pub(crate) mod pass;

/// The truth, read from a request's `truth`.
#[derive(Clone, Debug)]
pub struct Truth {
    /// `truth.model`, or None: the request's model.
    pub model: Option<Model>,
    /// `truth.set`: overrides on top of the request's `set` (for the request's model)
    /// or of the truth model's own params.
    pub set: Overrides,
}

/// Read `truth` (an object with `set` and/or `model`); errors at `truth.…`.
pub fn read(v: &Value) -> Result<Truth, Vec<FieldError>> {
    let Some(obj) = v.as_object() else {
        return Err(vec![FieldError::new(
            "truth",
            format!(
                "expected an object such as {{\"set\": {{\"sv\": 1.0}}}} or {{\"model\": {{…}}}}, got {}",
                got(v)
            ),
        )]);
    };
    let mut errors: Vec<FieldError> = crate::request::unknown_members(obj, &["set", "model"])
        .into_iter()
        .map(|e| under("truth", e))
        .collect();
    if obj.is_empty() {
        errors.push(FieldError::new(
            "truth",
            "give `set` (params the truth has other values of) or `model` (a whole truth model)",
        ));
    }
    let set = match crate::request::overrides(obj.get("set")) {
        Ok(s) => s,
        Err(e) => {
            errors.extend(e.into_iter().map(|e| under("truth", e)));
            Overrides::new()
        }
    };
    let model = match obj.get("model") {
        None => None,
        Some(m) => match crate::model::model_from_value(m.clone()) {
            Ok(m) => Some(m),
            Err(e) => {
                errors.extend(e.with_prefix("truth.model").field_errors());
                None
            }
        },
    };
    if errors.is_empty() {
        Ok(Truth { model, set })
    } else {
        Err(errors)
    }
}

fn under(prefix: &str, e: FieldError) -> FieldError {
    Error::Invalid(vec![e])
        .with_prefix(prefix)
        .field_errors()
        .remove(0)
}

/// Compile the truth beside the design: its errors at `truth.model.…` / `truth.set.…`;
/// its dimensions must be the design's.
pub fn compile(
    truth: &Truth,
    design_model: &Model,
    design_set: &Overrides,
    design: &CompiledModel,
) -> Result<CompiledModel, Error> {
    let (model, set, prefix) = match &truth.model {
        Some(m) => (m, truth.set.clone(), "truth.model"),
        None => {
            let mut set = design_set.clone();
            set.extend(truth.set.iter().map(|(k, v)| (k.clone(), *v)));
            (design_model, set, "truth")
        }
    };
    let compiled = crate::model::compile(model, &set).map_err(|e| {
        let placed = e.field_errors().into_iter().map(|fe| {
            if fe.path == "set" || fe.path.starts_with("set.") {
                FieldError::new(format!("truth.{}", fe.path), fe.message)
            } else if truth.model.is_some() {
                FieldError::new(format!("{prefix}.{}", fe.path), fe.message)
            } else {
                let at = if fe.path.is_empty() {
                    "the model".into()
                } else {
                    fe.path
                };
                FieldError::new("truth.set", format!("with truth.set, {at}: {}", fe.message))
            }
        });
        Error::Invalid(placed.collect())
    })?;
    let mut errors = Vec::new();
    if compiled.n_states() != design.n_states() {
        errors.push(FieldError::new(
            "truth.model.system.states",
            format!(
                "the truth has {} states, the model {}: a mismatched filter needs the same states",
                compiled.n_states(),
                design.n_states()
            ),
        ));
    }
    if compiled.n_measurements() != design.n_measurements() {
        errors.push(FieldError::new(
            "truth.model.measurement.names",
            format!(
                "the truth has {} measurements, the model {}: a mismatched filter needs the same measurements",
                compiled.n_measurements(),
                design.n_measurements()
            ),
        ));
    }
    if compiled.t0 != design.t0 || compiled.t_end != design.t_end {
        errors.push(FieldError::new(
            "truth.model.time",
            "the truth's interval must be the model's (t0, t_end)",
        ));
    }
    if !errors.is_empty() {
        return Err(Error::Invalid(errors));
    }
    // Availability belongs to the world the filter sees: the model's schedule, for the
    // truth's own analysis too.
    let mut compiled = compiled;
    compiled.schedule = design.schedule.clone();
    Ok(compiled)
}

/// Place an error of the truth's run in the request: at `truth.model.…` for a truth
/// model; for the model with `truth.set`, at `truth.set` with the model's path in the
/// message.
pub fn place_in(e: Error, truth_model: bool) -> Error {
    match e {
        Error::Numerical {
            step,
            t,
            path,
            message,
        } => {
            let (path, message) = if truth_model {
                (format!("truth.model.{path}"), message)
            } else {
                (
                    "truth.set".into(),
                    format!("with truth.set, {path}: {message}"),
                )
            };
            Error::Numerical {
                step,
                t,
                path,
                message,
            }
        }
        e => e,
    }
}

/// Run the mismatch beside a finished design analysis `design_result`, given the
/// truth's own analysis (`truth_result`): the pass, and the criteria from the actual
/// SKOs (with the truth's open-loop and measured SKOs and its y_B, z_B) — the result's
/// `criteria.actual`, the fourth set beside `bound`, `covariance`, `monte_carlo`.
pub fn run(
    design: &CompiledModel,
    design_result: &AnalysisResult,
    truth: &CompiledModel,
    truth_result: &AnalysisResult,
    place: impl Fn(Error) -> Error,
    progress: &mut dyn Progress,
) -> Result<(Mismatch, CriteriaSet), Error> {
    let n = design.n_states();
    let steps = design_result.steps;
    // Trace points: the last step of every bucket, as many as the analysis's trace
    // points (none where it has none).
    let points = design.trace_points as u64;
    let bucket = if points == 0 {
        u64::MAX
    } else {
        steps.div_ceil(points).max(1)
    };
    let mut tr_t = Vec::new();
    let mut tr_actual = vec![Vec::new(); n];
    let mut tr_believed = vec![Vec::new(); n];
    let mut tr_optimal = vec![Vec::new(); n];
    let mut sums = SetSums {
        yz: vec![Avg::default(); n],
        zx: vec![Avg::default(); n],
        yx: vec![Avg::default(); n],
    };
    let (mut fin_var, mut fin_mean) = (vec![0.0; n], vec![0.0; n]);
    let every = crate::progress::steps_between_reports(50.0 * (2 * n * 2 * n * 2 * n) as f64);
    let (structural, same) = pass::run(design, truth, steps, place, |s| {
        for i in 0..n {
            let actual = s.err_var[i].max(0.0).sqrt();
            let open = s.open_var[i].max(0.0).sqrt();
            match truth.pair_of_state[i] {
                Some(j) if s.avail[j] => {
                    sums.yz[i].add(open, s.meas_sko[j]);
                    sums.zx[i].add(s.meas_sko[j], actual);
                }
                Some(_) => {
                    sums.yz[i].add(f64::NAN, 0.0);
                    sums.zx[i].add(f64::NAN, 0.0);
                }
                None => {}
            }
            sums.yx[i].add(open, actual);
        }
        if points > 0 && (s.k % bucket == 0 || s.k == steps) {
            tr_t.push(design.t0 + s.k as f64 * (design.t_end - design.t0) / steps as f64);
            for i in 0..n {
                tr_actual[i].push(s.err_var[i].max(0.0).sqrt());
                tr_believed[i].push(s.believed_var[i].max(0.0).sqrt());
                tr_optimal[i].push(s.optimal_var[i].max(0.0).sqrt());
            }
        }
        if s.k == steps {
            fin_var.copy_from_slice(s.err_var);
            fin_mean.copy_from_slice(s.err_mean);
        }
        if s.k % every == 0 && progress.report(s.k as f64 / steps as f64).is_break() {
            return Err(Error::Cancelled);
        }
        Ok(())
    })?;
    let actual = criteria_set(
        truth,
        &sums,
        &truth_result.y_max,
        &truth_result.z_max,
        "actual",
        [None, None, None],
    );
    let states = (0..n)
        .map(|i| {
            let believed_sko = design_result.final_.potential_sko[i];
            // A truth that is the model throughout: the actual error covariance is the
            // filter's own R_k, as the analysis computed it.
            let actual_sko = if same {
                believed_sko
            } else {
                fin_var[i].max(0.0).sqrt()
            };
            let optimal_sko = truth_result.final_.potential_sko[i];
            let ratio = |a: f64, b: f64| (b > 0.0).then(|| a / b);
            MismatchState {
                state: design.states[i].clone(),
                actual_sko,
                bias: fin_mean[i],
                believed_sko,
                optimal_sko,
                loss: ratio(actual_sko, optimal_sko),
                actual_over_believed: ratio(actual_sko, believed_sko),
            }
        })
        .collect();
    let traces = MismatchTraces {
        t: tr_t,
        states: (0..n)
            .map(|i| MismatchTrace {
                state: design.states[i].clone(),
                actual_sko: std::mem::take(&mut tr_actual[i]),
                believed_sko: std::mem::take(&mut tr_believed[i]),
                optimal_sko: std::mem::take(&mut tr_optimal[i]),
            })
            .collect(),
    };
    let mismatch = Mismatch {
        differs_in: if structural { "structure" } else { "noise" }.into(),
        states,
        optimal: truth_result.criteria.covariance.clone(),
        traces,
    };
    Ok((mismatch, actual))
}

/// The `truth` member of a request object, read, if present.
pub fn from_request(obj: &Map<String, Value>, errors: &mut Vec<FieldError>) -> Option<Truth> {
    let v = obj.get("truth")?;
    match read(v) {
        Ok(t) => Some(t),
        Err(e) => {
            errors.extend(e);
            None
        }
    }
}

/// The pass's step: two Riccati steps and the 2N-state covariance F S Fᵀ (2·(2N)³,
/// plain loops) with its noise terms.
pub fn pass_step(design: &CompiledModel) -> f64 {
    let (n, nm) = (design.n_states() as f64, design.n_measurements() as f64);
    let n2 = 2.0 * n;
    2.0 * n2 * n2 * n2
        + n2 * n2 * (n + nm)
        + 2.0 * crate::analysis::work::step_cost(design.n_states())
}

/// The mismatch's work: the truth's own analysis, and D × the pass's step
/// ([`pass_step`]). Its units and how they were computed.
pub fn work(design: &CompiledModel, truth: &CompiledModel) -> (f64, String) {
    use crate::analysis::work::analysis_work;
    let steps = design.max_steps();
    let optimal = analysis_work(truth, None).units;
    let step = pass_step(design);
    (
        optimal + steps as f64 * step,
        format!("the truth's analysis {optimal:.3e} + D = {steps} steps × {step:.0}"),
    )
}
