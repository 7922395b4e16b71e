//! Matrix entries as numbers or expressions in `t` and the model's params.
//!
//! Expressions are parsed once with exmex; entries that do not depend on `t` are
//! evaluated once at compile time, so only the time-varying entries cost anything
//! per step. The analysis steps through a time grid and evaluates them for
//! [`LANES`] grid points at a time (`TimeMatrix::update_grid`, `expr_block`), which
//! spreads exmex's interpretation cost over the lanes (BENCHMARKS.md).
//!
//! The language: numbers (`2`, `.5`, `1e-5`), `t`, the params, the constants
//! `PI π E e TAU τ`, `+ - * /`, `^` for a power, parentheses, and the functions of
//! `expr_block`'s operator table — one argument each, in parentheses (`sin(t)`, never
//! `sin t`), except `atan2(y, x)`, `min(a, b)` and `max(a, b)`. `translate` checks a
//! text before exmex sees it, so that each mistake is named with its position, and
//! gives it the meaning below, which is not always exmex's:
//!
//! - A sign applies to the power after it: `-x^2` is −(x²), `2/-3*4` is (2/(−3))·4,
//!   as in mathematics and Python. Operators of one rank go left to right: `a*b/c`
//!   is (a·b)/c and `a-b+c` is (a−b)+c, to the last bit.
//! - `a^b^c` without parentheses is an error that asks for `a^(b^c)` or `(a^b)^c`:
//!   Excel and MATLAB read it one way, mathematics and Python the other
//!   (`ambiguous_power`). `2^-3` is 2^(−3); an exponent belongs to its number, so
//!   `1e-5^2` is (1e-5)².
//! - There is no implicit multiplication: `2t` and `2(t+1)` are errors (write `2*t`).
//! - `log` is the natural logarithm, like `ln` (base 10 is `log10`, base 2 `log2`).
//! - `signum(x)` is the sign function of mathematics (numpy's and MATLAB's `sign`):
//!   −1, 0 or 1 (`signum(0)` is 0, not Rust's `f64::signum`'s 1).
//! - `round` rounds halves away from zero: `round(2.5)` is 3, `round(-2.5)` is −3.

use crate::error::FieldError;
use crate::expr::block::{Block, BlockEx, ScalarEx};
pub use value::Value;

/// Time points per evaluation.
pub const LANES: usize = 16;

pub mod block;
pub mod dual;
mod dual_lanes;
mod lex;
mod limits;
mod state_fn;
mod tape;
mod time_matrix;
mod translate;
mod trig;
mod value;
use exmex::prelude::*;
pub use limits::{
    ExprBudget, MAX_EXPRESSION_CHARS, MAX_TIME_EXPRESSION_CHARS, MAX_TIME_EXPRESSIONS,
};
pub use state_fn::StateFn;
use std::collections::BTreeMap;
use std::sync::Arc;
pub use time_matrix::{TimeMatrix, TimeMatrixBuilder};
use translate::{describe, translate, unknown};

/// The expression language's names, read off the operator table
/// (`expr_block::ScalarOps`): its constants, its one-argument functions and its
/// two-argument functions (atan2, min, max), in the table's order.
struct Language {
    constants: Vec<(&'static str, f64)>,
    unary: Vec<&'static str>,
    binary: Vec<&'static str>,
}

fn language() -> &'static Language {
    static LANGUAGE: std::sync::OnceLock<Language> = std::sync::OnceLock::new();
    LANGUAGE.get_or_init(|| {
        let mut lang = Language {
            constants: Vec::new(),
            unary: Vec::new(),
            binary: Vec::new(),
        };
        for op in <crate::expr::block::ScalarOps as exmex::MakeOperators<f64>>::make() {
            let name = op.repr();
            if !name.chars().all(|c| c.is_alphanumeric() || c == '_') {
                continue; // + - * / ^
            }
            if let Some(value) = op.constant() {
                lang.constants.push((name, value));
            } else if op.has_bin() {
                lang.binary.push(name);
            } else {
                lang.unary.push(name);
            }
        }
        lang
    })
}

/// Whether `name` is a function or constant of the expression language: every named
/// entry of the operator table, so that a name the parser knows can never pass for a
/// parameter (a param `e` would otherwise be silently read as Euler's number).
pub fn is_reserved(name: &str) -> bool {
    let lang = language();
    lang.constant(name).is_some() || lang.unary.contains(&name) || lang.binary.contains(&name)
}

