//! The analysis's work estimate: a cost model of the core's steps, in units of about a
//! nanosecond of one core. The server's limits (`--sync-work-limit`, `--max-work`),
//! the command line's `--max-work` and the web page (before a run in the browser)
//! compare it ([`analysis_work`], [`monte_carlo_work`], [`synthesis_work`]), and the core spaces its progress
//! reports (the callers' chance to cancel) by it
//! ([`crate::analysis::steps_between_reports`]),
//! so it must follow what the engine does per step (engine.rs, inputs.rs, and the
//! Monte Carlo's plan.rs and runs.rs), not only N.
//!
//! An analysis step costs (units ≈ ns; N states, n measurements, L = columns of b,
//! M = columns of Γ or g):
//!
//! - the engine, whatever varies: N³ + 16N² + 200 ([`crate::analysis::work::step_cost`]), N³ replaced
//!   by 2(N + nnz(a))N + nN² where that is smaller ([`sparse_engine`]);
//! - b(t) varying: re-forming B = bΔt W (bΔt)ᵀ, N·L²/4 (bΔt W, a vectorised product)
//!   + N(N+1)/2·L (the symmetric product's dot products, ≈ 1 ns a term) + 2NL;
//! - Γ(t) (or g(t)) varying: Γ V Γᵀ the same way, n·M²/4 + n(n+1)/2·M + 2nM (plus
//!   n·N·M/4 for Γ = C g), and Rv's factorisation n³/3 + n²N/2;
//! - a(t) varying: 2N², u(t): 2N; a measurement schedule: n·N + n³/3 + n²N/2 (the
//!   measurements are prepared again whenever the available ones change);
//! - each distinct time-dependent expression: 10 + its length in characters (entries
//!   of one matrix with the same text are evaluated once) + its calls ([`call_units`]:
//!   60 a power `^`, 12 a sin or exp, 25 any other function but sqrt, abs and the
//!   roundings), plus 2 per entry
//!   that varies; a schedule's `when` (evaluated point by point): 20 + 4 per character
//!   + its calls.
//!
//! Measured (CPU time of `kea analyze`, a 2-core x86-64 with AVX2, per step, against
//! the estimate): the presets 175–613 ns against 240–1085; N = 10, L = M = 200, b(t)
//! of one expression 74 µs against 118 000, of 2000 distinct `sin(k*t)/1e3` 124 µs
//! against 171 000; N = 100, L = M = 100 577 µs against 1.9e6 (N³ dominates, and the
//! engine's N³ is pessimistic on this machine). Per distinct expression and step: 1000–2000
//! `sin(k*t)/1e3` 33–42 ns, `k*t` 16 ns, 39 characters 64 ns, 242 characters 269 ns,
//! 977 characters 772 ns (a parsed expression is tens of KB, so hundreds of them no
//! longer fit in the caches). Per call, in chains of 60 on a 2-core Zen 4: `^1.01`
//! 56 ns, cos 19, sin 7 (vectorised; 15–20 lane by lane), ln 18, cbrt 23, tanh and
//! atanh 15 each, exp 11, sqrt and `*1.01` 2–4; these chains' whole steps are
//! estimated at 1.7–3.0 times their time (sqrt's 2.4–3.7, with the host's noise). A
//! chain of 100 `^1.01` (985 characters) was estimated at 997 units a step against
//! 6.5 µs before calls were counted.
//!
//! A Monte Carlo adds the plan's and the runs' steps
//! ([`crate::monte_carlo::work::plan_step`], [`crate::monte_carlo::work::run_step`]);
//! estimated 1.07–2.4 times the CPU time of the presets and of N = 10, L = M = 200
//! with 2 to 1000 runs.

use crate::error::Error;
use crate::expr::Value;
use crate::model::Model;
use crate::model::Overrides;
use crate::model::compile::{CompiledModel, MeasurementNoise};
use crate::model::schedule::Availability;
use crate::work::Work;
use std::collections::HashSet;

/// The cost of the expressions in t of a model, per step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Expressions {
    /// Distinct time-dependent texts (per matrix; schedule `when`s not included).
    pub distinct: usize,
    /// Their characters.
    pub chars: usize,
    /// Entries whose value depends on t.
    pub entries: usize,
    /// Schedule `when` expressions and their characters.
    pub whens: usize,
    pub when_chars: usize,
    /// The [`call_units`] of the distinct expressions and the `when`s.
    pub calls: usize,
}

