//! Matrix entries as numbers or expressions in `t` and the model's params.
//!
//! Expressions are parsed once with exmex; entries that do not depend on `t` are
//! evaluated once at compile time, so only the time-varying entries cost anything
//! per step. The analysis steps through a time grid and evaluates them for
//! [`LANES`] grid points at a time (`TimeMatrix::update_grid`, `expr_block`), which
//! spreads exmex's interpretation cost over the lanes (BENCHMARKS.md).

use crate::error::FieldError;
use crate::expr_block::{Block, BlockEx, LANES, ScalarEx};
use crate::model::Value;
use exmex::prelude::*;
use std::collections::{BTreeMap, HashMap};

/// Names that are functions or constants in expressions, not parameters: every named
/// entry of the operator table (`expr_block::ScalarOps`), so that a name the parser
/// knows can never pass for a parameter (a param `e` would otherwise be silently read
/// as Euler's number).
fn reserved() -> &'static [&'static str] {
    static NAMES: std::sync::OnceLock<Vec<&'static str>> = std::sync::OnceLock::new();
    NAMES.get_or_init(|| {
        <crate::expr_block::ScalarOps as exmex::MakeOperators<f64>>::make()
            .iter()
            .map(|op| op.repr())
            .filter(|r| r.chars().all(|c| c.is_alphanumeric() || c == '_'))
            .collect()
    })
}

/// Whether `name` is a function or constant of the expression language.
pub fn is_reserved(name: &str) -> bool {
    reserved().contains(&name)
}

/// A time-varying scalar: compiled expression plus its variable vector, and the
/// same expression parsed over blocks of [`LANES`] time points (`expr_block`).
#[derive(Clone, Debug)]
pub struct TimeFn {
    expr: ScalarEx,
    /// Values of the expression's variables in exmex's (alphabetical) order.
    vars: Vec<f64>,
    /// Index of `t` in `vars`.
    t_slot: usize,
    /// The block form of `expr`'s text with its variables, parsed on the first
    /// `eval_block`: a parsed exmex expression is ≈ 20 KB (its nodes are inline), so
    /// only the copy an analysis steps with carries the second one.
    block: Option<Box<(BlockEx, Vec<Block>)>>,
}

impl TimeFn {
    #[inline]
    pub fn eval(&mut self, t: f64) -> f64 {
        self.vars[self.t_slot] = t;
        // Errors cannot happen after a successful parse with the right variable count;
        // NaN makes the caller's finiteness check fire with the entry's path.
        self.expr.eval(&self.vars).unwrap_or(f64::NAN)
    }

    /// The values at LANES time points, each equal to `eval` at that point.
    #[inline]
    pub fn eval_block(&mut self, t: [f64; LANES]) -> [f64; LANES] {
        if self.block.is_none() {
            // `compile_entry` checked that the text parses over blocks.
            let Ok(ex) = BlockEx::parse(self.expr.unparse()) else {
                return [f64::NAN; LANES];
            };
            let vars = self.vars.iter().map(|&v| Block([v; LANES])).collect();
            self.block = Some(Box::new((ex, vars)));
        }
        let Some(block) = self.block.as_deref_mut() else {
            return [f64::NAN; LANES];
        };
        let (ex, vars) = block;
        vars[self.t_slot] = Block(t);
        ex.eval(vars).map_or([f64::NAN; LANES], |b| b.0)
    }
}

/// One compiled entry. A `TimeFn` is large (exmex keeps its nodes inline), so it is
/// boxed: matrices of mostly constant entries then move pointers, not kilobytes.
#[derive(Clone, Debug)]
pub enum Entry {
    Const(f64),
    Time(Box<TimeFn>),
}

