//! The analysis as a kind of run ([`crate::kind`]): `{model, set?}` → the analysis
//! result (METHOD §1.2–§1.6).

use super::result::{AnalysisResult, Timing};
use crate::error::Error;
use crate::exec::{Executor, Memo};
use crate::kind::Kind;
use crate::model::CompiledModel;
use crate::model::Model;
use crate::progress::Progress;
use crate::request;
use crate::work::Work;
use serde_json::{Map, Value};

/// The analysis kind.
pub struct Analysis;

/// An analysis request, compiled.
pub struct Request {
    pub model: Model,
    pub compiled: CompiledModel,
}

impl Kind for Analysis {
    const NAME: &'static str = "analysis";
    const ALIASES: &'static [&'static str] = &[];
    const MEMBERS: &'static [&'static str] = &["model", "model_id", "set"];
    type Request = Request;
    type Outcome = AnalysisResult;

    fn prepare(obj: Map<String, Value>) -> Result<Request, Error> {
        let mut errors = request::unknown_members(&obj, Self::MEMBERS);
        let (model, set) = request::model_and_set(&obj, &mut errors);
        let Some(model) = model.filter(|_| errors.is_empty()) else {
            return Err(Error::Invalid(errors));
        };
        let compiled = request::compile(&model, &set).map_err(request::locate)?;
        Ok(Request { model, compiled })
    }

    fn work(r: &Request) -> Work {
        super::work::analysis_work(&r.compiled, Some(&r.model))
    }

    fn run<E: Executor>(
        r: &Request,
        _exec: &E,
        progress: &mut dyn Progress,
        memo: &dyn Memo,
    ) -> Result<AnalysisResult, Error> {
        // The step loop's state is kept in the memo as it goes: a run after a restart
        // goes on from the last one kept (crate::resume).
        super::run_resumable(&r.compiled, progress, memo).map_err(request::locate)
    }

    fn timing(o: &mut AnalysisResult) -> &mut Timing {
        &mut o.timing
    }

    fn text(o: &AnalysisResult) -> String {
        super::report::criteria_table(o)
    }

    fn csv(o: &AnalysisResult) -> Option<String> {
        Some(super::report::traces_csv(o))
    }
}
