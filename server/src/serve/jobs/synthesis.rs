//! The `synthesis` job kind: `{model, set?, target, mode}` → the error levels that
//! reach a desired filtering effect (METHOD §1.7), its points on every core.

use super::{JobKind, JobOutput, PreparedJob, Work};
use crate::parallel::Rayon;
use kea_core::synthesis::{self, SynthesisRequest};
use kea_core::{Error, Progress};
use serde_json::Value;
use std::time::Instant;

pub struct Synthesis;

impl JobKind for Synthesis {
    fn name(&self) -> &'static str {
        "synthesis"
    }

    fn prepare(&self, request: &Value) -> Result<Box<dyn PreparedJob>, Error> {
        if !request.is_object() {
            return Err(Error::invalid("", "expected a JSON object"));
        }
        // `model_id` was resolved to `model` before a kind sees the request.
        let request = synthesis::request_from_value(request.clone())?;
        synthesis::validate(&request)?;
        let work = work(&request).map_err(crate::serve::request::locate)?;
        Ok(Box::new(Prepared { work, request }))
    }
}

/// The work of a synthesis: at most its planned analyses, each the analysis' estimate.
pub fn work(request: &SynthesisRequest) -> Result<Work, Error> {
    let analyses = synthesis::planned_analyses(request);
    let compiled = kea_core::validate::compile(&request.model, &request.set)?;
    let one = super::analysis::work_of(&compiled, Some(&request.model));
    Ok(Work {
        units: one.units * analyses as f64,
        explain: format!("at most {analyses} analyses × {}", one.explain),
        path: "mode".into(),
    })
}

struct Prepared {
    request: SynthesisRequest,
    work: Work,
}

impl PreparedJob for Prepared {
    fn work(&self) -> Work {
        self.work.clone()
    }

    fn run(self: Box<Self>, progress: &mut dyn Progress) -> Result<JobOutput, Error> {
        let exec = Rayon::new(None).map_err(|e| Error::invalid("", e))?;
        let start = Instant::now();
        let mut result = synthesis::synthesize(&self.request, &exec, progress)?;
        result.timing.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        let result_json = serde_json::to_string(&result)
            .map_err(|e| Error::invalid("", format!("result not serialisable: {e}")))?;
        Ok(JobOutput {
            result_json,
            traces_csv: None,
        })
    }
}