/// The cost of the functions and powers an expression calls, beyond its characters:
/// 60 a `^` (libm's pow), 12 a sin or exp, 0 a sqrt, abs or rounding (an
/// instruction or two: its characters cover it), 25 any other function (cos, ln, cbrt, tanh, …; see the module's figures).
pub fn call_units(text: &str) -> usize {
    let mut units = 60 * text.matches('^').count();
    let mut rest = text;
    while let Some(start) = rest.find(|c: char| c.is_ascii_alphabetic() || c == '_') {
        let word = &rest[start..];
        let len = word
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(word.len());
        let (name, after) = word.split_at(len);
        if after.trim_start().starts_with('(') {
            units += match name {
                "sin" | "exp" => 12,
                "sqrt" | "abs" | "signum" | "floor" | "ceil" | "round" | "trunc" | "fract" => 0,
                _ => 25,
            };
        }
        rest = after;
    }
    units
}

/// The characters assumed for an expression whose text is not known.
const ASSUMED_CHARS: usize = 20;

impl Expressions {
    /// The expressions of `compiled`, with their texts from `model` when given (else
    /// every varying entry counts as a distinct expression of 20 characters).
    pub fn of(compiled: &CompiledModel, model: Option<&Model>) -> Expressions {
        let mut e = Expressions::default();
        let sys = model.map(|m| &m.system);
        let meas = model.map(|m| &m.measurement);
        let u_rows: Option<Vec<Vec<Value>>> = sys
            .and_then(|s| s.u.as_ref())
            .map(|u| u.iter().map(|v| vec![v.clone()]).collect());
        let noise_rows = meas.and_then(|m| match &compiled.noise {
            MeasurementNoise::Gamma(_) => m.gamma.as_ref(),
            MeasurementNoise::SeedG(_) => m.g.as_ref(),
        });
        let matrices = [
            (&compiled.a, sys.map(|s| &s.a)),
            (&compiled.u, u_rows.as_ref()),
            (&compiled.b, sys.map(|s| &s.b)),
            (compiled.noise.matrix(), noise_rows),
        ];
        for (m, rows) in matrices {
            let mut texts = HashSet::new();
            for i in 0..m.rows * m.cols {
                if !m.varies(i) {
                    continue;
                }
                e.entries += 1;
                let text = rows
                    .and_then(|r| r.get(i / m.cols))
                    .and_then(|r| r.get(i % m.cols));
                match text {
                    Some(Value::Expr(s)) => {
                        if texts.insert(s.as_str()) {
                            e.distinct += 1;
                            e.chars += s.chars().count();
                            e.calls += call_units(s);
                        }
                    }
                    _ => {
                        e.distinct += 1;
                        e.chars += ASSUMED_CHARS;
                    }
                }
            }
        }
        if let Some(s) = &compiled.schedule {
            let texts = meas.and_then(|m| m.schedule.as_ref());
            for (j, a) in s.items.iter().enumerate() {
                if let Availability::When(..) = a {
                    e.whens += 1;
                    match texts
                        .and_then(|t| t.get(j))
                        .and_then(|s| s.as_ref())
                        .and_then(|s| s.when.as_ref())
                    {
                        Some(Value::Expr(s)) => {
                            e.when_chars += s.chars().count();
                            e.calls += call_units(s);
                        }
                        _ => e.when_chars += ASSUMED_CHARS,
                    }
                }
            }
        }
        e
    }

    /// Units per step.
    pub fn units(&self) -> f64 {
        (10 * self.distinct + self.chars + 2 * self.entries) as f64
            + (20 * self.whens + 4 * self.when_chars) as f64
            + self.calls as f64
    }
}

