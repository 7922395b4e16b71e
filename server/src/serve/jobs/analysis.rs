//! The `analysis` job kind: `{model, set?}` → the core's analysis result (METHOD §1.2–§1.6).

use super::{JobKind, JobOutput, PreparedJob, Work, cost};
use crate::serve::request;
use kea_core::validate::CompiledModel;
use kea_core::{Error, Model, Overrides, Progress};
use serde_json::Value;
use std::time::Instant;

pub struct Analysis;

/// The members an analysis request may have (`model_id` is resolved to `model`
/// before a kind sees the request).
pub const MEMBERS: &[&str] = &["model", "model_id", "set"];

impl JobKind for Analysis {
    fn name(&self) -> &'static str {
        "analysis"
    }

    fn prepare(&self, request: &Value) -> Result<Box<dyn PreparedJob>, Error> {
        let Value::Object(obj) = request else {
            return Err(Error::invalid("", "expected a JSON object"));
        };
        let mut errors = request::unknown_members(obj, MEMBERS);
        let (model, set) = request::model_and_set(obj, &mut errors);
        let Some(model) = model.filter(|_| errors.is_empty()) else {
            return Err(Error::Invalid(errors));
        };
        let work = work(&model, &set).map_err(request::locate)?;
        Ok(Box::new(Prepared { model, set, work }))
    }
}

/// The work of analysing `model` with `set`: the estimate the server's limits and the
/// command line's `--max-work` compare (paths relative to the request). Validates the
/// model.
pub fn work(model: &Model, set: &Overrides) -> Result<Work, Error> {
    let compiled = request::compile(model, set)?;
    Ok(work_of(&compiled, Some(model)))
}

/// The work of analysing a compiled model (`model`: its expressions' texts): the
/// core's estimate, [`cost::analysis_work`].
pub fn work_of(compiled: &CompiledModel, model: Option<&Model>) -> Work {
    cost::analysis_work(compiled, model)
}

struct Prepared {
    model: Model,
    set: Overrides,
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
        // The step loop's state is kept in the job's memo as it goes: a run after a
        // restart goes on from the last one kept (kea_core::resume).
        let compiled = request::compile(&self.model, &self.set)?;
        let mut result = kea_core::analysis::run_resumable(&compiled, progress, memo)
            .map_err(request::locate)?;
        result.timing.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        let result_json = serde_json::to_string(&result)
            .map_err(|e| Error::invalid("", format!("result not serialisable: {e}")))?;
        Ok(JobOutput {
            result_json,
            traces_csv: Some(kea_core::report::traces_csv(&result)),
        })
    }
}
