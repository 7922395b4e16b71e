//! Synthesis (METHOD §1.7, (3.27)): the error levels that reach a desired filtering
//! effect, e.g. F_YX ≥ F*_YX. Three modes, each built on repeated analyses
//! ([`crate::analysis::analyze`]) with parameter overrides:
//!
//! - `seed_search` — the seed's section-4 procedure, faithfully: nested loops over the
//!   params from their upper bounds, multiplying by shrink factors < 1, stopping at the
//!   first point that meets the target (or reporting failure with the seed's advice);
//! - `bisect` — the boundary value of one param (the loosest one that still meets the
//!   target) by bisection on a log scale, with a monotonicity check;
//! - `grid` — criteria tables over up to three params (the seed's Table 2), cells that
//!   meet the target marked, and the cheapest qualifying cell under a cost order.
//!
//! Every answer is verified by a fresh analysis. The points of a batch run through an
//! [`Executor`], so adapters may run them in parallel; every answer (and the number of
//! analyses) is independent of the number of threads. The core has no clock: it
//! counts analyses, the adapters fill `timing.wall_ms`.

use crate::analysis::result::{AnalysisResult, Timing};
use crate::error::Error;
use crate::exec::{Executor, Forgetful, Memo};
use crate::model::Model;
use crate::model::Overrides;
use crate::progress::Progress;
use serde::{Deserialize, Serialize};
use std::ops::ControlFlow;

pub mod kind;
mod modes;
mod report;
mod request;
mod result;
pub mod work;

pub use modes::{LOOSER_FACTOR, first_meeting};
use modes::{bisect, grid, seed_search};
use report::describe;
pub use report::render_text;
pub use request::{
    Bisect, Cheaper, CostKey, CriteriaSetName, Criterion, Grid, GridParam, HINTS, MAX_GRID_PARAMS,
    MAX_POINTS, Mode, RangeParam, SeedSearch, SynthesisRequest, Target, levels, planned_analyses,
    request_from_json, request_from_value, seed_order, validate, validated,
};
pub use result::{
    BisectOut, Details, GridCell, GridOut, Point, SeedSearchOut, Side, Status, SynthesisResult,
    Verification,
};

// ---------------------------------------------------------------- evaluation

/// One analysis's outcome as a synthesis uses it, the form a [`Memo`] keeps.
#[derive(Serialize, Deserialize)]
struct Outcome {
    point: Point,
    steps: u64,
    warnings: Vec<String>,
}

/// A point's memo key: each param's name and its value's bits (`q=3fb999999999999a`),
/// in the order the search gives them.
fn memo_key(params: &[(String, f64)]) -> String {
    let parts: Vec<String> = params
        .iter()
        .map(|(k, v)| format!("{k}={:016x}", v.to_bits()))
        .collect();
    parts.join(",")
}

struct Ctx<'a> {
    model: &'a Model,
    memo: &'a dyn Memo,
    /// Analyses taken from `memo` (counted from every thread of a batch).
    recalled: std::sync::atomic::AtomicU64,
    /// The keys this run kept: a point it visits again (the verification's) runs again,
    /// as without a memo, so that `recalled_analyses` counts only an earlier run's.
    kept_here: std::sync::Mutex<std::collections::HashSet<String>>,
    set: &'a Overrides,
    target: &'a Target,
    state_index: Option<usize>,
    /// Planned analyses (for the progress fraction) and analyses done.
    total: u64,
    done: u64,
    steps: u64,
    /// The work estimate of one analysis ([`crate::work`]), which sizes the parts of
    /// a batch between progress reports.
    analysis_work: f64,
}

/// The work (units of [`crate::work`]) a batch's part gives each thread between two
/// progress reports: as a Monte Carlo chunk's, ≈ 17 ms of one core.
const PART_WORK: f64 = crate::progress::WORK_BETWEEN_PARTS;

