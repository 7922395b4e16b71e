//! The analysis as a kind of run ([`crate::kind`]): `{model, set?, budget?}` → the
//! analysis result (METHOD §1.2–§1.6), with its error budget when asked
//! ([`super::budget`]).

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
    /// Also the error budget (`"budget": true`; default false).
    pub budget: bool,
    /// A mismatched filter's truth (`"truth": {...}`), compiled.
    pub truth: Option<Box<CompiledModel>>,
    /// The truth is a model of its own (`truth.model`), not the model with `truth.set`.
    pub truth_is_model: bool,
}

impl Kind for Analysis {
    const NAME: &'static str = "analysis";
    const ALIASES: &'static [&'static str] = &[];
    const MEMBERS: &'static [&'static str] = &["model", "model_id", "set", "budget", "truth"];
    type Request = Request;
    type Outcome = AnalysisResult;

    fn prepare(obj: Map<String, Value>) -> Result<Request, Error> {
        let mut errors = request::unknown_members(&obj, Self::MEMBERS);
        let (model, set) = request::model_and_set(&obj, &mut errors);
        let budget = request::flag(&obj, "budget", &mut errors).unwrap_or(false);
        let truth = super::mismatch::from_request(&obj, &mut errors);
        let Some(model) = model.filter(|_| errors.is_empty()) else {
            return Err(Error::Invalid(errors));
        };
        let compiled = request::compile(&model, &set).map_err(request::locate)?;
        let truth_is_model = truth.as_ref().is_some_and(|t| t.model.is_some());
        let truth = truth
            .map(|t| super::mismatch::compile(&t, &model, &set, &compiled).map(Box::new))
            .transpose()?;
        Ok(Request {
            model,
            compiled,
            budget,
            truth,
            truth_is_model,
        })
    }

    fn work(r: &Request) -> Work {
        let mut work = super::work::analysis_work(&r.compiled, Some(&r.model));
        if r.budget {
            let (units, explain) = super::budget::work(&r.compiled);
            work.units += units;
            work.explain += &format!(" + the budget {explain}");
        }
        if let Some(t) = &r.truth {
            let (units, explain) = super::mismatch::work(&r.compiled, t);
            work.units += units;
            work.explain += &format!(" + the mismatch {explain}");
        }
        work
    }

    fn run<E: Executor>(
        r: &Request,
        _exec: &E,
        progress: &mut dyn Progress,
        memo: &dyn Memo,
    ) -> Result<AnalysisResult, Error> {
        // The step loop's state is kept in the memo as it goes: a run after a restart
        // goes on from the last one kept (crate::resume). The budget's pass and the
        // mismatch's run after it (from the start again after a restart), progress
        // split by their work.
        let analysis = super::work::analysis_work(&r.compiled, Some(&r.model)).units;
        let budget = r.budget.then(|| super::budget::work(&r.compiled).0);
        let mismatch = r
            .truth
            .as_ref()
            .map(|t| super::mismatch::work(&r.compiled, t).0);
        let total = analysis + budget.unwrap_or(0.0) + mismatch.unwrap_or(0.0);
        let mut first = |f: f64| progress.report(analysis * f / total);
        let mut result =
            super::run_resumable(&r.compiled, &mut first, memo).map_err(request::locate)?;
        let mut done = analysis;
        if let Some(units) = budget {
            let frozen_at = result
                .steady_state
                .as_ref()
                .filter(|s| s.shortcut_used)
                .map(|s| s.reached_at_step);
            let mut report = |f: f64| progress.report((done + units * f) / total);
            let b = super::budget::run(&r.compiled, result.steps, frozen_at, &mut report)?;
            result.budget = Some(b);
            done += units;
        }
        if let (Some(truth), Some(units)) = (&r.truth, mismatch) {
            // The truth on the design's steps (an "auto" selection made once).
            let mut truth = CompiledModel::clone(truth);
            truth.steps = crate::model::compile::StepPlan::Fixed(result.steps);
            let half = units / 2.0;
            let mut report = |f: f64| progress.report((done + half * f) / total);
            let place = |e| super::mismatch::place_in(e, r.truth_is_model);
            let optimal = super::run(&truth, &mut report).map_err(place)?;
            let mut report = |f: f64| progress.report((done + half + half * f) / total);
            let m =
                super::mismatch::run(&r.compiled, &result, &truth, &optimal, place, &mut report)?;
            result.criteria.actual = Some(m.1);
            result.mismatch = Some(Box::new(m.0));
        }
        Ok(result)
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