/// Compile one entry at `path`. `allow_t` false: `t` is an error (constant fields).
pub fn compile_entry(
    value: &Value,
    params: &BTreeMap<String, f64>,
    path: &str,
    allow_t: bool,
    t_probe: f64,
) -> Result<Entry, FieldError> {
    let text = match value {
        Value::Number(x) => {
            return if x.is_finite() {
                Ok(Entry::Const(*x))
            } else {
                Err(FieldError::new(path, "expected a finite number"))
            };
        }
        Value::Expr(s) => s.as_str(),
    };
    if text.trim().is_empty() {
        return Err(FieldError::new(
            path,
            "empty expression: expected a number or an expression such as \"-s/m\"",
        ));
    }
    let chars = text.chars().count();
    if chars > MAX_EXPRESSION_CHARS {
        return Err(FieldError::new(
            path,
            format!("expression of {chars} characters; the limit is {MAX_EXPRESSION_CHARS}"),
        ));
    }
    check_identifiers(text, params, path, allow_t)?;
    let plain = unary_minus_binds_loosely(&expand_exponents(text));
    let expr = ScalarEx::parse(&plain).map_err(|e| {
        FieldError::new(
            path,
            format!(
                "cannot parse expression \"{text}\": {}",
                describe(&e.to_string())
            ),
        )
    })?;
    let mut vars = Vec::with_capacity(expr.var_names().len());
    let mut t_slot = None;
    for (i, name) in expr.var_names().iter().enumerate() {
        if name == "t" {
            t_slot = Some(i);
            vars.push(t_probe);
        } else if let Some(v) = params.get(name.as_str()) {
            vars.push(*v);
        } else {
            return Err(unknown(text, name, params, path, allow_t));
        }
    }
    let value = expr
        .eval(&vars)
        .map_err(|e| FieldError::new(path, format!("cannot evaluate \"{text}\": {e}")))?;
    match t_slot {
        None => {
            if value.is_finite() {
                Ok(Entry::Const(value))
            } else {
                Err(FieldError::new(
                    path,
                    format!("\"{text}\" evaluates to {value}; expected a finite number"),
                ))
            }
        }
        Some(t_slot) => {
            // The same text over blocks parses whenever the f64 parse did (the
            // operator sets are the same, `expr_block`'s test); checked here so that
            // the lazy parse in `eval_block` cannot fail.
            BlockEx::parse(&plain).map_err(|e| {
                FieldError::new(path, format!("cannot parse expression \"{text}\": {e}"))
            })?;
            Ok(Entry::Time(Box::new(TimeFn {
                expr,
                vars,
                t_slot,
                block: None,
            })))
        }
    }
}

/// Compile an entry that must be a constant number (params allowed, `t` not).
pub fn compile_const(
    value: &Value,
    params: &BTreeMap<String, f64>,
    path: &str,
) -> Result<f64, FieldError> {
    match compile_entry(value, params, path, false, 0.0)? {
        Entry::Const(x) => Ok(x),
        Entry::Time(_) => Err(FieldError::new(path, "must not depend on t")),
    }
}

/// exmex's number literals have no exponent: rewrite `1.5e-5` as a plain decimal
/// (Rust prints f64 without an exponent, exactly round-tripping).
fn expand_exponents(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < b.len() {
        let starts_number = (b[i].is_ascii_digit() || b[i] == b'.')
            && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'));
        if !starts_number {
            out.push(text[i..].chars().next().unwrap());
            i += text[i..].chars().next().unwrap().len_utf8();
            continue;
        }
        let start = i;
        while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
            i += 1;
        }
        let mut end = i;
        if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
            let mut j = i + 1;
            if j < b.len() && (b[j] == b'+' || b[j] == b'-') {
                j += 1;
            }
            let digits = j;
            while j < b.len() && b[j].is_ascii_digit() {
                j += 1;
            }
            if j > digits {
                end = j;
            }
        }
        let lit = &text[start..end];
        match lit.parse::<f64>() {
            Ok(x) if end > i && x.is_finite() => out.push_str(&format!("{x}")),
            _ => out.push_str(lit),
        }
        i = end;
    }
    out
}

/// exmex binds a unary minus tighter than `^` (`-x^2` = 9 at x = 3); mathematics and
/// most languages bind it looser (`-x^2` = −9). Rewrite a unary minus as `(-1)*`, except
/// directly after `^` (`x^-2` stays x^(−2)).
fn unary_minus_binds_loosely(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 8);
    let mut prev: Option<char> = None;
    for c in text.chars() {
        if c == '-' {
            let unary = matches!(prev, None | Some('(' | ',' | '+' | '-' | '*' | '/'));
            if unary {
                out.push_str("(-1)*");
                prev = Some('*');
                continue;
            }
        }
        out.push(c);
        if !c.is_whitespace() {
            prev = Some(c);
        }
    }
    out
}

/// exmex's messages can carry Debug dumps of its internals: keep the readable part.
fn describe(msg: &str) -> String {
    let msg = msg.trim();
    if msg.starts_with("we have") && msg.contains("ops and") {
        return "an operator or an operand is missing (e.g. \"2 3\" or \"2*\")".to_string();
    }
    let cut = [", Operator {", " Operator {", "{"]
        .iter()
        .filter_map(|p| msg.find(p))
        .min()
        .unwrap_or(msg.len());
    let short = msg[..cut].trim_end_matches([',', ' ']);
    if short.is_empty() {
        "not a valid expression".to_string()
    } else {
        short.to_string()
    }
}

