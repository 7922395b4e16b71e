//! The `simulation` job kind: `{model, set?, runs, seed?, truth?, model_error?,
//! trace_points?}` → the core's Monte Carlo result (METHOD §1.8).

use super::{JobKind, JobOutput, PreparedJob, Work, cost};
use crate::parallel::Rayon;
use crate::serve::request;
use kea_core::simulation::SimulationRequest;
use kea_core::validate::CompiledModel;
use kea_core::{Error, FieldError, Model, Overrides, Progress};
use serde_json::{Map, Value};

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
        // The simulation's own members, each parsed at its own path.
        let mut sim = SimulationRequest::new(0, 0);
        fn member<T: serde::de::DeserializeOwned>(
            obj: &Map<String, Value>,
            name: &str,
            errors: &mut Vec<FieldError>,
        ) -> Option<T> {
            let v = obj.get(name)?;
            match serde_json::from_value(v.clone()) {
                Ok(x) => Some(x),
                Err(e) => {
                    errors.push(FieldError::new(name, e.to_string()));
                    None
                }
            }
        }
        match member::<u64>(obj, "runs", &mut errors) {
            Some(r) => sim.runs = r,
            None if !obj.contains_key("runs") => errors.push(FieldError::new(
                "runs",
                "missing: the number of runs R (e.g. 1000)",
            )),
            None => {}
        }
        if let Some(x) = member(obj, "seed", &mut errors) {
            sim.seed = x;
        }
        if let Some(x) = member(obj, "truth", &mut errors) {
            sim.truth = x;
        }
        if let Some(x) = member(obj, "model_error", &mut errors) {
            sim.model_error = x;
        }
        if let Some(x) = member(obj, "trace_points", &mut errors) {
            sim.trace_points = Some(x);
        }
        let sim = Some(sim);
        let (Some(model), Some(sim)) = (model, sim) else {
            return Err(Error::Invalid(errors));
        };
        if !errors.is_empty() {
            return Err(Error::Invalid(errors));
        }
        let compiled = kea_core::validate::compile(&model, &set).map_err(request::locate)?;
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

/// The work of `sim` on a compiled model, each time-dependent entry counted as a
/// distinct expression (see [`work_of`], which reads their texts from the model).
pub fn work(compiled: &CompiledModel, sim: &SimulationRequest) -> Work {
    work_of(compiled, None, sim)
}

/// The work of `sim` on a compiled model (`model`: its expressions' texts): the
/// analysis it starts with, then per step the plan (the inputs and a dense Riccati
/// step, [`cost::simulation_plan_step`]) and every run's step
/// ([`cost::simulation_run_step`]).
pub fn work_of(compiled: &CompiledModel, model: Option<&Model>, sim: &SimulationRequest) -> Work {
    let analysis = super::analysis::work_of(compiled, model);
    let steps = compiled.max_steps();
    let plan = cost::simulation_plan_step(compiled, model);
    let run = cost::simulation_run_step(compiled, sim.model_error);
    let per_run_once = cost::simulation_run_start(compiled, sim.model_error);
    let runs = sim.runs as f64;
    Work {
        units: analysis.units + steps as f64 * (plan + runs * run) + runs * per_run_once,
        explain: format!(
            "the analysis {:.3e} + D = {steps} steps × (the plan {plan:.0} + runs R = {} × {run:.0} per run)",
            analysis.units, sim.runs
        ),
        path: "runs".into(),
    }
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

    fn run(self: Box<Self>, progress: &mut dyn Progress) -> Result<JobOutput, Error> {
        let start = Instant::now();
        let exec = Rayon::new(None).map_err(|e| Error::invalid("", e))?;
        let mut result =
            kea_core::simulation::simulate(&self.model, &self.set, &self.sim, &exec, progress)
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
