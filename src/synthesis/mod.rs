//! Synthesis (METHOD §1.7, (3.27)): the error levels that reach a desired filtering
//! effect, e.g. F_YX ≥ F*_YX. Three modes, each built on repeated analyses
//! ([`crate::analyze`]) with parameter overrides:
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
use crate::exec::{Executor, Forgetful, Memo};
use crate::model::Model;
use crate::{Error, FieldError, Overrides, Progress};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::ops::ControlFlow;

pub mod kind;
pub mod work;

/// Largest number of points a seed search or a grid may have.
pub const MAX_POINTS: usize = 10_000;
/// Largest number of params of a grid (rows × columns × pages).
pub const MAX_GRID_PARAMS: usize = 3;
/// How much looser than the bisection answer the verification's "looser" point is.
pub const LOOSER_FACTOR: f64 = 1.01;
/// Relative tolerance of the monotonicity check (rounding of equal criteria).
const MONOTONE_TOL: f64 = 1e-9;

// ---------------------------------------------------------------- request

/// A synthesis request: a model, a target, one mode.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SynthesisRequest {
    pub model: Model,
    /// Overrides applied at every point (the mode's params are set on top).
    #[serde(default)]
    pub set: Overrides,
    pub target: Target,
    pub mode: Mode,
}

/// The desired effect: `criterion` of `set`, weighted (3.25) or for one `state`
/// (3.24), at least `threshold`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Target {
    pub criterion: Criterion,
    #[serde(default)]
    pub set: CriteriaSetName,
    /// A state name; absent: the weighted criterion.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state: Option<String>,
    pub threshold: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Criterion {
    Yz,
    Zx,
    Yx,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CriteriaSetName {
    #[default]
    Bound,
    Covariance,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    SeedSearch(SeedSearch),
    Bisect(Bisect),
    Grid(Grid),
}

/// The seed's procedure: params are nested loops, the first one outermost.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SeedSearch {
    pub params: Vec<RangeParam>,
    /// Points analysed per batch (in parallel natively). Fixed by the request, never by
    /// the thread count, so the number of analyses is reproducible; after the first
    /// qualifying point the rest of its batch is discarded.
    #[serde(
        default = "default_batch",
        deserialize_with = "crate::json::whole_in::<_, _, 1, 1024>"
    )]
    pub batch: usize,
}

fn default_batch() -> usize {
    4
}

/// A param's range [low, high] and shrink factor k < 1: values high, high·k, high·k², …
/// down to low.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RangeParam {
    pub name: String,
    pub low: f64,
    pub high: f64,
    pub shrink: f64,
}

/// The boundary value of one param in [low, high] (0 < low < high) where the target
/// starts to be met.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bisect {
    pub param: String,
    pub low: f64,
    pub high: f64,
    /// Stop when the bracket's ratio high/low − 1 is at most this (< 0.01).
    #[serde(default = "default_rel_tol")]
    pub rel_tol: f64,
    /// Log-spaced points (ends included) analysed first to bracket the boundary and
    /// check monotonicity.
    #[serde(
        default = "default_probes",
        deserialize_with = "crate::json::whole_in::<_, _, 2, 64>"
    )]
    pub probes: usize,
}

fn default_rel_tol() -> f64 {
    1e-3
}
fn default_probes() -> usize {
    9
}

/// A sweep over up to three params: rows × columns (× pages).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Grid {
    pub params: Vec<GridParam>,
    /// Which direction of which param is cheaper, most important first; the cheapest
    /// qualifying cell is the lexicographically cheapest one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost_order: Option<Vec<CostKey>>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridParam {
    pub name: String,
    pub values: Vec<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CostKey {
    pub name: String,
    pub cheaper: Cheaper,
}

/// Which values of a param cost less (e.g. a larger sensor SKO is a cheaper sensor).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Cheaper {
    Higher,
    Lower,
}

// ---------------------------------------------------------------- result

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SynthesisResult {
    pub target: Target,
    pub status: Status,
    /// One or two sentences: the answer, or why there is none and what to do.
    pub message: String,
    /// The point found (seed_search, bisect) or the cheapest qualifying cell (grid).
    pub answer: Option<Point>,
    pub verification: Option<Verification>,
    pub details: Details,
    /// Analyses run, verification included.
    pub analyses: u64,
    /// Of `analyses`, those not run again but recalled from an earlier run of the same
    /// request that was interrupted (a server's job re-queued by a shutdown or a crash,
    /// [`crate::exec::Memo`]). Absent when 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub recalled_analyses: u64,
    /// Steps D of each analysis.
    pub steps: u64,
    /// Filled by the caller (the core has no clock).
    pub timing: Timing,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// An answer was found and verified.
    Found,
    /// No point meets the target (the seed's failure: widen the ranges or lower it).
    NotFound,
    /// Bisection: both ends meet the target, the boundary lies outside the range.
    WholeRangeMeets,
    /// Bisection: the criterion is not monotonic in the param; no answer is given.
    NonMonotonic,
    /// Grid without a cost order: the table is the answer.
    Table,
}

/// One analysed point: the params set, the three criteria of the target's set and
/// scope, the targeted value and whether it meets the threshold.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Point {
    pub params: BTreeMap<String, f64>,
    pub yz: Option<f64>,
    pub zx: Option<f64>,
    pub yx: Option<f64>,
    /// The targeted criterion (null when undefined, see `note`).
    pub value: Option<f64>,
    pub meets: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