/// Scan identifiers ourselves so that an unknown name is reported with its position
/// (exmex would silently take it as a variable).
fn check_identifiers(
    text: &str,
    params: &BTreeMap<String, f64>,
    path: &str,
    allow_t: bool,
) -> Result<(), FieldError> {
    let mut depth: i64 = 0;
    let chars: Vec<(usize, char)> = text.char_indices().collect();
    let mut i = 0;
    while i < chars.len() {
        let (pos, c) = chars[i];
        if c == '(' {
            depth += 1;
        } else if c == ')' {
            depth -= 1;
            if depth < 0 {
                return Err(FieldError::new(
                    path,
                    format!(
                        "unbalanced ')' at position {} in \"{text}\"",
                        char_pos(text, pos) + 1
                    ),
                ));
            }
        }
        if c.is_alphabetic() || c == '_' {
            // A number's exponent (1e-5) is not an identifier.
            let in_number = i > 0 && {
                let (_, p) = chars[i - 1];
                (c == 'e' || c == 'E') && (p.is_ascii_digit() || p == '.')
            };
            let start = i;
            while i < chars.len() && (chars[i].1.is_alphanumeric() || chars[i].1 == '_') {
                i += 1;
            }
            if in_number {
                continue;
            }
            let name: String = chars[start..i].iter().map(|(_, c)| *c).collect();
            if is_reserved(&name) || params.contains_key(&name) {
                continue;
            }
            if name == "t" {
                if allow_t {
                    continue;
                }
                return Err(FieldError::new(
                    path,
                    format!("\"{text}\" depends on t, but this field must be constant"),
                ));
            }
            let mut e = unknown(text, &name, params, path, allow_t);
            e.message = format!(
                "{} (at position {})",
                e.message,
                char_pos(text, chars[start].0) + 1
            );
            return Err(e);
        }
        i += 1;
    }
    if depth > 0 {
        return Err(FieldError::new(
            path,
            format!("unbalanced '(' in \"{text}\": {depth} not closed"),
        ));
    }
    Ok(())
}

fn char_pos(text: &str, byte: usize) -> usize {
    text[..byte].chars().count()
}

fn unknown(
    text: &str,
    name: &str,
    params: &BTreeMap<String, f64>,
    path: &str,
    allow_t: bool,
) -> FieldError {
    // A model may define thousands of params: list a few, not all of them.
    const LISTED: usize = 12;
    let all = params.len() + usize::from(allow_t);
    let names = allow_t
        .then_some("t")
        .into_iter()
        .chain(params.keys().map(String::as_str))
        .take(LISTED)
        .collect::<Vec<_>>()
        .join(", ");
    let known = match all {
        0 => "no params are defined".to_string(),
        1..=LISTED => format!("known: {names}"),
        _ => format!("known: {names}, … ({all} names in all)"),
    };
    FieldError::new(
        path,
        format!("unknown parameter \"{name}\" in \"{text}\" ({known})"),
    )
}

/// The longest expression text, in characters. exmex's parse time grows faster than
/// linearly for some shapes (a product of many parenthesised negations: 10 000
/// characters 0.26 s, 40 000 characters 5.9 s), so texts are bounded before parsing.
pub const MAX_EXPRESSION_CHARS: usize = 1000;

/// The most distinct time-dependent expressions one model may have, and their total
/// length. A parsed expression takes ≈ 20 KB plus ≈ 1.2 KB per character with the
/// analysis's 16-lane form (≈ 23 KB), so these bound a model's expressions to
/// ≈ 150 MB. Entries of one matrix with the same text share one parse and count once;
/// the measurement schedule's `when` expressions count too.
pub const MAX_TIME_EXPRESSIONS: usize = 2000;
pub const MAX_TIME_EXPRESSION_CHARS: usize = 50_000;

/// What a model's distinct time-dependent expressions use of the limits above.
#[derive(Clone, Copy, Debug, Default)]
pub struct ExprBudget {
    count: usize,
    chars: usize,
    /// A limit was exceeded (reported once; the rest of the model is not parsed).
    exceeded: bool,
}