/// Points of a batch analysed between two progress reports: `threads` points
/// (one each) at least, more while each thread's share stays within [`PART_WORK`].
/// An analysis that runs beside others reports nothing, so a cancel is seen between
/// parts, or, where the executor can say so ([`Executor::stop_requested`]), by each
/// analysis within about a millisecond of its work.
fn part_points(analysis_work: f64, threads: usize) -> usize {
    let each = crate::work::fitting(PART_WORK, analysis_work, 1_000_000);
    threads.max(1).saturating_mul(each as usize)
}

impl Ctx<'_> {
    /// One analysis at `params` (on top of `set`). Pure: usable from any thread.
    fn eval(
        &self,
        params: &[(String, f64)],
        progress: &mut dyn Progress,
    ) -> Result<(Point, u64, Vec<String>), Error> {
        let key = memo_key(params);
        let earlier = || !self.kept_here.lock().is_ok_and(|k| k.contains(&key));
        if earlier()
            && let Some(kept) = self.memo.recall(&key)
            && let Ok(o) = serde_json::from_str::<Outcome>(&kept)
        {
            self.recalled
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            return Ok((o.point, o.steps, o.warnings));
        }
        let mut set = self.set.clone();
        for (k, v) in params {
            set.insert(k.clone(), *v);
        }
        let r = crate::analysis::analyze(self.model, &set, progress).map_err(|e| {
            let at = describe(params);
            crate::request::locate(e).map_messages(|m| format!("{m} (at {at})"))
        })?;
        // The warnings that concern the target's set: the bound set's own say nothing
        // of a covariance target's criteria.
        let point = self.point(params, &r);
        let mut warnings = r.warnings;
        if self.target.criteria == CriteriaSetName::Covariance {
            warnings.retain(|w| !crate::analysis::bound_set_only(w));
        }
        let outcome = Outcome {
            point,
            steps: r.steps,
            warnings,
        };
        if let Ok(json) = serde_json::to_string(&outcome) {
            self.memo.keep(&key, &json);
            if let Ok(mut k) = self.kept_here.lock() {
                k.insert(key);
            }
        }
        Ok((outcome.point, outcome.steps, outcome.warnings))
    }

    fn point(&self, params: &[(String, f64)], r: &AnalysisResult) -> Point {
        let set = match self.target.criteria {
            CriteriaSetName::Bound => &r.criteria.bound,
            CriteriaSetName::Covariance => &r.criteria.covariance,
        };
        let (yz, zx, yx, undefined) = match self.state_index {
            Some(i) => {
                let s = &set.per_state[i];
                (s.yz, s.zx, s.yx, &s.undefined)
            }
            None => {
                let w = &set.weighted;
                (w.yz, w.zx, w.yx, &w.undefined)
            }
        };
        let (value, key) = match self.target.criterion {
            Criterion::Yz => (yz, "yz"),
            Criterion::Zx => (zx, "zx"),
            Criterion::Yx => (yx, "yx"),
        };
        let note = if value.is_none() {
            Some(
                undefined
                    .get(key)
                    .cloned()
                    .unwrap_or_else(|| "the criterion is undefined".into()),
            )
        } else {
            None
        };
        Point {
            params: params.iter().cloned().collect(),
            yz,
            zx,
            yx,
            value,
            meets: value.is_some_and(|v| v >= self.target.threshold),
            note,
        }
    }

    /// Analyse a batch of points, in order. A single point runs on the calling thread
    /// with fine-grained progress; a larger batch goes to the executor in parts of
    /// about [`PART_WORK`] a thread ([`part_points`]), with progress and cancellation
    /// checked between parts.
    fn batch<E: Executor>(
        &mut self,
        exec: &E,
        points: Vec<Vec<(String, f64)>>,
        progress: &mut dyn Progress,
    ) -> Result<Vec<Point>, Error> {
        let out = self.batch_warned(exec, points, progress)?;
        Ok(out.into_iter().map(|(p, _)| p).collect())
    }

    /// [`Ctx::batch`], with each analysis's warnings.
    fn batch_warned<E: Executor>(
        &mut self,
        exec: &E,
        points: Vec<Vec<(String, f64)>>,
        progress: &mut dyn Progress,
    ) -> Result<Vec<(Point, Vec<String>)>, Error> {
        let n = points.len() as u64;
        let total = self.total.max(1) as f64;
        let results = if points.len() == 1 {
            let done = self.done as f64;
            let mut sub = |f: f64| progress.report(((done + f) / total).min(1.0));
            vec![self.eval(&points[0], &mut sub)]
        } else {
            // In parts, with a report (a chance to cancel) before each.
            let part = part_points(self.analysis_work, exec.threads());
            let mut results = Vec::with_capacity(points.len());
            let mut points = points.into_iter().peekable();
            while points.peek().is_some() {
                let done = self.done + results.len() as u64;
                if progress.report((done as f64 / total).min(1.0)).is_break() {
                    return Err(Error::Cancelled);
                }
                let this = &*self;
                let part: Vec<_> = points.by_ref().take(part).collect();
                let stop = |_: f64| match exec.stop_requested() {
                    true => ControlFlow::Break(()),
                    false => ControlFlow::Continue(()),
                };
                results.extend(exec.map(part, |p| this.eval(&p, &mut { stop })));
                if results.iter().any(|r| matches!(r, Err(Error::Cancelled))) {
                    // Stopped inside the part: the caller's progress says why.
                    let _ = progress.report((done as f64 / total).min(1.0));
                    return Err(Error::Cancelled);
                }
            }
            results
        };
        self.done += n;
        let mut out = Vec::with_capacity(results.len());
        for r in results {
            let (p, steps, warnings) = r?;
            self.steps = steps;
            out.push((p, warnings));
        }
        if let ControlFlow::Break(()) = progress.report((self.done as f64 / total).min(1.0)) {
            return Err(Error::Cancelled);
        }
        Ok(out)
    }
}

