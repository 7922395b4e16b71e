//! Sensitivity: which param moves the filtering effect most — for each chosen param p
//! and each weighted criterion F (3.25) of both sets, the log-log derivative by central
//! differences on a log scale,
//!
//! ```text
//! S = d ln F / d ln p ≈ [ln F(p e^h) − ln F(p e^−h)] / 2h
//! ```
//!
//! (a 1 % change of p moves F by about S %), from 2 analyses per param beside the
//! base one. The error of the difference is h²/6 · d³ln F/d(ln p)³; the default
//! h = 10⁻³ keeps it near 10⁻⁷ while rounding (≈ 10⁻¹³ relative in F) adds ≈ 10⁻¹⁰.
//! A param at 0 has no log-log derivative (its row says so); a negative one is scaled
//! the same way (the derivative in ln |p|). With `time.steps: "auto"`, every analysis
//! runs the base one's D, so the step selection never jumps between p e^±h.
//!
//! The analyses run through the [`Executor`] in parts, as a synthesis's; the result
//! does not depend on the thread count.

use crate::error::Error;
use crate::exec::Executor;
use crate::model::{Model, Overrides, Steps};
use crate::progress::Progress;
use std::ops::ControlFlow;

pub mod kind;
mod report;
mod result;

pub use report::render_text;
pub use result::{Criteria, ParamSensitivity, SensitivityResult};

/// The default relative step h (a log-scale step: p e^±h).
pub const DEFAULT_RELATIVE_STEP: f64 = 1e-3;
/// The range of h a request may give.
pub const RELATIVE_STEP_RANGE: (f64, f64) = (1e-8, 0.1);
/// At most this many params in one request.
pub const MAX_PARAMS: usize = 200;
/// The criteria a ranking may name: `set.criterion`.
pub const CRITERIA: &[&str] = &[
    "covariance.yx",
    "covariance.zx",
    "covariance.yz",
    "bound.yx",
    "bound.zx",
    "bound.yz",
];

/// A sensitivity request, read.
#[derive(Clone, Debug)]
pub struct SensitivityRequest {
    pub model: Model,
    pub set: Overrides,
    /// The params, in the request's order (default: every param of the model, in
    /// alphabetical order; ties in the ranking keep this order).
    pub params: Vec<String>,
    pub relative_step: f64,
    /// Index into [`CRITERIA`]: the params are listed by |S| of this criterion.
    pub rank_by: usize,
}

/// The weighted criteria of both sets, in [`CRITERIA`]'s order.
fn criteria_of(r: &crate::AnalysisResult) -> [Option<f64>; 6] {
    let (c, b) = (&r.criteria.covariance.weighted, &r.criteria.bound.weighted);
    [c.yx, c.zx, c.yz, b.yx, b.zx, b.yz]
}

/// Runs the sensitivity analysis: the base analysis on the calling thread (with
/// progress), then the 2 per param through `exec`.
pub fn run<E: Executor>(
    req: &SensitivityRequest,
    analysis_work: f64,
    exec: &E,
    progress: &mut dyn Progress,
) -> Result<SensitivityResult, Error> {
    let h = req.relative_step;
    // Points: (param index, its value there); a param at 0 has none.
    let value = |p: &str| {
        req.set
            .get(p)
            .or_else(|| req.model.params.get(p))
            .copied()
            .unwrap_or(0.0)
    };
    let points: Vec<(usize, f64)> = req
        .params
        .iter()
        .enumerate()
        .filter(|(_, p)| value(p) != 0.0)
        .flat_map(|(i, p)| {
            let v = value(p);
            [(i, v * h.exp()), (i, v * (-h).exp())]
        })
        .collect();
    let total = 1.0 + points.len() as f64;
    let mut first = |f: f64| progress.report(f / total);
    let base = crate::analysis::analyze(&req.model, &req.set, &mut first)
        .map_err(crate::request::locate)?;
    // The base's D for every other analysis (an "auto" selection made once).
    let mut model = req.model.clone();
    model.time.steps = Steps::Fixed(base.steps);

    let each = crate::work::fitting(
        crate::progress::WORK_BETWEEN_PARTS,
        analysis_work,
        1_000_000,
    ) as usize;
    let part = exec.threads().max(1) * each;
    let mut values: Vec<[Option<f64>; 6]> = Vec::with_capacity(points.len());
    let mut rest = points.iter().peekable();
    while rest.peek().is_some() {
        let done = 1.0 + values.len() as f64;
        if progress.report(done / total).is_break() {
            return Err(Error::Cancelled);
        }
        let batch: Vec<(usize, f64)> = rest.by_ref().take(part).copied().collect();
        let stop = |_: f64| match exec.stop_requested() {
            true => ControlFlow::Break(()),
            false => ControlFlow::Continue(()),
        };
        let out = exec.map(batch, |(i, v)| {
            let mut set = req.set.clone();
            set.insert(req.params[i].clone(), v);
            crate::analysis::analyze(&model, &set, &mut { stop })
                .map(|r| criteria_of(&r))
                .map_err(|e| {
                    let at = format!("{} = {}", req.params[i], crate::text::num(v));
                    crate::request::locate(e).map_messages(|m| format!("{m} (at {at})"))
                })
        });
        for r in out {
            values.push(r?);
        }
    }
    if progress.report(1.0).is_break() {
        return Err(Error::Cancelled);
    }

    let base_criteria = criteria_of(&base);
    let mut at = values.chunks_exact(2);
    let mut params: Vec<ParamSensitivity> = req
        .params
        .iter()
        .map(|p| {
            let v = value(p);
            if v == 0.0 {
                return ParamSensitivity::undefined(
                    p,
                    v,
                    "the param is 0: a log-log derivative needs a value other than 0",
                );
            }
            let pair = at.next().expect("two analyses a param");
            let s = std::array::from_fn(|c| match (pair[0][c], pair[1][c]) {
                (Some(hi), Some(lo)) if hi > 0.0 && lo > 0.0 => {
                    Some((hi.ln() - lo.ln()) / (2.0 * h))
                }
                _ => None,
            });
            ParamSensitivity::new(p, v, h, s)
        })
        .collect();
    let k = req.rank_by;
    params.sort_by(|a, b| {
        let key = |x: &ParamSensitivity| x.sensitivity.get(k).map_or(-1.0, f64::abs);
        key(b).total_cmp(&key(a))
    });
    Ok(SensitivityResult {
        relative_step: h,
        rank_by: CRITERIA[k].to_string(),
        steps: base.steps,
        base: Criteria::from_array(base_criteria),
        params,
        analyses: 1 + points.len() as u64,
        warnings: base.warnings,
        timing: Default::default(),
    })
}