impl ExprBudget {
    /// A limit was exceeded (the model is refused; what follows need not be parsed).
    pub(crate) fn is_exceeded(&self) -> bool {
        self.exceeded
    }

    /// Take one time-dependent entry (its text's characters), or say which limit it
    /// exceeds.
    pub(crate) fn take(&mut self, entry: &Value) -> Result<(), String> {
        let chars = match entry {
            Value::Expr(text) => text.chars().count(),
            Value::Number(_) => 0,
        };
        let why = if self.count >= MAX_TIME_EXPRESSIONS {
            format!(
                "more than {MAX_TIME_EXPRESSIONS} distinct time-dependent expressions in one model (the limit: each costs ≈ 45 KB)"
            )
        } else if self.chars + chars > MAX_TIME_EXPRESSION_CHARS {
            format!(
                "the model's distinct time-dependent expressions exceed {MAX_TIME_EXPRESSION_CHARS} characters in total (the limit: each character costs ≈ 1.2 KB parsed)"
            )
        } else {
            self.count += 1;
            self.chars += chars;
            return Ok(());
        };
        self.exceeded = true;
        Err(format!(
            "{why}; entries of one matrix with the same text count once"
        ))
    }
}

/// A matrix (row-major) whose entries may vary with time.
#[derive(Clone, Debug)]
pub struct TimeMatrix {
    pub rows: usize,
    pub cols: usize,
    /// Current values, row-major; constant entries are set once.
    pub values: Vec<f64>,
    /// (flat index, index into `fns`, path) of each time-varying entry, by index.
    varying: Vec<(usize, usize, String)>,
    /// The distinct time-dependent expressions (entries with one text share one).
    fns: Vec<TimeFn>,
    /// `update_grid`'s cache: the grid (t0, Δt bits), the first grid index held,
    /// and LANES values of each of `fns`.
    block_grid: Option<(u64, u64, u64)>,
    block_values: Vec<[f64; LANES]>,
}

impl TimeMatrix {
    pub fn constant(rows: usize, cols: usize, values: Vec<f64>) -> Self {
        debug_assert_eq!(values.len(), rows * cols);
        TimeMatrix {
            rows,
            cols,
            values,
            varying: Vec::new(),
            fns: Vec::new(),
            block_grid: None,
            block_values: Vec::new(),
        }
    }

    pub fn is_constant(&self) -> bool {
        self.varying.is_empty()
    }

    /// Whether entry `i` (flat, row-major) depends on t.
    pub fn varies(&self, i: usize) -> bool {
        self.varying.binary_search_by_key(&i, |v| v.0).is_ok()
    }

    /// Re-evaluate the time-varying entries at the grid point t = t0 + i·Δt — the
    /// same t, and the same values, as `TimeFn::eval(t0 + i as f64 * dt)` — evaluating
    /// LANES consecutive grid points at a time: for stepping through a grid in order.
    /// Err((path, t)) if one is not finite at this point.
    #[inline]
    pub fn update_grid(&mut self, t0: f64, dt: f64, i: u64) -> Result<(), (&str, f64)> {
        let grid = (t0.to_bits(), dt.to_bits());
        let lane = match self.block_grid {
            Some((g0, gd, first)) if (g0, gd) == grid && i >= first && i - first < LANES as u64 => {
                (i - first) as usize
            }
            _ => {
                let ts: [f64; LANES] = std::array::from_fn(|l| t0 + (i + l as u64) as f64 * dt);
                for (f, out) in self.fns.iter_mut().zip(&mut self.block_values) {
                    *out = f.eval_block(ts);
                }
                self.block_grid = Some((grid.0, grid.1, i));
                0
            }
        };
        for (idx, f, path) in &self.varying {
            let v = self.block_values[*f][lane];
            if !v.is_finite() {
                return Err((path.as_str(), t0 + i as f64 * dt));
            }
            self.values[*idx] = v;
        }
        Ok(())
    }
}

/// Compiles a [`TimeMatrix`] entry by entry, in row-major order. Entries with the
/// same expression text are compiled once and share the result: a model that
/// repeats `"0.3*sin(2*t)"` over a 200 × 200 matrix parses it once and evaluates it
/// once per step.
#[derive(Debug)]
pub struct TimeMatrixBuilder {
    m: TimeMatrix,
    by_text: HashMap<String, Shared>,
}

#[derive(Clone, Copy, Debug)]
enum Shared {
    Const(f64),
    Fn(usize),
}