/// The engine's step where A and the measurements are sparse: 16N² + 200 plus
/// 2(N + nnz(a))·N + n·N² in place of N³ — the two predictions R + E R (+ its
/// transpose's) go over a's structural non-zeros (E = aΔt), and each of the n scalar
/// updates is O(N²) — where that is smaller. Measured (a 2-core Zen 4, N = 200,
/// D = 3000, n = 1, CPU time of `kea analyze` against the estimate): a chain 262 µs a
/// step against 840, a = 0 (every step takes the exact update) 560 against 760, a
/// dense a 3 729 against N³'s 8 640. With n = N (every state measured: Table 1, the
/// presets) N³ is the smaller and nothing changes.
pub fn sparse_engine(n: usize, nnz_a: usize, n_meas: usize) -> f64 {
    let (n, nnz, nm) = (n as f64, nnz_a as f64, n_meas as f64);
    2.0 * (n + nnz) * n + nm * n * n
}

/// The cost of one analysis step, in parts (for messages).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnalysisStep {
    pub n: usize,
    /// N³ + 16N² + 200, or with [`sparse_engine`] for N³ where that is smaller.
    pub engine: f64,
    /// (nnz(a), n) where the sparse form is the engine's.
    pub sparse: Option<(usize, usize)>,
    /// Re-forming the inputs that vary with t (B, Rv, A, u; the schedule's masks).
    pub inputs: f64,
    /// Evaluating the expressions in t.
    pub expressions: Expressions,
}

impl AnalysisStep {
    pub fn of(compiled: &CompiledModel, model: Option<&Model>) -> AnalysisStep {
        let n = compiled.n_states() as f64;
        let nm = compiled.n_measurements() as f64;
        let l = compiled.b.cols as f64;
        let ms = compiled.noise.sources() as f64;
        let mut inputs = 0.0;
        if !compiled.b.is_constant() {
            inputs += n * l * l / 4.0 + n * (n + 1.0) / 2.0 * l + 2.0 * n * l;
        }
        let noise = compiled.noise.matrix();
        let rv_factor = nm * nm * nm / 3.0 + nm * nm * n / 2.0;
        if !noise.is_constant() {
            inputs += nm * ms * ms / 4.0 + nm * (nm + 1.0) / 2.0 * ms + 2.0 * nm * ms + rv_factor;
            if let MeasurementNoise::SeedG(_) = compiled.noise {
                inputs += nm * n * ms / 4.0;
            }
        }
        if !compiled.a.is_constant() {
            inputs += 2.0 * n * n;
        }
        if !compiled.u.is_constant() {
            inputs += 2.0 * n;
        }
        if compiled.schedule.is_some() {
            inputs += nm * n + rv_factor;
        }
        let states = compiled.n_states();
        let nnz_a = (0..states * states)
            .filter(|&k| compiled.a.values[k] != 0.0 || compiled.a.varies(k))
            .count();
        let n_meas = compiled.n_measurements();
        let dense = crate::analysis::work::step_cost(states);
        let sparse = sparse_engine(states, nnz_a, n_meas);
        let cube = n * n * n;
        AnalysisStep {
            n: states,
            engine: if sparse < cube {
                dense - cube + sparse
            } else {
                dense
            },
            sparse: (sparse < cube).then_some((nnz_a, n_meas)),
            inputs,
            expressions: Expressions::of(compiled, model),
        }
    }

    /// Units per step.
    pub fn units(&self) -> f64 {
        self.engine + self.inputs + self.expressions.units()
    }

    /// The parts, e.g. "N³ + 16N² + 200 = 2800 (N = 10); inputs in t 114000;
    /// 2000 expressions in t (31000 characters) 55000".
    pub fn explain(&self) -> String {
        let mut s = match self.sparse {
            None => format!("N³ + 16N² + 200 = {} (N = {})", self.engine, self.n),
            Some((nnz, nm)) => format!(
                "2(N + nnz(a))N + nN² + 16N² + 200 = {} (N = {}, {nnz} non-zeros in a, n = {nm}: below N³)",
                self.engine, self.n
            ),
        };
        if self.inputs > 0.0 {
            s += &format!(" + inputs varying in t {:.0}", self.inputs);
        }
        let e = &self.expressions;
        if e.entries + e.whens > 0 {
            let count = e.distinct + e.whens;
            let calls = if e.calls > 0 {
                format!(", calls {}", e.calls)
            } else {
                String::new()
            };
            s += &format!(
                " + {count} expression{} in t ({} characters{calls}) {:.0}",
                if count == 1 { "" } else { "s" },
                e.chars + e.when_chars,
                e.units()
            );
        }
        s
    }
}