/// The answer re-analysed; for bisection also a point 1 % looser, which must miss.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Verification {
    pub point: Point,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub looser: Option<Point>,
    /// The answer meets the target (and the looser point, if any, misses it).
    pub passed: bool,
    /// The warnings of the answer's analysis that concern the target's set: a bound
    /// set that grew far beyond the covariance's (its criteria then describe |A|'s
    /// growth, not the filter; left out for a covariance target), lost precision, … —
    /// what the Analysis of that point would say.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Details {
    SeedSearch(SeedSearchOut),
    Bisect(BisectOut),
    Grid(GridOut),
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeedSearchOut {
    /// Each param's values in the order visited.
    pub levels: Vec<GridParam>,
    /// Points of the search space.
    pub points_total: usize,
    /// The points in the seed's order, up to and including the one found.
    pub visited: Vec<Point>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BisectOut {
    pub param: String,
    /// Which end of the range meets the target.
    pub meets_side: Option<Side>,
    /// The final bracket [meets, misses] (ordered as values).
    pub bracket: Option<[f64; 2]>,
    pub iterations: u32,
    /// Every analysed point of the search, sorted by the param.
    pub evaluations: Vec<Point>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    Low,
    High,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridOut {
    pub params: Vec<GridParam>,
    /// Row-major: the first param varies slowest.
    pub cells: Vec<GridCell>,
    /// Index of the cheapest qualifying cell (with a cost order).
    pub cheapest: Option<Vec<usize>>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridCell {
    /// Index into each param's values.
    pub index: Vec<usize>,
    pub point: Point,
}

// ---------------------------------------------------------------- parsing, validation

/// What each member of a synthesis request is, for "missing: …" (docs/synthesis.md).
pub const HINTS: &[(&str, &str)] = &[
    (
        "target",
        "the desired effect, an object such as {\"criterion\": \"yx\", \"threshold\": 14}",
    ),
    ("criterion", "the criterion to reach, one of: yz, zx, yx"),
    (
        "mode",
        "the search, an object with exactly one member: seed_search, bisect or grid",
    ),
    (
        "threshold",
        "the least value the criterion must reach (a number > 0)",
    ),
    ("params", "the params to search (an array)"),
    (
        "param",
        "the name of the param to search (one of the model's params)",
    ),
    ("name", "the name of one of the model's params"),
    ("low", "the lower end of the param's range (a number > 0)"),
    (
        "high",
        "the upper end of the param's range (a number > low)",
    ),
    (
        "shrink",
        "the factor in (0, 1) each step multiplies the param by",
    ),
    ("values", "the param's values (an array of numbers)"),
    (
        "cheaper",
        "which values of the param cost less: \"higher\" or \"lower\"",
    ),
];

/// Parse a request from JSON, with serde errors located at their field path.
pub fn request_from_value(value: serde_json::Value) -> Result<SynthesisRequest, Error> {
    crate::from_value_at(value, HINTS)
}

pub fn request_from_json(text: &str) -> Result<SynthesisRequest, Error> {
    let value = crate::parse_json(text.as_bytes())
        .map_err(|e| Error::invalid("", format!("not valid JSON: {e}")))?;
    request_from_value(value)
}

/// Check a request without running it; every problem found, at its path.
pub fn validate(req: &SynthesisRequest) -> Result<(), Error> {
    validated(req).map(drop)
}

/// [`validate`], giving the request's model compiled (with its `set`).
pub fn validated(req: &SynthesisRequest) -> Result<crate::model::CompiledModel, Error> {
    let mut errs: Vec<FieldError> = Vec::new();
    let compiled = crate::model::compile::compile(&req.model, &req.set);
    if let Err(e) = &compiled {
        errs.extend(crate::request::locate(e.clone()).field_errors());
    }
    let t = &req.target;
    // F_YZ and F_ZX of a state are defined only where it has a measurement: a target
    // there could never be met (every point would be undefined).
    if let (Ok(c), Some(s), Criterion::Yz | Criterion::Zx) = (&compiled, &t.state, t.criterion)
        && let Some(i) = c.states.iter().position(|x| x == s)
        && c.pair_of_state[i].is_none()
    {
        errs.push(FieldError::new(
            "target.criterion",
            format!(
                "{} is undefined for state \"{s}\": it has no paired measurement (measurement.pairs); yx is defined for every state",
                crit_name(t)
            ),
        ));
    }
    // The searched params take values the model may refuse (an SKO ≤ 0, a square root
    // of a negative): each param's extreme values are checked here, with the others
    // as the model and `set` give them, so that such a request is refused now at the
    // value's path rather than as a failed run.
    let mut fixed_in_set: Vec<&str> = Vec::new();
    for (name, path, value) in extremes(&req.mode) {
        if req.set.contains_key(name) {
            if !fixed_in_set.contains(&name) {
                fixed_in_set.push(name);
                errs.push(FieldError::new(
                    crate::error::member_path("set", name),
                    format!("\"{name}\" is a searched param (at {path}): the search sets it, so it cannot be fixed in set"),
                ));
            }
            continue;
        }
        // (A value the mode's own rule refuses — seed_search's bounds are > 0,
        // bisect's normal doubles — is reported there, once.)
        let mode_refuses = match req.mode {
            Mode::Grid(_) => false,
            Mode::SeedSearch(_) => value <= 0.0,
            Mode::Bisect(_) => value < f64::MIN_POSITIVE,
        };
        if compiled.is_err()
            || !req.model.params.contains_key(name)
            || !value.is_finite()
            || mode_refuses
        {
            continue;
        }
        let mut set = req.set.clone();
        set.insert(name.to_string(), value);
        if let Err(e) = crate::check(&req.model, &set)
            && let Some(first) = crate::request::locate(e).field_errors().into_iter().next()
        {
            errs.push(FieldError::new(
                path,
                format!(
                    "the model is invalid with {name} = {}: {first}",
                    crate::text::num(value)
                ),
            ));
        }
    }
    if !(t.threshold.is_finite() && t.threshold > 0.0) {
        errs.push(FieldError::new(
            "target.threshold",
            "expected a finite number > 0 (criteria are ratios; > 1 means an effect)",
        ));
    }
    if let Some(s) = &t.state
        && !req.model.system.states.contains(s)
    {
        errs.push(FieldError::new(
            "target.state",
            format!(
                "no state \"{s}\" in the model (states: {}); omit it for the weighted criterion",
                req.model.system.states.join(", ")
            ),
        ));
    }
    let param_check = |name: &str, path: String, errs: &mut Vec<FieldError>| {
        if !req.model.params.contains_key(name) {
            let known: Vec<&str> = req.model.params.keys().map(|s| s.as_str()).collect();
            errs.push(FieldError::new(
                path,
                format!(
                    "no parameter \"{name}\" in the model (params: {})",
                    if known.is_empty() {
                        "none".into()
                    } else {
                        known.join(", ")
                    }
                ),
            ));
        }
    };
    match &req.mode {
        Mode::SeedSearch(s) => {
            let base = "mode.seed_search";
            if s.params.is_empty() {
                errs.push(FieldError::new(
                    format!("{base}.params"),
                    "give at least one param range",
                ));
            }
            if s.batch == 0 || s.batch > 1024 {
                errs.push(FieldError::new(
                    format!("{base}.batch"),
                    format!("expected a whole number from 1 to 1024, got {}", s.batch),
                ));
            }
            let mut total: usize = 1;
            for (i, p) in s.params.iter().enumerate() {
                let path = format!("{base}.params[{i}]");
                param_check(&p.name, format!("{path}.name"), &mut errs);
                duplicate_check(s.params.iter().map(|p| &p.name), i, &path, &mut errs);
                let mut ok = true;
                if !(p.low.is_finite() && p.low > 0.0) {
                    errs.push(FieldError::new(
                        format!("{path}.low"),
                        "expected a finite number > 0 (values shrink toward it)",
                    ));
                    ok = false;
                }
                if !(p.high.is_finite() && p.high > 0.0) {
                    errs.push(FieldError::new(
                        format!("{path}.high"),
                        "expected a finite number > 0",
                    ));
                    ok = false;
                } else if ok && p.high < p.low {
                    errs.push(FieldError::new(
                        format!("{path}.high"),
                        format!("must be ≥ low = {}", p.low),
                    ));
                    ok = false;
                }
                if !(p.shrink > 0.0 && p.shrink < 1.0) {
                    errs.push(FieldError::new(
                        format!("{path}.shrink"),
                        "expected a factor in (0, 1): the search goes from high down to low",
                    ));
                    ok = false;
                }
                if ok {
                    let n = level_count(p);
                    if n > MAX_POINTS {
                        errs.push(FieldError::new(
                            format!("{path}.shrink"),
                            format!("{n} levels from high to low; at most {MAX_POINTS}"),
                        ));
                    }
                    total = total.saturating_mul(n);
                }
            }
            if total > MAX_POINTS {
                errs.push(FieldError::new(
                    format!("{base}.params"),
                    format!("{total} points in the search space; at most {MAX_POINTS}"),
                ));
            }
        }
        Mode::Bisect(b) => {
            let base = "mode.bisect";
            param_check(&b.param, format!("{base}.param"), &mut errs);
            // Bisection is on a log scale, among normal doubles: below f64::MIN_POSITIVE
            // (the subnormals) neighbouring doubles are further apart than any rel_tol,
            // and the bracket could not narrow to it.
            let expected = || {
                format!(
                    "expected a finite number ≥ {} (bisection is on a log scale, among normal doubles)",
                    crate::text::num(f64::MIN_POSITIVE)
                )
            };
            let low_ok = b.low.is_finite() && b.low >= f64::MIN_POSITIVE;
            if !low_ok {
                errs.push(FieldError::new(format!("{base}.low"), expected()));
            }
            if !(b.high.is_finite() && b.high >= f64::MIN_POSITIVE) {
                errs.push(FieldError::new(format!("{base}.high"), expected()));
            } else if low_ok && b.high <= b.low {
                errs.push(FieldError::new(
                    format!("{base}.high"),
                    format!("must be > low = {}", b.low),
                ));
            }
            if !(b.rel_tol >= 1e-12 && b.rel_tol < 0.01) {
                errs.push(FieldError::new(
                    format!("{base}.rel_tol"),
                    "expected a number in [1e-12, 0.01) (the answer is verified 1 % looser)",
                ));
            }
            if !(2..=64).contains(&b.probes) {
                errs.push(FieldError::new(
                    format!("{base}.probes"),
                    format!("expected a whole number from 2 to 64 (log-spaced points, ends included), got {}", b.probes),
                ));
            }
        }
        Mode::Grid(g) => {
            let base = "mode.grid";
            if g.params.is_empty() || g.params.len() > MAX_GRID_PARAMS {
                errs.push(FieldError::new(
                    format!("{base}.params"),
                    format!(
                        "expected 1 to {MAX_GRID_PARAMS} params (rows, columns, pages), got {}",
                        g.params.len()
                    ),
                ));
            }
            let mut total: usize = 1;
            for (i, p) in g.params.iter().enumerate() {
                let path = format!("{base}.params[{i}]");
                param_check(&p.name, format!("{path}.name"), &mut errs);
                duplicate_check(g.params.iter().map(|p| &p.name), i, &path, &mut errs);
                if p.values.is_empty() {
                    errs.push(FieldError::new(
                        format!("{path}.values"),
                        "give at least one value",
                    ));
                }
                for (j, v) in p.values.iter().enumerate() {
                    if !v.is_finite() {
                        errs.push(FieldError::new(
                            format!("{path}.values[{j}]"),
                            "expected a finite number",
                        ));
                    }
                }
                total = total.saturating_mul(p.values.len().max(1));
            }
            if total > MAX_POINTS {
                errs.push(FieldError::new(
                    format!("{base}.params"),
                    format!("{total} cells; at most {MAX_POINTS}"),
                ));
            }
            if let Some(order) = &g.cost_order {
                for (i, k) in order.iter().enumerate() {
                    let path = format!("{base}.cost_order[{i}]");
                    if !g.params.iter().any(|p| p.name == k.name) {
                        errs.push(FieldError::new(
                            format!("{path}.name"),
                            format!(
                                "\"{}\" is not a param of the grid ({})",
                                k.name,
                                g.params
                                    .iter()
                                    .map(|p| p.name.as_str())
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            ),
                        ));
                    }
                    duplicate_check(order.iter().map(|k| &k.name), i, &path, &mut errs);
                }
            }
        }
    }
    match compiled {
        Ok(c) if errs.is_empty() => Ok(c),
        _ => Err(Error::Invalid(errs)),
    }
}

/// Each searched param's extreme values with their paths: a grid's smallest and
/// largest value, a range's ends.
fn extremes(mode: &Mode) -> Vec<(&str, String, f64)> {
    let mut out: Vec<(&str, String, f64)> = Vec::new();
    match mode {
        Mode::SeedSearch(s) => {
            for (i, p) in s.params.iter().enumerate() {
                let path = format!("mode.seed_search.params[{i}]");
                out.push((&p.name, format!("{path}.low"), p.low));
                out.push((&p.name, format!("{path}.high"), p.high));
            }
        }
        Mode::Bisect(b) => {
            out.push((&b.param, "mode.bisect.low".into(), b.low));
            out.push((&b.param, "mode.bisect.high".into(), b.high));
        }
        Mode::Grid(g) => {
            for (i, p) in g.params.iter().enumerate() {
                let finite = p.values.iter().enumerate().filter(|(_, v)| v.is_finite());
                let by = |a: &(usize, &f64), b: &(usize, &f64)| a.1.total_cmp(b.1);
                let path = |j: usize| format!("mode.grid.params[{i}].values[{j}]");
                if let (Some(lo), Some(hi)) = (finite.clone().min_by(by), finite.max_by(by)) {
                    out.push((&p.name, path(lo.0), *lo.1));
                    if hi.0 != lo.0 {
                        out.push((&p.name, path(hi.0), *hi.1));
                    }
                }
            }
        }
    }
    out
}

fn duplicate_check<'a>(
    names: impl Iterator<Item = &'a String>,
    i: usize,
    path: &str,
    errs: &mut Vec<FieldError>,
) {
    let names: Vec<&String> = names.collect();
    if names[..i].contains(&names[i]) {
        errs.push(FieldError::new(
            format!("{path}.name"),
            format!("\"{}\" is listed twice", names[i]),
        ));
    }
}

/// The values of a seed-search param: high, high·k, high·k², … while ≥ low (the low
/// bound counts as reached within a relative 1e-9, so 0.5·0.5² = 0.125 is included).
pub fn levels(p: &RangeParam) -> Vec<f64> {
    let mut out = Vec::new();
    let mut v = p.high;
    while v >= p.low * (1.0 - 1e-9) && out.len() <= MAX_POINTS {
        out.push(v);
        v *= p.shrink;
    }
    out
}

fn level_count(p: &RangeParam) -> usize {
    levels(p).len()
}

/// The seed's visiting order: nested loops, the first param outermost, each from its
/// upper bound down. Each point lists one value per param.
pub fn seed_order(params: &[RangeParam]) -> Vec<Vec<f64>> {
    let levels: Vec<Vec<f64>> = params.iter().map(levels).collect();
    cartesian(&levels)
}

/// Row-major cartesian product (the first list varies slowest).
fn cartesian(lists: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut out = vec![Vec::new()];
    for list in lists {
        let mut next = Vec::with_capacity(out.len() * list.len());
        for prefix in &out {
            for &v in list {
                let mut p = prefix.clone();
                p.push(v);
                next.push(p);
            }
        }
        out = next;
    }
    out
}

/// Index of the first value meeting the threshold: the seed's stopping rule.
pub fn first_meeting(values: &[Option<f64>], threshold: f64) -> Option<usize> {
    values
        .iter()
        .position(|v| v.is_some_and(|v| v >= threshold))
}

/// Analyses a request will run at most (for work estimates and progress).
pub fn planned_analyses(req: &SynthesisRequest) -> u64 {
    match &req.mode {
        Mode::SeedSearch(s) => seed_order(&s.params).len() as u64 + 1,
        Mode::Grid(g) => {
            g.params
                .iter()
                .map(|p| p.values.len() as u64)
                .product::<u64>()
                + u64::from(g.cost_order.is_some())
        }
        Mode::Bisect(b) => b.probes as u64 + bisect_iterations_max(b) as u64 + 2,
    }
}

/// Bisection halves the log-width of the bracket; at most this many halvings bring a
/// probe interval down to rel_tol.
fn bisect_iterations_max(b: &Bisect) -> u32 {
    if !(b.low > 0.0 && b.high > b.low && b.rel_tol > 0.0 && b.probes >= 2) {
        return 0;
    }
    // (ln high − ln low: high/low itself overflows for low = 1e-300, high = 1e15.)
    let width = (b.high.ln() - b.low.ln()) / (b.probes - 1) as f64;
    let goal = b.rel_tol.ln_1p();
    ((width / goal).log2().ceil().max(0.0) as u32).saturating_add(1)
}

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

fn is_zero(n: &u64) -> bool {
    *n == 0
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
        let r = crate::analyze(self.model, &set, progress).map_err(|e| {
            let at = describe(params);
            match crate::request::locate(e) {
                Error::Invalid(v) => Error::Invalid(
                    v.into_iter()
                        .map(|f| FieldError::new(f.path, format!("{} (at {at})", f.message)))
                        .collect(),
                ),
                Error::Numerical {
                    step,
                    t,
                    path,
                    message,
                } => Error::Numerical {
                    step,
                    t,
                    path,
                    message: format!("{message} (at {at})"),
                },
                Error::Cancelled => Error::Cancelled,
            }
        })?;
        // The warnings that concern the target's set: the bound set's own say nothing
        // of a covariance target's criteria.
        let point = self.point(params, &r);
        let mut warnings = r.warnings;
        if self.target.set == CriteriaSetName::Covariance {
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
        let set = match self.target.set {
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

/// The end of a "no point meets the target" message: " (the best is 3.2100): widen the
/// range or lower the target." — or, where no point has a value, why (a criterion
/// undefined everywhere has no best: "-inf" was printed, with advice to widen).
fn best_of<'a>(points: impl Iterator<Item = &'a Point> + Clone, range: &str) -> String {
    match points.clone().filter_map(|p| p.value).reduce(f64::max) {
        Some(best) => {
            format!(
                " (the best is {}): widen the {range} or lower the target.",
                crate::text::cell(Some(best))
            )
        }
        None => {
            let why = points
                .filter_map(|p| p.note.as_deref())
                .next()
                .unwrap_or("no value");
            format!(
                ": the criterion has no value at any point ({why}); an analysis of the model says why (y_B = 0, no paired measurement, …)."
            )
        }
    }
}

fn describe(params: &[(String, f64)]) -> String {
    params
        .iter()
        .map(|(k, v)| format!("{k} = {}", crate::text::num(*v)))
        .collect::<Vec<_>>()
        .join(", ")
}

fn fmt_params(p: &BTreeMap<String, f64>) -> String {
    p.iter()
        .map(|(k, v)| format!("{k} = {}", fmt_num(*v)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A number in what a synthesis reports (notes, summaries, the bisection's
/// findings): rounded to 6 decimals or 5 significant digits, for reading. Where a
/// point's parameters must be quoted exactly — the point an analysis failed at
/// ([`describe`]) — [`crate::text::num`] is used instead.
fn fmt_num(x: f64) -> String {
    if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e6) {
        format!("{x:.4e}")
    } else {
        format!("{}", (x * 1e6).round() / 1e6)
    }
}

fn crit_name(t: &Target) -> String {
    let c = match t.criterion {
        Criterion::Yz => "YZ",
        Criterion::Zx => "ZX",
        Criterion::Yx => "YX",
    };
    let set = match t.set {
        CriteriaSetName::Bound => "bound",
        CriteriaSetName::Covariance => "covariance",
    };
    match &t.state {
        Some(s) => format!("f_{c}({s}, {set})"),
        None => format!("F_{c} ({set})"),
    }
}

/// A criterion's value as the analysis table writes it ([`crate::text::cell`]).
fn fmt_value(v: Option<f64>) -> String {
    v.map_or("undefined".into(), |v| crate::text::cell(Some(v)))
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

type ModeOut = (Status, String, Option<Point>, Option<Verification>, Details);

fn named(names: &[String], values: &[f64]) -> Vec<(String, f64)> {
    names.iter().cloned().zip(values.iter().copied()).collect()
}

/// Re-analyse `point` (and `looser`, which must miss) for the verification.
fn verify<E: Executor>(
    ctx: &mut Ctx,
    exec: &E,
    point: &Point,
    looser: Option<&BTreeMap<String, f64>>,
    progress: &mut dyn Progress,
) -> Result<Verification, Error> {
    let as_list =
        |m: &BTreeMap<String, f64>| m.iter().map(|(k, v)| (k.clone(), *v)).collect::<Vec<_>>();
    let mut batch = vec![as_list(&point.params)];
    if let Some(l) = looser {
        batch.push(as_list(l));
    }
    let mut out = ctx.batch_warned(exec, batch, progress)?;
    let looser = if looser.is_some() {
        out.pop().map(|(p, _)| p)
    } else {
        None
    };
    let (again, warnings) = out.pop().expect("one result per point");
    let passed = again.meets && looser.as_ref().is_none_or(|l| !l.meets);
    Ok(Verification {
        point: again,
        looser,
        passed,
        warnings,
    })
}

/// The seed's procedure (METHOD §1.7): nested loops from the upper bounds, shrink
/// factors < 1, stop at the first point meeting the target.
fn seed_search<E: Executor>(
    ctx: &mut Ctx,
    exec: &E,
    s: &SeedSearch,
    progress: &mut dyn Progress,
) -> Result<ModeOut, Error> {
    let names: Vec<String> = s.params.iter().map(|p| p.name.clone()).collect();
    let order = seed_order(&s.params);
    let levels: Vec<GridParam> = s
        .params
        .iter()
        .map(|p| GridParam {
            name: p.name.clone(),
            values: levels(p),
        })
        .collect();
    let points_total = order.len();
    let mut visited: Vec<Point> = Vec::new();
    let mut found: Option<Point> = None;
    for chunk in order.chunks(s.batch) {
        let batch = chunk.iter().map(|v| named(&names, v)).collect();
        for p in ctx.batch(exec, batch, progress)? {
            let meets = p.meets;
            visited.push(p.clone());
            if meets {
                found = Some(p);
                break;
            }
        }
        if found.is_some() {
            break;
        }
    }
    let details = |visited| {
        Details::SeedSearch(SeedSearchOut {
            levels: levels.clone(),
            points_total,
            visited,
        })
    };
    let crit = crit_name(ctx.target);
    match found {
        Some(p) => {
            let v = verify(ctx, exec, &p, None, progress)?;
            let message = format!(
                "{crit} = {} ≥ {} at {} (point {} of {} in the seed's order; verified by a fresh analysis: {}).",
                fmt_value(p.value),
                ctx.target.threshold,
                fmt_params(&p.params),
                visited.len(),
                points_total,
                if v.passed { "meets" } else { "FAILED" }
            );
            Ok((Status::Found, message, Some(p), Some(v), details(visited)))
        }
        None => {
            let best = visited
                .iter()
                .filter(|p| p.value.is_some())
                .max_by(|a, b| a.value.partial_cmp(&b.value).expect("finite criteria"));
            let message = format!(
                "No point of the {points_total} in the ranges reaches {crit} ≥ {}{}. Widen the ranges (lower the low bounds of {}) or lower the target.",
                ctx.target.threshold,
                best.map_or(String::new(), |b| format!(
                    " (the best is {} at {})",
                    fmt_value(b.value),
                    fmt_params(&b.params)
                )),
                names.join(", ")
            );
            Ok((Status::NotFound, message, None, None, details(visited)))
        }
    }
}

/// Whether values along increasing x are monotonic (within rounding), and if not the
/// index i where values[i−1], values[i], values[i+1] turn.
fn monotonic_violation(values: &[f64]) -> Option<usize> {
    let scale = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let tol = MONOTONE_TOL * scale;
    let mut dir = 0i8; // +1 rising, −1 falling
    for i in 1..values.len() {
        let d = values[i] - values[i - 1];
        let s = if d > tol {
            1
        } else if d < -tol {
            -1
        } else {
            0
        };
        if s != 0 {
            if dir != 0 && s != dir {
                return Some(i - 1);
            }
            dir = s;
        }
    }
    None
}

/// The boundary of one param by bisection on a log scale (METHOD §1.7).
fn bisect<E: Executor>(
    ctx: &mut Ctx,
    exec: &E,
    b: &Bisect,
    progress: &mut dyn Progress,
) -> Result<ModeOut, Error> {
    let name = b.param.clone();
    let at = |x: f64| vec![(name.clone(), x)];
    let (l0, l1) = (b.low.ln(), b.high.ln());
    let n = b.probes;
    let xs: Vec<f64> = (0..n)
        .map(|i| match i {
            0 => b.low,
            i if i == n - 1 => b.high,
            i => (l0 + (l1 - l0) * i as f64 / (n - 1) as f64).exp(),
        })
        .collect();
    let probes = ctx.batch(exec, xs.iter().map(|&x| at(x)).collect(), progress)?;
    let mut evals: Vec<(f64, Point)> = xs.iter().copied().zip(probes).collect();
    let crit = crit_name(ctx.target);
    let thr = crate::text::num(ctx.target.threshold); // (for messages: 1e308 not in 309 digits)
    let out = |evals: &[(f64, Point)], side, bracket, iterations| {
        Details::Bisect(BisectOut {
            param: name.clone(),
            meets_side: side,
            bracket,
            iterations,
            evaluations: evals.iter().map(|(_, p)| p.clone()).collect(),
        })
    };
    let fmt_evals = |evals: &[(f64, Point)], idx: &[usize]| {
        idx.iter()
            .map(|&i| {
                format!(
                    "{} at {name} = {}",
                    fmt_value(evals[i].1.value),
                    fmt_num(evals[i].0)
                )
            })
            .collect::<Vec<_>>()
            .join(", ")
    };

    // Undefined criteria: no answer can be trusted.
    if let Some((x, p)) = evals.iter().find(|(_, p)| p.value.is_none()) {
        let message = format!(
            "{crit} is undefined at {name} = {} ({}); no boundary can be bisected.",
            fmt_num(*x),
            p.note.clone().unwrap_or_default()
        );
        return Ok((
            Status::NonMonotonic,
            message,
            None,
            None,
            out(&evals, None, None, 0),
        ));
    }
    let meets: Vec<bool> = evals.iter().map(|(_, p)| p.meets).collect();
    let transitions: Vec<usize> = (1..n).filter(|&i| meets[i] != meets[i - 1]).collect();
    let values: Vec<f64> = evals.iter().map(|(_, p)| p.value.unwrap()).collect();
    if transitions.len() > 1 || monotonic_violation(&values).is_some() {
        let i = monotonic_violation(&values).unwrap_or_else(|| transitions[0]);
        let idx: Vec<usize> = (i.saturating_sub(1)..(i + 2).min(n)).collect();
        let message = format!(
            "{crit} is not monotonic in {name} on [{}, {}] ({}){}: bisection could return a wrong answer, so none is given. Narrow the range to a monotonic part, or use a grid to see the shape.",
            fmt_num(b.low),
            fmt_num(b.high),
            fmt_evals(&evals, &idx),
            if transitions.len() > 1 {
                format!(
                    ", and the target is met on {} separate parts",
                    transitions.len() / 2 + 1
                )
            } else {
                String::new()
            }
        );
        return Ok((
            Status::NonMonotonic,
            message,
            None,
            None,
            out(&evals, None, None, 0),
        ));
    }
    if transitions.is_empty() {
        let best = best_of(evals.iter().map(|(_, p)| p), "range");
        return Ok(if meets[0] {
            (
                Status::WholeRangeMeets,
                format!(
                    "Every {name} in [{}, {}] meets {crit} ≥ {thr} ({}): the boundary lies outside the range; widen it.",
                    fmt_num(b.low),
                    fmt_num(b.high),
                    fmt_evals(&evals, &[0, n - 1])
                ),
                None,
                None,
                out(&evals, None, None, 0),
            )
        } else {
            (
                Status::NotFound,
                format!(
                    "No {name} in [{}, {}] reaches {crit} ≥ {thr}{best}",
                    fmt_num(b.low),
                    fmt_num(b.high)
                ),
                None,
                None,
                out(&evals, None, None, 0),
            )
        });
    }
    let t = transitions[0];
    let side = if meets[0] { Side::Low } else { Side::High };
    // The bracket: `good` meets, `bad` misses.
    let (mut good, mut bad) = if meets[0] {
        (xs[t - 1], xs[t])
    } else {
        (xs[t], xs[t - 1])
    };
    let mut iterations = 0u32;
    while good.max(bad) / good.min(bad) - 1.0 > b.rel_tol {
        // The geometric mean; √good·√bad where good·bad leaves f64's range.
        let mid = match (good * bad).sqrt() {
            m if m.is_finite() && m > 0.0 => m,
            _ => good.sqrt() * bad.sqrt(),
        };
        // Never reached with normal bounds and rel_tol ≥ 1e-12 (validation), but a
        // bracket with no double inside must end the loop, not repeat it forever.
        if !(mid > good.min(bad) && mid < good.max(bad)) || iterations >= bisect_iterations_max(b) {
            break;
        }
        let p = ctx.batch(exec, vec![at(mid)], progress)?.remove(0);
        iterations += 1;
        let pos = evals.partition_point(|(x, _)| *x < mid);
        let m = p.meets;
        evals.insert(pos, (mid, p));
        let values: Vec<f64> = evals
            .iter()
            .map(|(_, p)| p.value.unwrap_or(f64::NAN))
            .collect();
        if let Some(i) = monotonic_violation(&values) {
            let idx: Vec<usize> = (i.saturating_sub(1)..(i + 2).min(evals.len())).collect();
            let message = format!(
                "{crit} turns out not monotonic in {name} near {} ({}): no answer is given. Narrow the range or use a grid.",
                fmt_num(mid),
                fmt_evals(&evals, &idx)
            );
            return Ok((
                Status::NonMonotonic,
                message,
                None,
                None,
                out(&evals, Some(side), None, iterations),
            ));
        }
        if m {
            good = mid;
        } else {
            bad = mid;
        }
    }
    let answer = evals
        .iter()
        .find(|(x, _)| *x == good)
        .map(|(_, p)| p.clone())
        .expect("the bracket's ends were analysed");
    let looser_x = match side {
        Side::Low => good * LOOSER_FACTOR,
        Side::High => good / LOOSER_FACTOR,
    };
    let looser: BTreeMap<String, f64> = [(name.clone(), looser_x)].into_iter().collect();
    let v = verify(ctx, exec, &answer, Some(&looser), progress)?;
    let bracket = Some([good, bad]);
    if !v.passed {
        let message = format!(
            "Bisection ended at {name} = {} but the verification failed ({} there, {} at {name} = {}): {crit} is not monotonic near the boundary; no answer is given.",
            fmt_num(good),
            fmt_value(v.point.value),
            fmt_value(v.looser.as_ref().and_then(|l| l.value)),
            fmt_num(looser_x)
        );
        return Ok((
            Status::NonMonotonic,
            message,
            None,
            Some(v),
            out(&evals, Some(side), bracket, iterations),
        ));
    }
    let message = format!(
        "The loosest {name} meeting {crit} ≥ {thr} is {name} = {} ({}; the target is met for {name} {} it). Verified: {} there, {} at {name} = {} (1 % looser) misses.",
        fmt_num(good),
        fmt_value(answer.value),
        match side {
            Side::Low => "at or below",
            Side::High => "at or above",
        },
        fmt_value(v.point.value),
        fmt_value(v.looser.as_ref().and_then(|l| l.value)),
        fmt_num(looser_x)
    );
    Ok((
        Status::Found,
        message,
        Some(answer),
        Some(v),
        out(&evals, Some(side), bracket, iterations),
    ))
}

/// Criteria tables over up to three params (the seed's Table 2).
fn grid<E: Executor>(
    ctx: &mut Ctx,
    exec: &E,
    g: &Grid,
    progress: &mut dyn Progress,
) -> Result<ModeOut, Error> {
    let names: Vec<String> = g.params.iter().map(|p| p.name.clone()).collect();
    let lists: Vec<Vec<f64>> = g.params.iter().map(|p| p.values.clone()).collect();
    let index_lists: Vec<Vec<f64>> = lists
        .iter()
        .map(|l| (0..l.len()).map(|i| i as f64).collect())
        .collect();
    let indices: Vec<Vec<usize>> = cartesian(&index_lists)
        .into_iter()
        .map(|v| v.into_iter().map(|i| i as usize).collect())
        .collect();
    let points: Vec<Vec<(String, f64)>> =
        cartesian(&lists).iter().map(|v| named(&names, v)).collect();
    let mut cells = Vec::with_capacity(points.len());
    let per_batch = exec.threads().max(1);
    let mut idx_iter = indices.into_iter();
    let mut rest = points;
    while !rest.is_empty() {
        let tail = rest.split_off(per_batch.min(rest.len()));
        for p in ctx.batch(exec, rest, progress)? {
            cells.push(GridCell {
                index: idx_iter.next().expect("one index per cell"),
                point: p,
            });
        }
        rest = tail;
    }
    let qualifying = cells.iter().filter(|c| c.point.meets).count();
    let crit = crit_name(ctx.target);
    let thr = crate::text::num(ctx.target.threshold); // (for messages)
    let cheapest = g.cost_order.as_ref().and_then(|order| {
        cells
            .iter()
            .filter(|c| c.point.meets)
            .min_by(|a, b| {
                for k in order {
                    let (x, y) = (a.point.params[&k.name], b.point.params[&k.name]);
                    let ord = match k.cheaper {
                        Cheaper::Higher => y.partial_cmp(&x),
                        Cheaper::Lower => x.partial_cmp(&y),
                    }
                    .expect("finite values");
                    if ord.is_ne() {
                        return ord;
                    }
                }
                std::cmp::Ordering::Equal
            })
            .cloned()
    });
    let out = |cheapest: Option<Vec<usize>>, cells| {
        Details::Grid(GridOut {
            params: g.params.clone(),
            cells,
            cheapest,
        })
    };
    match (&g.cost_order, cheapest) {
        (Some(_), Some(c)) => {
            let v = verify(ctx, exec, &c.point, None, progress)?;
            let message = format!(
                "{qualifying} of {} cells meet {crit} ≥ {thr}; the cheapest is {} with {} (verified by a fresh analysis: {}).",
                cells.len(),
                fmt_params(&c.point.params),
                fmt_value(c.point.value),
                if v.passed { "meets" } else { "FAILED" }
            );
            Ok((
                Status::Found,
                message,
                Some(c.point.clone()),
                Some(v),
                out(Some(c.index), cells),
            ))
        }
        _ if qualifying == 0 => {
            let best = best_of(cells.iter().map(|c| &c.point), "ranges");
            Ok((
                Status::NotFound,
                format!("No cell of {} meets {crit} ≥ {thr}{best}", cells.len()),
                None,
                None,
                out(None, cells),
            ))
        }
        _ => Ok((
            Status::Table,
            format!(
                "{qualifying} of {} cells meet {crit} ≥ {thr} (marked); give `cost_order` to pick the cheapest.",
                cells.len()
            ),
            None,
            None,
            out(None, cells),
        )),
    }
}

// ---------------------------------------------------------------- text output

/// A plain-text rendering: the message, and for a grid its tables (rows = first param,
/// columns = second, one table per value of the third), cells `F_YZ / F_ZX / F_YX`
/// with `*` on those meeting the target and `[ ]` around the cheapest.
pub fn render_text(r: &SynthesisResult) -> String {
    let mut s = String::new();
    // Cells of three criteria, each as the analysis table writes it.
    let f = crate::text::cell;
    const W: usize = 3 * crate::text::CELL + 8;
    match &r.details {
        Details::Grid(g) => {
            let rows = &g.params[0];
            let cols = g.params.get(1);
            let pages = g.params.get(2);
            let n_cols = cols.map_or(1, |c| c.values.len());
            let n_pages = pages.map_or(1, |p| p.values.len());
            for k in 0..n_pages {
                if let Some(p) = pages {
                    s += &format!("{} = {}\n", p.name, fmt_num(p.values[k]));
                }
                let head = match cols {
                    Some(c) => format!("{} \\ {}", rows.name, c.name),
                    None => rows.name.clone(),
                };
                s += &format!("{head:>14}");
                for j in 0..n_cols {
                    let h = cols.map_or("F_YZ / F_ZX / F_YX".into(), |c| fmt_num(c.values[j]));
                    s += &format!(" | {h:^W$}");
                }
                s += "\n";
                for (i, rv) in rows.values.iter().enumerate() {
                    s += &format!("{:>14}", fmt_num(*rv));
                    for j in 0..n_cols {
                        let mut idx = vec![i];
                        if cols.is_some() {
                            idx.push(j);
                        }
                        if pages.is_some() {
                            idx.push(k);
                        }
                        let cell = g.cells.iter().find(|c| c.index == idx);
                        let txt = cell.map_or(String::new(), |c| {
                            let p = &c.point;
                            let body = format!("{} / {} / {}", f(p.yz), f(p.zx), f(p.yx));
                            let mark = if p.meets { "*" } else { " " };
                            if g.cheapest.as_ref() == Some(&idx) {
                                format!("[{body}]{mark}")
                            } else {
                                format!(" {body} {mark}")
                            }
                        });
                        s += &format!(" | {txt:^W$}");
                    }
                    s += "\n";
                }
                s += "\n";
            }
        }
        Details::SeedSearch(d) => {
            for (i, p) in d.visited.iter().enumerate() {
                s += &format!(
                    "{:>4}  {}  →  {}{}\n",
                    i + 1,
                    fmt_params(&p.params),
                    fmt_value(p.value),
                    if p.meets { "  *" } else { "" }
                );
            }
        }
        Details::Bisect(d) => {
            for p in &d.evaluations {
                s += &format!(
                    "  {}  →  {}{}\n",
                    fmt_params(&p.params),
                    fmt_value(p.value),
                    if p.meets { "  *" } else { "" }
                );
            }
        }
    }
    s += &r.message;
    // The answer's analysis's warnings, as `kea analyze` prints them.
    for w in r.verification.iter().flat_map(|v| &v.warnings) {
        s += &format!("\nwarning (the answer's analysis): {w}");
    }
    s += &format!(
        "\n{} analyses of D = {} steps, {:.1} ms\n",
        r.analyses, r.steps, r.timing.wall_ms
    );
    s
}