impl TimeMatrixBuilder {
    pub fn new(rows: usize, cols: usize) -> Self {
        TimeMatrixBuilder {
            m: TimeMatrix::constant(rows, cols, vec![0.0; rows * cols]),
            by_text: HashMap::new(),
        }
    }

    /// Compile entry `i` (flat, row-major; after every entry before it) at `path`.
    /// `budget`: what the model's distinct time-dependent expressions have used so
    /// far (see [`MAX_TIME_EXPRESSIONS`]). On error the entry stays 0.
    pub fn set(
        &mut self,
        i: usize,
        value: &Value,
        params: &BTreeMap<String, f64>,
        path: String,
        t0: f64,
        budget: &mut ExprBudget,
    ) -> Result<(), FieldError> {
        debug_assert!(self.m.varying.last().is_none_or(|v| v.0 < i));
        let text = match value {
            Value::Expr(s) => Some(s.as_str()),
            Value::Number(_) => None,
        };
        let shared = match text.and_then(|s| self.by_text.get(s)) {
            Some(&s) => s,
            // Past a limit (reported once, at the first entry beyond it): the model is
            // refused, so the rest of it is not parsed.
            None if budget.exceeded => return Ok(()),
            None => {
                let s = match compile_entry(value, params, &path, true, t0)? {
                    Entry::Const(x) => Shared::Const(x),
                    Entry::Time(f) => {
                        budget
                            .take(value)
                            .map_err(|why| FieldError::new(&path, why))?;
                        self.m.fns.push(*f);
                        Shared::Fn(self.m.fns.len() - 1)
                    }
                };
                if let Some(text) = text {
                    self.by_text.insert(text.to_string(), s);
                }
                s
            }
        };
        match shared {
            Shared::Const(x) => self.m.values[i] = x,
            Shared::Fn(f) => self.m.varying.push((i, f, path)),
        }
        Ok(())
    }