/// Every name [`is_reserved`] refuses as a parameter: the language's constants and
/// functions (the web editor keeps a copy; a test compares them).
pub fn reserved_names() -> Vec<&'static str> {
    let lang = language();
    let constants = lang.constants.iter().map(|c| c.0);
    constants
        .chain(lang.unary.iter().copied())
        .chain(lang.binary.iter().copied())
        .collect()
}

impl Language {
    /// The value of the constant `name`.
    fn constant(&self, name: &str) -> Option<f64> {
        self.constants.iter().find(|c| c.0 == name).map(|c| c.1)
    }
}

/// A time-varying scalar: compiled expression plus its variable vector, and the
/// same expression parsed over blocks of [`LANES`] time points (`expr_block`). A
/// parsed exmex expression is ≈ 25 KB (its nodes are inline), so both parses are
/// shared by every copy (an analysis's, a synthesis point's): a copy, or a push into a
/// matrix's list, moves pointers, not kilobytes (2000 expressions took 60 ms of copies).
#[derive(Clone, Debug)]
pub struct TimeFn {
    expr: Arc<ScalarEx>,
    /// Values of the expression's variables in exmex's (alphabetical) order.
    vars: Vec<f64>,
    /// Index of `t` in `vars`.
    t_slot: usize,
    /// The block form, parsed with the scalar one (that parse is the check that it
    /// parses, so evaluating it cannot fail to).
    block: Arc<BlockEx>,
    /// Its variables (each value in every lane); empty until the first `eval_block`.
    block_vars: Vec<Block>,
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
        if self.block_vars.is_empty() {
            self.block_vars = self.vars.iter().map(|&v| Block([v; LANES])).collect();
        }
        self.block_vars[self.t_slot] = Block(t);
        self.block
            .eval(&self.block_vars)
            .map_or([f64::NAN; LANES], |b| b.0)
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
    let (plain, literals) = translate(text, params, path, allow_t)?;
    let expr = ScalarEx::parse(&plain).map_err(|e| cannot_parse(text, path, &e))?;
    let mut vars = Vec::with_capacity(expr.var_names().len());
    let mut t_slot = None;
    for (i, name) in expr.var_names().iter().enumerate() {
        let literal = name
            .strip_prefix('#')
            .and_then(|k| literals.get(k.parse::<usize>().ok()?));
        if name == "t" {
            t_slot = Some(i);
            vars.push(t_probe);
        } else if let Some(v) = literal {
            vars.push(*v);
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
            // operator sets are the same, `expr_block`'s test); checked all the same.
            let block = BlockEx::parse(&plain).map_err(|e| cannot_parse(text, path, &e))?;
            Ok(Entry::Time(Box::new(TimeFn {
                expr: Arc::new(expr),
                vars,
                t_slot,
                block: Arc::new(block),
                block_vars: Vec::new(),
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

/// exmex's refusal of a translated `text`, at `path`.
fn cannot_parse(text: &str, path: &str, e: &exmex::ExError) -> FieldError {
    FieldError::new(
        path,
        format!(
            "cannot parse expression \"{text}\": {}",
            describe(&e.to_string())
        ),
    )
}

/// A constant entry's value, bit for bit [`compile_const`]'s, and its exact partial
/// derivatives with respect to the params `wrt` (forward-mode dual numbers,
/// [`dual`]). Every name in `wrt` is a param. Bad entries give `compile_const`'s
/// errors; a derivative that is not finite (`sqrt(q)` at q = 0) is an error at `path`.
/// A number, or a text that does not name `wrt[i]`, has derivative 0 there, exactly.
pub fn compile_const_with_derivatives(
    value: &Value,
    params: &BTreeMap<String, f64>,
    wrt: &[&str],
    path: &str,
) -> Result<(f64, Vec<f64>), FieldError> {
    debug_assert!(
        wrt.iter().all(|name| params.contains_key(*name)),
        "{wrt:?} are not all params"
    );
    let x = compile_const(value, params, path)?;
    let mut derivatives = vec![0.0; wrt.len()];
    let Value::Expr(text) = value else {
        return Ok((x, derivatives));
    };
    let used = names(text);
    let (slots, directions): (Vec<usize>, Vec<&str>) = wrt
        .iter()
        .enumerate()
        .filter(|(_, name)| used.iter().any(|u| u == *name))
        .map(|(i, name)| (i, *name))
        .unzip();
    if directions.is_empty() {
        return Ok((x, derivatives));
    }
    let duals = dual::along(text, params, &directions, path)?;
    for ((slot, name), d) in slots.into_iter().zip(directions).zip(duals) {
        debug_assert_eq!(d.v.to_bits(), x.to_bits(), "{text}");
        if !d.d[0].is_finite() {
            return Err(FieldError::new(
                path,
                format!(
                    "the derivative of \"{text}\" with respect to {name} is not finite at {name} = {}",
                    params[name]
                ),
            ));
        }
        derivatives[slot] = d.d[0];
    }
    Ok((x, derivatives))
}

/// The names a text uses — params, `t`, constants, functions — each once, in the
/// order of their first use; none for a text that does not lex (its entry is an error
/// of its own). What a compiled entry owes to which param
/// ([`crate::model::params::ParamDependence`]).
pub fn names(text: &str) -> Vec<String> {
    let Ok(tokens) = lex::lex(text) else {
        return Vec::new();
    };
    let mut out: Vec<String> = Vec::new();
    for t in tokens.iter().filter(|t| t.tok == lex::Tok::Name) {
        let name = &text[t.start..t.end];
        if !out.iter().any(|o| o == name) {
            out.push(name.to_string());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two params, `m` and `s`, for the expressions' tests.
    pub(super) fn params() -> BTreeMap<String, f64> {
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
        // A sign applies to the power after it, not to what a '/' or '*' left of it
        // divides (a rewrite as `(-1)*` made `2/-3` −6 and `6/-2^2` −24).
        assert_eq!(v("2/-3"), 2.0 / -3.0);
        assert_eq!(v("2/-3*4"), 2.0 / -3.0 * 4.0);
        assert_eq!(v("6/-2^2"), -1.5);
        assert_eq!(v("2*-(3+4)/2"), -7.0);
        assert_eq!(v("-s/m"), -37.17 / 100.0);
        // Signs in a row, and after '^' (`2^--3` was 6).
        assert_eq!(v("2^--3"), 8.0);
        assert_eq!(v("-2^-3"), -0.125);
        assert_eq!(v("- -+-2"), -2.0);
        assert_eq!(v("-sin(1)^2"), -(libm::sin(1.0) * libm::sin(1.0)));
    }

    #[test]
    fn t_in_constant_field_is_rejected() {
        let e = compile_const(&"m*t".into(), &params(), "measurement.c[0][0]").unwrap_err();
        assert_eq!(e.path, "measurement.c[0][0]");
        assert_eq!(
            e.message,
            "\"m*t\" depends on t, but this field must be constant (t at position 3)"
        );
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

    /// The message of the error `text` gives (params m and s, `t` allowed).
    fn message(text: &str) -> String {
        match compile_entry(&text.into(), &params(), "p", true, 0.0) {
            Err(e) => {
                assert_eq!(e.path, "p");
                e.message
            }
            Ok(_) => panic!("{text} was accepted"),
        }
    }

    /// The value of a constant `text`.
    fn value(text: &str) -> f64 {
        match compile_entry(&text.into(), &params(), "p", true, 0.0) {
            Ok(Entry::Const(x)) => x,
            Ok(Entry::Time(_)) => panic!("{text} depends on t"),
            Err(e) => panic!("{text}: {}", e.message),
        }
    }

    /// `a^b^c` is rejected with both readings spelled out; parenthesised, either
    /// reading is what it says. It was left-associative (`2^3^2` = 64).
    #[test]
    fn power_chains_are_rejected_with_both_readings() {
        assert_eq!(
            message("2^3^2"),
            "cannot parse expression \"2^3^2\" at position 4: \"2^3^2\" is ambiguous: some tools read a^b^c as (a^b)^c (Excel, MATLAB), others as a^(b^c) (mathematics, Python, Julia); write 2^(3^2) or (2^3)^2"
        );
        assert!(
            message("2 ^ 3 ^ 2").contains("at position 7: \"2^3^2\" is ambiguous"),
            "{}",
            message("2 ^ 3 ^ 2")
        );
        // The operands as written: a sign belongs to b, a call or group is one operand.
        assert!(message("2^-3^2").ends_with("write 2^(-3^2) or (2^-3)^2"));
        assert!(message("-sin(t)^m^(1+s)").ends_with("write sin(t)^(m^(1+s)) or (sin(t)^m)^(1+s)"));
        assert!(message("2^(3)^2").contains("at position 6"));
        assert!(message("e^2^2").contains("ambiguous"));
        assert!(message("1 + 2^3^2^2").contains("at position 8"));
        assert_eq!(value("2^(3^2)"), 512.0);
        assert_eq!(value("(2^3)^2"), 64.0);
        assert_eq!(value("2^3*2^2"), 32.0);
        // An exponent belongs to its number: 1e-5^2 is (1e-5)², with one '^'.
        assert_eq!(value("1e-5^2").to_bits(), libm::pow(1e-5, 2.0).to_bits());
        assert_eq!(value("2^-3"), 0.125);
        assert_eq!(value("2^1e1"), 1024.0);
    }

    /// A wrong number of arguments names the function, the argument count and the
    /// ',' that begins one too many.
    #[test]
    fn argument_counts_are_named() {
        assert_eq!(
            message("min(1,2,3)"),
            "cannot parse expression \"min(1,2,3)\" at position 1: min(…) takes exactly two arguments; the ',' at position 8 begins a third (for three, nest them: min(a, min(b, c)))"
        );
        assert_eq!(
            message("log(2,8)"),
            "cannot parse expression \"log(2,8)\" at position 1: log(…) takes one argument; the ',' at position 6 begins a second (log is the natural logarithm, like ln; for the logarithm of x to base b write ln(x)/ln(b))"
        );
        assert_eq!(
            message("1 + sin(t, 2)"),
            "cannot parse expression \"1 + sin(t, 2)\" at position 5: sin(…) takes one argument; the ',' at position 10 begins a second"
        );
        assert_eq!(
            message("atan2(1)"),
            "cannot parse expression \"atan2(1)\" at position 1: atan2(…) takes exactly two arguments, got one: write atan2(a, b)"
        );
        assert_eq!(
            message("max()"),
            "cannot parse expression \"max()\" at position 1: max(…) takes exactly two arguments, got none"
        );
        assert_eq!(
            message("2*sqrt()"),
            "cannot parse expression \"2*sqrt()\" at position 3: sqrt(…) takes one argument, got none"
        );
        assert_eq!(
            message("min(1,)"),
            "cannot parse expression \"min(1,)\" at position 6: an argument is missing after the ','"
        );
        assert_eq!(
            message("min(,1)"),
            "cannot parse expression \"min(,1)\" at position 5: an argument is missing before the ','"
        );
        assert_eq!(
            message("(1,2)"),
            "cannot parse expression \"(1,2)\" at position 3: a ',' outside a function's arguments (only atan2, min, max take two)"
        );
        // exmex read `atan2(1 2)` as atan2(1, 2).
        assert!(message("atan2(1 2)").contains("at position 9: an operator is missing"));
    }

    /// A name followed by '(' that is no function is an unknown function, with the
    /// functions listed; a function without '(' is reported as such (exmex read
    /// `sin t^2` as (sin t)², and `sin+1` as sin(1)).
    #[test]
    fn functions_are_called_with_parentheses() {
        let pow = message("pow(2,3)");
        assert!(
            pow.starts_with(
                "unknown function \"pow\" in \"pow(2,3)\" (at position 1); for a power write a^b; the functions are abs, signum, sin,"
            ),
            "{pow}"
        );
        let lang = language();
        for name in lang.unary.iter().chain(&lang.binary) {
            assert!(
                pow.contains(&format!(" {name},")) || pow.ends_with(&format!(" {name}")),
                "{name}: {pow}"
            );
        }
        assert!(
            pow.ends_with("and with two arguments atan2, min, max"),
            "{pow}"
        );
        assert!(message("2*foo (t)").starts_with(
            "unknown function \"foo\" in \"2*foo (t)\" (at position 3); the functions are"
        ));
        assert_eq!(
            message("sin t^2"),
            "cannot parse expression \"sin t^2\" at position 1: sin is a function: write its argument in parentheses, as in sin(x)"
        );
        assert!(message("1 + sin+1").contains("at position 5: sin is a function"));
        assert!(message("max").contains("write its arguments in parentheses, as in max(a, b)"));
        // A param, t or a constant before '(' is a product without its '*'.
        assert_eq!(
            message("m(2)"),
            "cannot parse expression \"m(2)\" at position 2: an operator is missing between \"m\" and \"(2)\" (m is not a function): implicit multiplication is not supported; write m*(2)"
        );
        assert!(message("PI (t+1)").contains("at position 4: an operator is missing between \"PI\" and \"(t+1)\" (PI is not a function)"));
    }

    /// Two operands side by side: implicit multiplication is not supported.
    #[test]
    fn implicit_multiplication_is_reported() {
        assert_eq!(
            message("2(3)"),
            "cannot parse expression \"2(3)\" at position 2: an operator is missing between \"2\" and \"(3)\": implicit multiplication is not supported; write 2*(3)"
        );
        assert_eq!(
            message("2 3"),
            "cannot parse expression \"2 3\" at position 3: an operator is missing between \"2\" and \"3\": implicit multiplication is not supported; write 2*3"
        );
        assert!(message("1 + 2t").ends_with("at position 6: an operator is missing between \"2\" and \"t\": implicit multiplication is not supported; write 2*t"));
        assert!(message("(1+t)(2)").ends_with("write (1+t)*(2)"));
        assert!(message("2exp(1)").ends_with("write 2*exp(1)"));
        assert!(message("s^2 m").ends_with("write 2*m"));
    }

    #[test]
    fn malformed_and_overflowing_numbers_are_named() {
        assert_eq!(
            message("1e309"),
            "cannot parse expression \"1e309\" at position 1: the number 1e309 overflows f64 (the largest finite value is about 1.8e308)"
        );
        // Below the smallest f64 it was read as 0 without a word.
        assert_eq!(
            message("t*2.5e-400"),
            "cannot parse expression \"t*2.5e-400\" at position 3: the number 2.5e-400 is below the smallest f64 (≈ 4.9e-324) and would be read as 0: write 0 if 0 is meant"
        );
        assert!(compile_entry(&"t*0e-400 + 1e-320".into(), &params(), "p", true, 0.0).is_ok());
        let long = format!("t + 1{}", "0".repeat(400));
        assert!(message(&long).contains("at position 5: the number 1000"));
        assert_eq!(
            message("2*2e"),
            "cannot parse expression \"2*2e\" at position 3: malformed number \"2e\": an exponent needs digits, as in 2e3 (for 2 times Euler's number write 2*e)"
        );
        assert!(message("1.5e+ 2").contains("at position 1: malformed number \"1.5e+\""));
        assert_eq!(
            message("1.2.3"),
            "cannot parse expression \"1.2.3\" at position 1: malformed number \"1.2.3\": more than one decimal point"
        );
        assert_eq!(
            message("1_000*t"),
            "cannot parse expression \"1_000*t\" at position 1: malformed number \"1_000\": digit separators (_) are not supported; write 1000"
        );
        assert_eq!(value("1.5e3 + .5 + 1. + 2E-1"), 1501.7);
    }

    #[test]
    fn misplaced_operators_and_characters_are_named() {
        let cases = [
            ("s**/m", 2, "\"**\" is not an operator: write ^ for a power"),
            (
                "1+*t",
                3,
                "\"*\" follows \"+\" with no operand between them",
            ),
            ("2*", 2, "\"*\" has no right operand"),
            ("(2^)", 3, "\"^\" has no right operand"),
            ("*2", 1, "\"*\" has no left operand"),
            ("(/2)", 2, "\"/\" has no left operand"),
            ("1 + ()", 5, "empty parentheses"),
            (
                "2%3",
                2,
                "unexpected character '%'; the operators are + - * / ^",
            ),
            ("2−3", 2, "unexpected character '−': write - for a minus"),
            ("2×3", 2, "unexpected character '×': write * for a product"),
            (
                "(t+1)²",
                6,
                "unexpected character '²': write ^2 for a square",
            ),
            ("[1]", 1, "unexpected character '[': write ( ) for grouping"),
            ("{m}", 1, "unexpected character '{': write ( ) for grouping"),
        ];
        for (text, at, what) in cases {
            assert_eq!(
                message(text),
                format!("cannot parse expression \"{text}\" at position {at}: {what}")
            );
        }
        assert_eq!(
            message("sin(t))"),
            "unbalanced ')' at position 7 in \"sin(t))\""
        );
        assert_eq!(
            message("1+(2*(t)"),
            "unbalanced '(' in \"1+(2*(t)\": 1 not closed (the '(' at position 3)"
        );
        // Any whitespace separates (exmex knew only ' ').
        assert_eq!(value("2\t*\n3"), 6.0);
    }

    /// exmex reads a name that begins with a two-argument function's name as the
    /// function (`maxv` as `max v`); params reach it quoted, so they never are.
    #[test]
    fn params_named_like_functions_are_params() {
        let p: BTreeMap<String, f64> = [("maxv", 2.0), ("mint", 3.0), ("atan2x", 5.0), ("v", 7.0)]
            .map(|(k, v)| (k.to_string(), v))
            .into_iter()
            .collect();
        let e = compile_entry(
            &"maxv*mint + atan2x - min(maxv, v)".into(),
            &p,
            "p",
            true,
            0.0,
        );
        assert!(
            matches!(e, Ok(Entry::Const(x)) if x == 2.0 * 3.0 + 5.0 - 2.0),
            "{e:?}"
        );
    }

    /// exmex's comma rewriting failed on a two-argument call inside a second argument.
    #[test]
    fn two_argument_calls_nest() {
        assert_eq!(value("min(1, max(2, 3))"), 1.0);
        assert_eq!(value("max(1, min(5, 3) + 1)"), 4.0);
        assert_eq!(
            value("atan2(min(1, 2), -max(3, 4))"),
            libm::atan2(1.0, -4.0)
        );
        assert_eq!(value("-min(-1, -2)^2"), -4.0);
        let e = compile_entry(&"max(min(t, 2), -t)*s".into(), &params(), "p", true, 0.0);
        let Ok(Entry::Time(mut f)) = e else {
            panic!("time-varying")
        };
        for t in [-3.0, 0.5, 2.5] {
            assert_eq!(f.eval(t), t.min(2.0).max(-t) * 37.17, "t = {t}");
            assert_eq!(
                f.eval_block([t; LANES])[LANES - 1].to_bits(),
                f.eval(t).to_bits()
            );
        }
    }

    /// What the module docs say of `signum`, `log` and `round`.
    #[test]
    fn documented_function_values() {
        assert_eq!(value("signum(0)"), 0.0);
        assert_eq!(value("signum(-0)"), 0.0);
        assert_eq!(value("signum(1e-300)"), 1.0);
        assert_eq!(value("signum(-2)"), -1.0);
        assert_eq!(value("log(e)"), 1.0);
        assert_eq!(value("log(10)"), value("ln(10)"));
        assert_eq!(value("log10(1000)"), 3.0);
        assert_eq!(value("round(2.5) + round(-2.5)*10"), 3.0 - 30.0);
    }

    /// A ')' or ',' with nothing before it, or a ')' too many after an operator.
    #[test]
    fn stray_closing_parenthesis_and_comma() {
        assert_eq!(message(")"), "unbalanced ')' at position 1 in \")\"");
        assert_eq!(message("2+)"), "unbalanced ')' at position 3 in \"2+)\"");
        assert_eq!(
            message(", 1"),
            "cannot parse expression \", 1\" at position 1: a ',' outside a function's arguments (only atan2, min, max take two)"
        );
        assert_eq!(
            message("-"),
            "cannot parse expression \"-\" at position 1: \"-\" has no right operand"
        );
    }

    /// A tiny xorshift generator: the tests' random texts are reproducible.
    struct Rng(u64);

    impl Rng {
        fn below(&mut self, n: usize) -> usize {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 % n as u64) as usize
        }
    }

    /// Random texts of the language's pieces, valid or not: none panics, each error
    /// names a position (no exmex message gets through), and each accepted text
    /// gives the same bits over blocks as one value at a time.
    #[test]
    fn random_texts_are_accepted_or_located() {
        let pieces = [
            "1", "2.5", "1e-3", "t", "m", "s", "+", "-", "*", "/", "^", "(", ")", ",", "sin",
            "min", "max", "atan2", "e", " ", "pow", "2e", "**", "log",
        ];
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let (mut accepted, mut rejected) = (0, 0);
        for _ in 0..20_000 {
            let n = 1 + rng.below(9);
            let text: String = (0..n).map(|_| pieces[rng.below(pieces.len())]).collect();
            if text.trim().is_empty() {
                continue;
            }
            match compile_entry(&text.as_str().into(), &params(), "p", true, 0.3) {
                Ok(Entry::Const(x)) => {
                    accepted += 1;
                    assert!(x.is_finite(), "{text}");
                }
                Ok(Entry::Time(mut f)) => {
                    accepted += 1;
                    let ts: [f64; LANES] = std::array::from_fn(|l| 0.1 + 0.37 * l as f64);
                    let block = f.eval_block(ts);
                    for (l, &t) in ts.iter().enumerate() {
                        assert_eq!(block[l].to_bits(), f.eval(t).to_bits(), "{text} at {t}");
                    }
                }
                Err(e) => {
                    rejected += 1;
                    assert!(
                        e.message.contains("position ")
                            || e.message.contains("; expected a finite number"),
                        "{text}: {}",
                        e.message
                    );
                }
            }
        }
        assert!(accepted > 500 && rejected > 5000, "{accepted} {rejected}");
    }

    /// An independent evaluator of the documented meaning, by recursive descent over
    /// Python's grammar with `^` for `**`: expr = term {(+|-) term}, term = unary
    /// {(*|/) unary}, unary = (+|-) unary | power, power = atom [^ unary]. Texts
    /// without spaces, numbers without signed exponents.
    struct Reference<'a> {
        text: &'a [u8],
        i: usize,
        t: f64,
    }

    impl Reference<'_> {
        fn peek(&self) -> u8 {
            self.text.get(self.i).copied().unwrap_or(0)
        }
        fn take(&mut self, c: u8) -> bool {
            let found = self.peek() == c;
            self.i += usize::from(found);
            found
        }
        fn expr(&mut self) -> f64 {
            let mut x = self.term();
            loop {
                if self.take(b'+') {
                    x += self.term();
                } else if self.take(b'-') {
                    x -= self.term();
                } else {
                    return x;
                }
            }
        }
        fn term(&mut self) -> f64 {
            let mut x = self.unary();
            loop {
                if self.take(b'*') {
                    x *= self.unary();
                } else if self.take(b'/') {
                    x /= self.unary();
                } else {
                    return x;
                }
            }
        }
        fn unary(&mut self) -> f64 {
            if self.take(b'-') {
                -self.unary()
            } else if self.take(b'+') {
                self.unary()
            } else {
                let x = self.atom();
                if self.take(b'^') {
                    libm::pow(x, self.unary())
                } else {
                    x
                }
            }
        }
        fn atom(&mut self) -> f64 {
            if self.take(b'(') {
                let x = self.expr();
                assert!(self.take(b')'));
                return x;
            }
            let start = self.i;
            while self.peek().is_ascii_alphanumeric() || self.peek() == b'.' {
                self.i += 1;
            }
            let word = std::str::from_utf8(&self.text[start..self.i]).unwrap();
            if self.take(b'(') {
                let a = self.expr();
                let b = self.take(b',').then(|| self.expr());
                assert!(self.take(b')'));
                return match (word, b) {
                    ("sin", None) => libm::sin(a),
                    ("sqrt", None) => a.sqrt(),
                    ("min", Some(b)) => libm::fmin(a, b),
                    ("max", Some(b)) => libm::fmax(a, b),
                    ("atan2", Some(b)) => libm::atan2(a, b),
                    _ => panic!("{word}"),
                };
            }
            match word {
                "t" => self.t,
                "m" => 100.0,
                "s" => 37.17,
                "e" => std::f64::consts::E,
                _ => word.parse().unwrap(),
            }
        }
    }

    /// A random valid text of up to `depth` levels.
    fn random_expression(rng: &mut Rng, depth: usize) -> String {
        let sub = |rng: &mut Rng| random_expression(rng, depth.saturating_sub(1));
        // A power's operands: single tokens or parenthesised (no a^b^c).
        let operand = |x: String| {
            if x.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'.') {
                x
            } else {
                format!("({x})")
            }
        };
        match if depth == 0 {
            rng.below(5)
        } else {
            rng.below(14)
        } {
            0 => ["1", "2.5", "3", "0.5", "1e2", "2.5e1", ".5"][rng.below(7)].to_string(),
            1 => "t".to_string(),
            2 => "m".to_string(),
            3 => "s".to_string(),
            4 => "e".to_string(),
            5 => format!("({})", sub(rng)),
            6..=9 => {
                let (a, b) = (sub(rng), sub(rng));
                format!("{a}{}{b}", ["+", "-", "*", "/"][rng.below(4)])
            }
            10 => format!("{}{}", ["-", "+", "--", "-+-"][rng.below(4)], sub(rng)),
            11 => {
                let (a, b) = (sub(rng), sub(rng));
                let sign = ["", "-"][rng.below(2)];
                format!("{}^{sign}{}", operand(a), operand(b))
            }
            12 => format!("{}({})", ["sin", "sqrt"][rng.below(2)], sub(rng)),
            _ => {
                let (a, b) = (sub(rng), sub(rng));
                format!("{}({a},{b})", ["min", "max", "atan2"][rng.below(3)])
            }
        }
    }

    /// Random valid texts evaluate to the independent evaluator's bits at several t
    /// (the same libm functions, operations in the same order). This found that
    /// exmex computed `sin(t*2*3)` as t·sin(6) (`translate`).
    #[test]
    fn random_expressions_mean_what_the_grammar_says() {
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        let mut compared = 0;
        for _ in 0..5_000 {
            let text = random_expression(&mut rng, 4);
            let reference = |t: f64| {
                let mut r = Reference {
                    text: text.as_bytes(),
                    i: 0,
                    t,
                };
                let x = r.expr();
                assert_eq!(r.i, text.len(), "{text}");
                x
            };
            let entry = match compile_entry(&text.as_str().into(), &params(), "p", true, 0.0) {
                Ok(entry) => entry,
                Err(e) => {
                    // Only a value that is not finite at t = 0 is refused.
                    assert!(!reference(0.0).is_finite(), "{text}: {}", e.message);
                    continue;
                }
            };
            let mut f = match entry {
                Entry::Const(x) => {
                    let want = reference(0.0);
                    assert!(same(x, want), "{text}: {x} against {want}");
                    compared += 1;
                    continue;
                }
                Entry::Time(f) => f,
            };
            for t in [0.0, 0.3, -1.7, 12.5] {
                let (got, want) = (f.eval(t), reference(t));
                assert!(same(got, want), "{text} at t = {t}: {got} against {want}");
                compared += 1;
            }
        }
        assert!(compared > 5000, "{compared}");
    }

    /// The same f64, or both NaN.
    fn same(a: f64, b: f64) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    /// exmex ranks an operator between two numbers above its equals and applies a
    /// function of a group after the group's rightmost lowest-ranked operator:
    /// `sin(t*2*PI)` was t·sin(2π) ≈ 0 and `-(t+2+3)` was t − 5. It ranks `/` above
    /// `*` and `-` above `+`: `m*t/m - t` was m·(t/m) − t, not 0 at t = 0.3.
    #[test]
    fn exmex_reorderings_are_avoided() {
        let at = |text: &str, t: f64| match compile_entry(&text.into(), &params(), "p", true, 0.0) {
            Ok(Entry::Time(mut f)) => f.eval(t),
            _ => panic!("{text}"),
        };
        let t = 0.3f64;
        let pi = std::f64::consts::PI;
        assert_eq!(at("sin(t*2*PI)", t), libm::sin(t * 2.0 * pi));
        assert_eq!(at("sin(t*2*3)", t), libm::sin(t * 2.0 * 3.0));
        assert_eq!(at("-(t+2+3)", t), -(t + 2.0 + 3.0));
        assert_eq!(at("cos(t+2+3)", t), libm::cos(t + 2.0 + 3.0));
        assert_eq!(at("m*t/m - t", t), 0.0);
        assert_eq!(at("t + 1e16 - 1e16", t), (t + 1e16) - 1e16);
        assert_eq!(at("exp(t*2/3*s)", t), libm::exp(t * 2.0 / 3.0 * 37.17));
    }
}
