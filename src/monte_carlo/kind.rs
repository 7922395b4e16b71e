//! The Monte Carlo as a kind of run ([`crate::kind`]): `{model, set?, runs, seed?,
//! truth?, model_error?, trace_points?}` → the Monte Carlo result (METHOD §1.8).
//! `truth` is what the filter is compared with — `"process"` (the default) or
//! `"mean"` — or a mismatched filter's truth, `{"set": {…}}` or `{"model": {…}}` as in
//! an analysis ([`crate::analysis::mismatch`]): the runs then imitate the truth's
//! process and the filter stays designed on the model.

use super::{DEFAULT_SEED, ModelError, MonteCarloRequest, MonteCarloResult, Truth};
use crate::analysis::result::Timing;
use crate::error::{Error, FieldError};
use crate::exec::{Executor, Memo};
use crate::kind::Kind;
use crate::model::CompiledModel;
use crate::model::Model;
use crate::progress::Progress;
use crate::request;
use crate::work::Work;
use serde_json::{Map, Value};

/// The Monte Carlo kind (its name in requests: `monte_carlo`; `simulation`, its former
/// name, is still read as it: stored jobs and older scripts).
pub struct MonteCarlo;

/// A Monte Carlo request, compiled.
pub struct Request {
    pub model: Model,
    pub compiled: CompiledModel,
    pub monte_carlo: MonteCarloRequest,
    /// A mismatched filter's truth (`"truth": {...}`), compiled, and whether it is a
    /// model of its own (`truth.model`).
    pub truth: Option<(Box<CompiledModel>, bool)>,
}

/// A Monte Carlo's outcome: the result (its JSON is the result's alone) and the
/// threads it ran on, which the text report names.
pub struct Outcome {
    pub result: MonteCarloResult,
    pub threads: usize,
}

impl serde::Serialize for Outcome {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.result.serialize(s)
    }
}

impl Kind for MonteCarlo {
    const NAME: &'static str = "monte_carlo";
    const ALIASES: &'static [&'static str] = &["simulation"];
    const MEMBERS: &'static [&'static str] = &[
        "model",
        "model_id",
        "set",
        "runs",
        "seed",
        "truth",
        "model_error",
        "trace_points",
    ];
    type Request = Request;
    type Outcome = Outcome;

    fn prepare(obj: Map<String, Value>) -> Result<Request, Error> {
        let mut errors = request::unknown_members(&obj, Self::MEMBERS);
        let (model, set) = request::model_and_set(&obj, &mut errors);
        let sim = read_members(&obj, &mut errors);
        let truth = obj
            .get("truth")
            .filter(|t| t.is_object())
            .and_then(|_| crate::analysis::mismatch::from_request(&obj, &mut errors));
        let Some(model) = model.filter(|_| errors.is_empty()) else {
            return Err(Error::Invalid(errors));
        };
        let compiled = request::compile(&model, &set).map_err(request::locate)?;
        let truth = match truth {
            Some(t) => {
                let is_model = t.model.is_some();
                let c = crate::analysis::mismatch::compile(&t, &model, &set, &compiled)?;
                Some((Box::new(c), is_model))
            }
            None => None,
        };
        Ok(Request {
            model,
            compiled,
            monte_carlo: sim,
            truth,
        })
    }

    fn check(r: &Request) -> Result<(), Error> {
        super::check_request(&r.monte_carlo, &r.compiled)
    }

    fn work(r: &Request) -> Work {
        let mut work = super::work::monte_carlo_work(&r.compiled, Some(&r.model), &r.monte_carlo);
        if r.truth.is_some() {
            let (units, explain) = super::work::truth_work(&r.compiled);
            work.units += units;
            work.explain += &format!(" + the truth {explain}");
        }
        work
    }

    fn run<E: Executor>(
        r: &Request,
        exec: &E,
        progress: &mut dyn Progress,
        memo: &dyn Memo,
    ) -> Result<Outcome, Error> {
        // The analysis's and the runs' states are kept in the memo as they go: a run
        // after a restart goes on from the last ones kept (crate::resume).
        let truth = r.truth.as_ref().map(|(t, is_model)| super::Mismatched {
            truth: t,
            truth_is_model: *is_model,
        });
        let result =
            super::simulate_compiled(&r.compiled, truth, &r.monte_carlo, exec, progress, memo)
                .map_err(request::locate)?;
        Ok(Outcome {
            result,
            threads: exec.threads(),
        })
    }

    fn timing(o: &mut Outcome) -> &mut Timing {
        &mut o.result.timing
    }

    fn text(o: &Outcome) -> String {
        super::report::text(&o.result, o.threads)
    }

    fn csv(o: &Outcome) -> Option<String> {
        Some(super::report::traces_csv(&o.result))
    }
}

/// The Monte Carlo's own members, each checked at its own path.
fn read_members(obj: &Map<String, Value>, errors: &mut Vec<FieldError>) -> MonteCarloRequest {
    let mut sim = MonteCarloRequest::new(0, DEFAULT_SEED);
    match request::whole(
        obj,
        "runs",
        "a whole number of runs, at least 2 (e.g. 1000)",
        errors,
    ) {
        Some(r) => sim.runs = r,
        None if !obj.contains_key("runs") => errors.push(FieldError::new(
            "runs",
            "missing: the number of runs R (e.g. 1000)",
        )),
        None => {}
    }
    if let Some(x) = request::whole(
        obj,
        "seed",
        "a whole number ≥ 0 (the random streams' seed)",
        errors,
    ) {
        sim.seed = x;
    }
    // (An object is a mismatched filter's truth, read beside.)
    if !obj.get("truth").is_some_and(Value::is_object) {
        match request::choice(
            obj,
            "truth",
            &[
                ("process", "the imitated process Y, the Kalman reading"),
                ("mean", "the mean y, seed 000's reading"),
            ],
            errors,
        ) {
            Some(0) => sim.truth = Truth::Process,
            Some(_) => sim.truth = Truth::Mean,
            None => {}
        }
    }
    match request::choice(
        obj,
        "model_error",
        &[
            ("white", "F drawn at every step"),
            ("constant", "F drawn once per run"),
        ],
        errors,
    ) {
        Some(0) => sim.model_error = ModelError::White,
        Some(_) => sim.model_error = ModelError::Constant,
        None => {}
    }
    if let Some(x) = request::whole(
        obj,
        "trace_points",
        "a whole number of trace rows (≥ 2)",
        errors,
    ) {
        sim.trace_points = Some(usize::try_from(x).unwrap_or(usize::MAX));
    }
    sim
}
