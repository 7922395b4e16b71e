//! The synthesis request (METHOD §1.7, (3.27)): the target, the three modes and their
//! params; parsing with located errors, validation (every problem at its path), the
//! seed search's levels and order, and the analyses a request plans.

use crate::error::Error;
use crate::error::FieldError;
use crate::model::Model;
use crate::model::Overrides;
use serde::{Deserialize, Serialize};

/// Largest number of points a seed search or a grid may have.
pub const MAX_POINTS: usize = 10_000;
/// Largest number of params of a grid (rows × columns × pages).
pub const MAX_GRID_PARAMS: usize = 3;

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

/// The desired effect: `criterion` of the `criteria` set, weighted (3.25) or for one
/// `state` (3.24), at least `threshold`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Target {
    pub criterion: Criterion,
    /// Which criteria set the criterion is of (`bound` when absent). Also read as
    /// `set`, its former name (a request's `set` is its parameter overrides); the two
    /// together are refused, as a member given twice.
    #[serde(default, alias = "set")]
    pub criteria: CriteriaSetName,
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
    crate::json::from_value_at(value, HINTS)
}

pub fn request_from_json(text: &str) -> Result<SynthesisRequest, Error> {
    let value = crate::json::parse_json(text.as_bytes())
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
        if let Err(e) = crate::model::check(&req.model, &set)
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
            let message = crate::model::params::unknown_param(&req.model.params, name);
            errs.push(FieldError::new(path, message));
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
pub(super) fn cartesian(lists: &[Vec<f64>]) -> Vec<Vec<f64>> {
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
pub(super) fn bisect_iterations_max(b: &Bisect) -> u32 {
    if !(b.low > 0.0 && b.high > b.low && b.rel_tol > 0.0 && b.probes >= 2) {
        return 0;
    }
    // (ln high − ln low: high/low itself overflows for low = 1e-300, high = 1e15.)
    let width = (b.high.ln() - b.low.ln()) / (b.probes - 1) as f64;
    let goal = b.rel_tol.ln_1p();
    ((width / goal).log2().ceil().max(0.0) as u32).saturating_add(1)
}

/// The target's criterion as messages name it (`F_YX (covariance)`, `f_YZ(x, bound)`).
pub(super) fn crit_name(t: &Target) -> String {
    let c = match t.criterion {
        Criterion::Yz => "YZ",
        Criterion::Zx => "ZX",
        Criterion::Yx => "YX",
    };
    let set = match t.criteria {
        CriteriaSetName::Bound => "bound",
        CriteriaSetName::Covariance => "covariance",
    };
    match &t.state {
        Some(s) => format!("f_{c}({s}, {set})"),
        None => format!("F_{c} ({set})"),
    }
}
