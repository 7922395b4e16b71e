//! The `simulation` job kind: `{model, set?, runs, seed?, truth?, model_error?,
//! trace_points?}` → the core's Monte Carlo result (METHOD §1.8).

use super::{JobKind, JobOutput, PreparedJob, Work, cost};
use crate::parallel::Rayon;
use crate::serve::request;
use kea_core::simulation::{ModelError, SimulationRequest, Truth};
use kea_core::validate::CompiledModel;
use kea_core::{Error, FieldError, Model, Overrides, Progress};
use serde_json::Value;

use std::time::Instant;

pub struct Simulation;

/// The members a simulation request may have (`model_id` is resolved to `model`).
pub const MEMBERS: &[&str] = &[
    "model",
    "model_id",
    "set",
    "runs",
    "seed",
    "truth",
    "model_error",
    "trace_points",
];

impl JobKind for Simulation {
    fn name(&self) -> &'static str {
        "simulation"
    }

    fn prepare(&self, request: &Value) -> Result<Box<dyn PreparedJob>, Error> {
        let Value::Object(obj) = request else {
            return Err(Error::invalid("", "expected a JSON object"));
        };
        let mut errors = request::unknown_members(obj, MEMBERS);
        let (model, set) = request::model_and_set(obj, &mut errors);
        // The simulation's own members, each checked at its own path.
        let mut sim = SimulationRequest::new(0, kea_core::simulation::DEFAULT_SEED);
        let whole = |name: &str, what: &str, errors: &mut Vec<FieldError>| {
            let v = obj.get(name)?;
            let n = kea_core::json::whole_u64(v);
            if n.is_none() {
                errors.push(FieldError::new(
                    name,
                    format!("expected {what}, got {}", request::got(v)),
                ));
            }
            n
        };
        match whole(
            "runs",
            "a whole number of runs, at least 2 (e.g. 1000)",
            &mut errors,
        ) {
            Some(r) => sim.runs = r,
            None if !obj.contains_key("runs") => errors.push(FieldError::new(
                "runs",
                "missing: the number of runs R (e.g. 1000)",
            )),
            None => {}
        }
        if let Some(x) = whole(
            "seed",
            "a whole number ≥ 0 (the random streams' seed)",
            &mut errors,
        ) {
            sim.seed = x;
        }
        let choice = |name: &str, choices: &[(&str, &str)], errors: &mut Vec<FieldError>| {
            let v = obj.get(name)?;
            let found = v
                .as_str()
                .and_then(|s| choices.iter().position(|(c, _)| *c == s));
            if found.is_none() {
                let list: Vec<String> = choices
                    .iter()
                    .map(|(c, what)| format!("\"{c}\" ({what})"))
                    .collect();
                errors.push(FieldError::new(
                    name,
                    format!("expected {}, got {}", list.join(" or "), request::got(v)),
                ));
            }
            found
        };
        match choice(
            "truth",
            &[
                ("process", "the imitated process Y, the Kalman reading"),
                ("mean", "the mean y, seed 000's reading"),
            ],
            &mut errors,
        ) {
            Some(0) => sim.truth = Truth::Process,
            Some(_) => sim.truth = Truth::Mean,
            None => {}
        }
        match choice(
            "model_error",
            &[
                ("white", "F drawn at every step"),
                ("constant", "F drawn once per run"),
            ],
            &mut errors,
        ) {
            Some(0) => sim.model_error = ModelError::White,
            Some(_) => sim.model_error = ModelError::Constant,
            None => {}
        }
        if let Some(x) = whole(
            "trace_points",
            "a whole number of trace rows (≥ 2)",
            &mut errors,
        ) {
            sim.trace_points = Some(usize::try_from(x).unwrap_or(usize::MAX));
        }
        let sim = Some(sim);
        let (Some(model), Some(sim)) = (model, sim) else {
            return Err(Error::Invalid(errors));
        };
        if !errors.is_empty() {
            return Err(Error::Invalid(errors));
        }
        let compiled = request::compile(&model, &set).map_err(request::locate)?;
        kea_core::simulation::check_request(&sim, &compiled)?;
        let work = work_of(&compiled, Some(&model), &sim);
        Ok(Box::new(Prepared {
            model,
            set,
            work,
            sim,
        }))
    }
}

/// The work of `sim` on a compiled model (`model`: its expressions' texts): the
/// core's estimate, [`cost::simulation_work`].
pub fn work_of(compiled: &CompiledModel, model: Option<&Model>, sim: &SimulationRequest) -> Work {
    cost::simulation_work(compiled, model, sim)
}

struct Prepared {
    model: Model,
    set: Overrides,
    sim: SimulationRequest,
    work: Work,
}

impl PreparedJob for Prepared {
    fn work(&self) -> Work {
        self.work.clone()
    }

    fn run(
        self: Box<Self>,
        progress: &mut dyn Progress,
        _stop: &(dyn Fn() -> bool + Sync),
        memo: &dyn kea_core::exec::Memo,
    ) -> Result<JobOutput, Error> {
        let start = Instant::now();
        let exec = Rayon::new(None).map_err(|e| Error::invalid("", e))?;
        // The analysis's and the runs' states are kept in the job's memo as they go: a
        // run after a restart goes on from the last ones kept (kea_core::resume).
        let mut result = kea_core::simulation::simulate_resumable(
            &self.model,
            &self.set,
            &self.sim,
            &exec,
            progress,
            memo,
        )
        .map_err(request::locate)?;
        result.timing.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        let result_json = serde_json::to_string(&result)
            .map_err(|e| Error::invalid("", format!("result not serialisable: {e}")))?;
        Ok(JobOutput {
            result_json,
            traces_csv: Some(kea_core::simulation::traces_csv(&result)),
        })
    }
}