/// The work of analysing a compiled model (`model`: its expressions' texts, see
/// [`Expressions::of`]): D (for `"auto"` the cap) × the step's cost.
pub fn analysis_work(compiled: &CompiledModel, model: Option<&Model>) -> Work {
    let step = AnalysisStep::of(compiled, model);
    let steps = compiled.max_steps();
    let once = AnalysisOnce::of(compiled, model);
    let mut explain = format!(
        "D = {steps} steps × {:.0} ({})",
        step.units(),
        step.explain()
    );
    if once.units() > 0.0 {
        explain += &format!(" + once {:.0} ({})", once.units(), once.explain());
    }
    Work {
        units: steps as f64 * step.units() + once.units(),
        explain,
        path: "model.time.steps".into(),
    }
}

/// Units of parsing one expression (a distinct text of a member), constant or in t:
/// exmex builds a parsed expression of tens of KB, and one in t is parsed twice (for
/// one value and for blocks of values). Measured (a 2-core Zen 4, `kea analyze` of one
/// step): 40 000 distinct constant texts `p*k` 1.0 s, 2000 in t 42 ms a synthesis point.
pub const PARSE_UNITS: f64 = 25_000.0;

/// Units of one doubling of [`crate::numerics::riccati::dare_doubling`] (an LU, two solves and
/// four products of N × N matrices), per N³: measured 1.5 at N = 200.
pub const DOUBLING_UNITS_PER_CUBE: f64 = 2.0;

/// What an analysis costs once, besides its steps: its expressions' parses (every
/// analysis compiles the model: a synthesis point too) and, for a time-invariant
/// model, the doublings of the stationary solution ([`crate::numerics::riccati::doublings_for`]).
/// Without them a model of many expressions, or N = 200 with few steps, ran 100 to
/// 1000 times its estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnalysisOnce {
    pub n: usize,
    /// Distinct expression texts per member (0 where the model's texts are not known).
    pub parses: usize,
    /// The doublings at most (0 for a time-varying model).
    pub doublings: u32,
}

impl AnalysisOnce {
    pub fn of(compiled: &CompiledModel, model: Option<&Model>) -> AnalysisOnce {
        AnalysisOnce {
            n: compiled.n_states(),
            parses: model.map_or(0, expression_texts),
            doublings: if compiled.is_time_invariant() {
                crate::numerics::riccati::doublings_for(compiled.max_steps())
            } else {
                0
            },
        }
    }

    pub fn units(&self) -> f64 {
        let cube = (self.n as f64).powi(3);
        self.parses as f64 * PARSE_UNITS
            + f64::from(self.doublings) * (DOUBLING_UNITS_PER_CUBE * cube + 1000.0)
    }

    /// E.g. "40000 expressions parsed, 4 doublings of the stationary solution".
    pub fn explain(&self) -> String {
        let mut parts = Vec::new();
        if self.parses > 0 {
            parts.push(format!(
                "{} expression{} parsed",
                self.parses,
                if self.parses == 1 { "" } else { "s" }
            ));
        }
        if self.doublings > 0 {
            parts.push(format!(
                "{} doublings of the stationary solution",
                self.doublings
            ));
        }
        parts.join(", ")
    }
}

/// The distinct expression texts of each of a model's members that take them (a
/// matrix's entries with one text are parsed once).
fn expression_texts(model: &Model) -> usize {
    fn distinct<'a>(values: impl Iterator<Item = &'a Value>) -> usize {
        let mut seen = HashSet::new();
        values
            .filter(|v| matches!(v, Value::Expr(s) if seen.insert(s.as_str())))
            .count()
    }
    let (sys, meas) = (&model.system, &model.measurement);
    let matrices = [
        Some(&sys.a),
        Some(&sys.b),
        sys.w.as_ref(),
        Some(&meas.c),
        meas.gamma.as_ref(),
        meas.g.as_ref(),
        meas.v.as_ref(),
    ];
    let vectors = [&sys.u, &sys.y0, &sys.eta0, &sys.phi, &meas.psi];
    let whens = meas.schedule.iter().flatten().flatten();
    matrices
        .into_iter()
        .flatten()
        .map(|m| distinct(m.iter().flatten()))
        .chain(vectors.into_iter().flatten().map(|v| distinct(v.iter())))
        .sum::<usize>()
        + distinct(whens.filter_map(|s| s.when.as_ref()))
}

