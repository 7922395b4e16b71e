//! The synthesis's work estimate: its planned analyses, each the analysis's.

use super::SynthesisRequest;
use crate::analysis::work::analysis_work;
use crate::error::Error;
use crate::work::Work;

/// The work of a synthesis: at most its planned analyses
/// ([`crate::synthesis::planned_analyses`]), each the analysis' estimate. Compiles the
/// model (its errors at the model's own paths).
pub fn synthesis_work(request: &SynthesisRequest) -> Result<Work, Error> {
    let compiled = crate::model::compile::compile(&request.model, &request.set)?;
    let one = analysis_work(&compiled, Some(&request.model));
    Ok(synthesis_work_of(request, &one))
}

/// [`synthesis_work`] of a request whose one analysis is estimated at `one`.
pub fn synthesis_work_of(request: &SynthesisRequest, one: &Work) -> Work {
    let analyses = crate::synthesis::planned_analyses(request);
    Work {
        units: one.units * analyses as f64,
        explain: format!("at most {analyses} analyses × {}", one.explain),
        path: "mode".into(),
    }
}