// ---------------------------------------------------------------- the modes

/// Run a synthesis request. Points of a batch go through `exec`; the answer does not
/// depend on its thread count.
pub fn synthesize<E: Executor>(
    req: &SynthesisRequest,
    exec: &E,
    progress: &mut dyn Progress,
) -> Result<SynthesisResult, Error> {
    synthesize_resuming(req, exec, progress, &Forgetful)
}

/// [`synthesize`], keeping each analysis in `memo` and taking those it already holds
/// (from an interrupted run of the same request) instead of running them again. The
/// result is the uninterrupted run's, but for `recalled_analyses` and the timing.
pub fn synthesize_resuming<E: Executor>(
    req: &SynthesisRequest,
    exec: &E,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
) -> Result<SynthesisResult, Error> {
    let compiled = validated(req)?;
    let analysis_work = crate::analysis::work::analysis_work(&compiled, Some(&req.model)).units;
    synthesize_validated(req, analysis_work, exec, progress, memo)
}

/// [`synthesize_resuming`] of a request [`validated`] already, whose one analysis has
/// the work estimate `analysis_work` (units of [`crate::work`]).
pub fn synthesize_validated<E: Executor>(
    req: &SynthesisRequest,
    analysis_work: f64,
    exec: &E,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
) -> Result<SynthesisResult, Error> {
    let state_index = req
        .target
        .state
        .as_ref()
        .and_then(|s| req.model.system.states.iter().position(|x| x == s));
    let mut ctx = Ctx {
        model: &req.model,
        memo,
        recalled: 0.into(),
        kept_here: Default::default(),
        set: &req.set,
        target: &req.target,
        state_index,
        total: planned_analyses(req),
        done: 0,
        steps: 0,
        analysis_work,
    };
    let (status, message, answer, verification, details) = match &req.mode {
        Mode::SeedSearch(s) => seed_search(&mut ctx, exec, s, progress)?,
        Mode::Bisect(b) => bisect(&mut ctx, exec, b, progress)?,
        Mode::Grid(g) => grid(&mut ctx, exec, g, progress)?,
    };
    Ok(SynthesisResult {
        target: req.target.clone(),
        status,
        message,
        answer,
        verification,
        details,
        analyses: ctx.done,
        recalled_analyses: ctx.recalled.into_inner(),
        steps: ctx.steps,
        timing: Timing::default(),
    })
}