/// How much work an analysis is, before running it (for limits and scheduling).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct WorkEstimate {
    /// Steps D (for `"auto"`: the cap, the worst case).
    pub steps: u64,
    /// State dimension N.
    pub states: usize,
    /// steps × [`step_cost`]`(N)`.
    pub work: f64,
}

/// The cost of one analysis step of an N-state model, N³ + 16 N² + 200: the Riccati
/// recursion's N³ multiply-adds, plus what every step pays per state (criteria, the
/// bound, the traces) and per step whatever N is. One unit is ≈ 1 ns on the reference
/// machine (measured, time-invariant chain, shortcut off: N = 1 195 ns per step against
/// 217 units, N = 3 572 against 371, N = 10 2 576 against 2 800, N = 30 29 µs
/// against 41 600); a bare N³ counted a one-state step as 1 unit, 200 times too little.
pub fn step_cost(n: usize) -> f64 {
    let n = n as f64;
    n * n * n + 16.0 * n * n + 200.0
}

/// Estimate the work of a model without running it. Validates the model.
pub fn estimate_work(model: &Model, set: &Overrides) -> Result<WorkEstimate, Error> {
    let compiled = crate::model::compile(model, set)?;
    let n = compiled.n_states();
    let steps = compiled.max_steps();
    Ok(WorkEstimate {
        steps,
        states: n,
        work: steps as f64 * step_cost(n),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::work::fitting;

    /// A chain of 100 powers was estimated at 997 units a step (its characters)
    /// against 6.5 µs; its calls now count 6000, near pow's ≈ 56 ns a call.
    #[test]
    fn calls_count_powers_and_functions_by_their_cost() {
        assert_eq!(call_units("2*t + 1"), 0);
        assert_eq!(call_units("t^2"), 60);
        assert_eq!(call_units("0.3*sin(2*t) + exp (t)"), 24);
        assert_eq!(call_units("cos(t)*ln(t)/cbrt(t)"), 75);
        assert_eq!(call_units("sqrt(abs(t))"), 0);
        // A parameter is not a call; a name is a call only before "(".
        assert_eq!(call_units("sin_f*t + tanh((t))"), 25);
        let chain = (0..100).fold("(1+t)".to_string(), |e, _| format!("({e})^1.01"));
        assert_eq!(call_units(&chain), 6000);
    }
    use crate::model::Overrides;

    #[test]
    fn fitting_counts_whole_items_from_one_to_the_cap() {
        assert_eq!(fitting(100.0, 30.0, 10), 3);
        assert_eq!(fitting(100.0, 1.0, 10), 10);
        assert_eq!(fitting(100.0, 300.0, 10), 1);
        assert_eq!(fitting(100.0, f64::NAN, 10), 1);
        assert_eq!(fitting(100.0, 0.0, 10), 10);
    }

    fn model(json: serde_json::Value) -> (Model, CompiledModel) {
        let m = crate::model::model_from_value(json).unwrap();
        let c = crate::model::compile::compile(&m, &Overrides::new()).unwrap();
        (m, c)
    }

    /// Two states, two noise sources of each kind; `b` and `gamma` given.
    fn two_states(b: serde_json::Value, gamma: serde_json::Value) -> serde_json::Value {
        serde_json::json!({
            "params": {"k": 2},
            "time": {"t0": 0, "t_end": 1, "steps": 1000},
            "system": {"states": ["x", "v"], "a": [[0, 1], [0, 0]], "b": b, "phi": [1, 1]},
            "measurement": {"names": ["z"], "c": [[1, 0]], "gamma": gamma, "psi": [1, 1]}
        })
    }

    #[test]
    fn a_constant_model_costs_the_engine_step() {
        let (m, c) = model(two_states(
            serde_json::json!([[0, "k"], [1, 0]]),
            serde_json::json!([[1, 0.5]]),
        ));
        let step = AnalysisStep::of(&c, Some(&m));
        assert_eq!(step.inputs, 0.0);
        assert_eq!(step.expressions, Expressions::default());
        assert_eq!(step.units(), crate::analysis::work::step_cost(2));
    }

    #[test]
    fn varying_inputs_cost_their_products_and_expressions_their_length() {
        // b(t): two entries share one text, the third is another; Γ constant.
        let (m, c) = model(two_states(
            serde_json::json!([["sin(t)", "sin(t)"], ["k*t", 0]]),
            serde_json::json!([[1, 0.5]]),
        ));
        let step = AnalysisStep::of(&c, Some(&m));
        let (n, l) = (2.0, 2.0);
        assert_eq!(
            step.inputs,
            n * l * l / 4.0 + n * (n + 1.0) / 2.0 * l + 2.0 * n * l
        );
        let e = step.expressions;
        assert_eq!((e.distinct, e.chars, e.entries, e.calls), (2, 6 + 3, 3, 12));
        assert_eq!(e.units(), (10 * 2 + 9 + 2 * 3 + 12) as f64);
        // Without the texts, every varying entry is an expression of 20 characters.
        let blind = Expressions::of(&c, None);
        assert_eq!((blind.distinct, blind.chars, blind.entries), (3, 60, 3));
    }

    #[test]
    fn a_varying_noise_matrix_and_a_schedule_cost_their_factorisation() {
        let mut json = two_states(
            serde_json::json!([[0, 1], [1, 0]]),
            serde_json::json!([["1 + t", 0.5]]),
        );
        json["measurement"]["schedule"] = serde_json::json!([{"when": "sin(t)"}]);
        let (m, c) = model(json);
        let step = AnalysisStep::of(&c, Some(&m));
        let (n, nm, ms) = (2.0, 1.0, 2.0);
        let rv_factor = nm * nm * nm / 3.0 + nm * nm * n / 2.0;
        assert_eq!(
            step.inputs,
            nm * ms * ms / 4.0
                + nm * (nm + 1.0) / 2.0 * ms
                + 2.0 * nm * ms
                + rv_factor
                + nm * n
                + rv_factor
        );
        let e = step.expressions;
        assert_eq!((e.distinct, e.chars, e.whens, e.when_chars), (1, 5, 1, 6));
        assert!(
            step.explain()
                .contains("2 expressions in t (11 characters, calls 12)")
        );
    }

    /// Once per analysis: every distinct expression text of a member is parsed (the
    /// constant `k` too, `sin(t)` once for its two entries of b, the schedule's
    /// `when`), and a time-invariant model's stationary solution takes up to
    /// ⌈log₂ D⌉ + 4 doublings; a time-varying one takes none.
    #[test]
    fn an_analysis_costs_its_parses_and_doublings_once() {
        assert_eq!(
            [1, 2, 3, 1000, 1024, 1025, 1_000_000, u64::MAX]
                .map(crate::numerics::riccati::doublings_for),
            [4, 5, 6, 14, 14, 15, 24, 68]
        );
        let (m, c) = model(two_states(
            serde_json::json!([[0, "k"], [1, 0]]),
            serde_json::json!([[1, 0.5]]),
        ));
        let once = AnalysisOnce::of(&c, Some(&m));
        assert_eq!((once.parses, once.doublings), (1, 14));
        let work = analysis_work(&c, Some(&m));
        let doubling = 2.0 * 8.0 + 1000.0;
        assert_eq!(
            work.units,
            1000.0 * crate::analysis::work::step_cost(2) + PARSE_UNITS + 14.0 * doubling
        );
        assert!(
            work.explain.ends_with(&format!(
                " + once {:.0} (1 expression parsed, 14 doublings of the stationary solution)",
                PARSE_UNITS + 14.0 * doubling
            )),
            "{}",
            work.explain
        );

        let mut json = two_states(
            serde_json::json!([["sin(t)", "sin(t)"], ["k*t", 0]]),
            serde_json::json!([[1, "k/2"]]),
        );
        json["measurement"]["schedule"] = serde_json::json!([{"when": "sin(t)"}]);
        let (m, c) = model(json);
        let once = AnalysisOnce::of(&c, Some(&m));
        assert_eq!((once.parses, once.doublings), (4, 0));
        assert_eq!(AnalysisOnce::of(&c, None).parses, 0);
    }
}