    pub fn finish(self) -> TimeMatrix {
        let mut m = self.m;
        m.block_values = vec![[0.0; LANES]; m.fns.len()];
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2 × 2 matrix: two entries share `text`, one is constant, one is `other`.
    fn grid_matrix(text: &str, other: &str) -> TimeMatrix {
        let mut b = TimeMatrixBuilder::new(2, 2);
        let mut budget = ExprBudget::default();
        for (i, v) in [text, "s/m", other, text].iter().enumerate() {
            b.set(
                i,
                &(*v).into(),
                &params(),
                format!("x[{i}]"),
                0.0,
                &mut budget,
            )
            .unwrap();
        }
        b.finish()
    }

    #[test]
    fn update_grid_equals_one_point_evaluation_in_any_order() {
        let (text, other) = ("0.3*sin(2*t)+m*t^2", "exp(-t/s)");
        let mut m = grid_matrix(text, other);
        assert_eq!(m.fns.len(), 2, "entries 0 and 3 share one parse");
        let eval = |e: &str, t: f64| match compile_entry(&e.into(), &params(), "p", true, 0.0) {
            Ok(Entry::Time(mut f)) => f.eval(t),
            _ => panic!("time-varying"),
        };
        // In order, backwards, across block edges, and on a second grid.
        let visits = (0..40u64)
            .chain([39, 3, 16, 15, 0, 33])
            .map(|i| (0.5, 1e-3, i));
        for (t0, dt, i) in visits.chain((0..20).map(|i| (0.0, 0.37, i))) {
            m.update_grid(t0, dt, i).unwrap();
            let t = t0 + i as f64 * dt;
            assert_eq!(m.values[0].to_bits(), eval(text, t).to_bits(), "t = {t}");
            assert_eq!(m.values[3].to_bits(), m.values[0].to_bits());
            assert_eq!(m.values[2].to_bits(), eval(other, t).to_bits(), "t = {t}");
            assert_eq!(m.values[1], 37.17 / 100.0);
        }
    }

    #[test]
    fn update_grid_names_the_first_entry_that_is_not_finite() {
        // Both entries of `ln(2.5 - t)` fail from t = 2.5: the first (row-major) is named.
        let mut m = grid_matrix("ln(2.5-t)", "t");
        m.update_grid(0.0, 0.5, 4).unwrap();
        assert_eq!(m.update_grid(0.0, 0.5, 5), Err(("x[0]", 2.5)));
    }

    fn params() -> BTreeMap<String, f64> {
        [("m".to_string(), 100.0), ("s".to_string(), 37.17)]
            .into_iter()
            .collect()
    }

    #[test]
    fn constant_expressions_fold() {
        let e = compile_entry(&"-s/m".into(), &params(), "a[0][0]", true, 0.0).unwrap();
        match e {
            Entry::Const(x) => assert_eq!(x, -37.17 / 100.0),
            _ => panic!("expected a constant"),
        }
    }

    #[test]
    fn time_expressions_evaluate() {
        let e = compile_entry(&"0.3*sin(2*t)+m".into(), &params(), "p", true, 0.0).unwrap();
        let Entry::Time(mut f) = e else {
            panic!("expected time-varying")
        };
        assert!((f.eval(0.7) - (0.3 * (1.4f64).sin() + 100.0)).abs() < 1e-12);
    }

    /// The binary functions and every constant pass the identifier check and
    /// evaluate to their values (they were once rejected as unknown parameters).
    #[test]
    fn binary_functions_and_constants_are_known() {
        let e = compile_entry(
            &"atan2(t, 2) + min(t, s) + max(t, m) + e + E + PI + π + TAU + τ".into(),
            &params(),
            "p",
            true,
            0.0,
        )
        .unwrap();
        let Entry::Time(mut f) = e else {
            panic!("expected time-varying")
        };
        let t = 0.7f64;
        let want = t.atan2(2.0)
            + t.min(37.17)
            + t.max(100.0)
            + 2.0 * std::f64::consts::E
            + 2.0 * std::f64::consts::PI
            + 2.0 * std::f64::consts::TAU;
        assert!((f.eval(t) - want).abs() < 1e-12, "{} vs {want}", f.eval(t));
        for name in [
            "e", "E", "PI", "π", "TAU", "τ", "atan2", "min", "max", "sin", "log",
        ] {
            assert!(is_reserved(name), "{name}");
        }
        for name in ["t", "x", "sinh2", "mass", "+", "^"] {
            assert!(!is_reserved(name), "{name}");
        }
    }

    #[test]
    fn unknown_parameter_is_named_with_position() {
        let e =
            compile_entry(&"s/mass".into(), &params(), "system.a[0][0]", true, 0.0).unwrap_err();
        assert_eq!(e.path, "system.a[0][0]");
        assert!(
            e.message.contains("unknown parameter \"mass\""),
            "{}",
            e.message
        );
        assert!(e.message.contains("position 3"), "{}", e.message);
    }

    #[test]
    fn exponent_is_not_an_identifier() {
        let e = compile_entry(&"1e-5*m".into(), &params(), "p", true, 0.0).unwrap();
        assert!(matches!(e, Entry::Const(x) if (x - 1e-3).abs() < 1e-15));
    }

    #[test]
    fn unary_minus_binds_looser_than_power() {
        let p = params();
        let v = |s: &str| match compile_entry(&s.into(), &p, "p", true, 0.0).unwrap() {
            Entry::Const(x) => x,
            _ => panic!(),
        };
        assert_eq!(v("-2^2"), -4.0);
        assert_eq!(v("-(1+1)^2"), -4.0);
        assert_eq!(v("3*-2^2"), -12.0);
        assert_eq!(v("2^-1"), 0.5);
        assert_eq!(v("-m"), -100.0);
        assert_eq!(v("1 - -1"), 2.0);
        assert_eq!(v("2e-1*10"), 2.0);
    }

    #[test]
    fn t_in_constant_field_is_rejected() {
        let e = compile_const(&"m*t".into(), &params(), "measurement.c[0][0]").unwrap_err();
        assert!(e.message.contains("must be constant"), "{}", e.message);
    }

    #[test]
    fn parse_errors_are_reported() {
        let e = compile_entry(&"s*(m".into(), &params(), "p", true, 0.0).unwrap_err();
        assert!(e.message.contains("unbalanced"), "{}", e.message);
        let e = compile_entry(&"s**/m".into(), &params(), "p", true, 0.0).unwrap_err();
        assert!(e.message.contains("cannot parse"), "{}", e.message);
        assert!(!e.message.contains('{'), "no Debug dumps: {}", e.message);
        let e = compile_entry(&"2 3".into(), &params(), "p", true, 0.0).unwrap_err();
        assert!(e.message.contains("missing"), "{}", e.message);
    }

    #[test]
    fn non_finite_is_rejected() {
        let e = compile_entry(&"1/0".into(), &params(), "p", true, 0.0).unwrap_err();
        assert!(e.message.contains("finite"), "{}", e.message);
    }
}
