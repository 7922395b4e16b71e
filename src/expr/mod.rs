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
mod trig;
mod value;
use exmex::prelude::*;
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

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
            let block = BlockEx::parse(&plain).map_err(|e| {
                FieldError::new(
                    path,
                    format!(
                        "cannot parse expression \"{text}\": {}",
                        describe(&e.to_string())
                    ),
                )
            })?;
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

/// One token of an expression's text: where it is (bytes `start..end`) and what.
#[derive(Clone, Copy, Debug)]
struct Token {
    tok: Tok,
    start: usize,
    end: usize,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Tok {
    /// A number literal and its value (finite).
    Num(f64),
    /// A parameter, `t`, a constant or a function.
    Name,
    /// `+ - * / ^`.
    Op(char),
    Open,
    Close,
    Comma,
}

/// A syntax error: where (a byte offset into the text) and what.
struct Syntax(usize, String);

/// The message of a syntax error at byte `at` of `text`.
fn syntax_message(text: &str, Syntax(at, what): Syntax) -> String {
    format!(
        "cannot parse expression \"{text}\" at position {}: {what}",
        char_pos(text, at) + 1
    )
}

/// Split `text` into tokens. Numbers are `1`, `1.5`, `.5`, `1.` with an optional
/// exponent (`1e-5`, `2.5E3`); names are letters, digits and `_`, not starting with a
/// digit; whitespace separates.
fn lex(text: &str) -> Result<Vec<Token>, Syntax> {
    let chars: Vec<(usize, char)> = text.char_indices().collect();
    let at = |i: usize| chars.get(i).map_or(text.len(), |c| c.0);
    let ch = |i: usize| chars.get(i).map(|c| c.1);
    let digit = |i: usize| ch(i).is_some_and(|c| c.is_ascii_digit());
    let mut tokens = Vec::new();
    let mut i = 0;
    while let Some(c) = ch(i) {
        let start = at(i);
        let tok = match c {
            _ if c.is_whitespace() => {
                i += 1;
                continue;
            }
            '+' | '-' | '*' | '/' | '^' => Tok::Op(c),
            '(' => Tok::Open,
            ')' => Tok::Close,
            ',' => Tok::Comma,
            _ if c.is_ascii_digit() || (c == '.' && digit(i + 1)) => {
                while digit(i) {
                    i += 1;
                }
                if ch(i) == Some('.') {
                    i += 1;
                    while digit(i) {
                        i += 1;
                    }
                }
                let mantissa = &text[start..at(i)];
                if ch(i) == Some('.') {
                    while digit(i) || ch(i) == Some('.') {
                        i += 1;
                    }
                    let lit = &text[start..at(i)];
                    return Err(Syntax(
                        start,
                        format!("malformed number \"{lit}\": more than one decimal point"),
                    ));
                }
                if matches!(ch(i), Some('e' | 'E')) {
                    let sign = usize::from(matches!(ch(i + 1), Some('+' | '-')));
                    if digit(i + 1 + sign) {
                        i += 1 + sign;
                        while digit(i) {
                            i += 1;
                        }
                    } else if sign == 1
                        || !ch(i + 1).is_some_and(|c| c.is_alphanumeric() || c == '_')
                    {
                        // `2e`, `2e+`: not `2e3`, nor a name after a number (`2exp(1)`,
                        // reported as a missing operator).
                        let lit = &text[start..at(i + 1 + sign)];
                        let euler = if sign == 0 {
                            format!(" (for {mantissa} times Euler's number write {mantissa}*e)")
                        } else {
                            String::new()
                        };
                        return Err(Syntax(
                            start,
                            format!(
                                "malformed number \"{lit}\": an exponent needs digits, as in {mantissa}e3{euler}"
                            ),
                        ));
                    }
                }
                if ch(i) == Some('_') {
                    while ch(i).is_some_and(|c| c.is_ascii_digit() || c == '_' || c == '.') {
                        i += 1;
                    }
                    let lit = &text[start..at(i)];
                    return Err(Syntax(
                        start,
                        format!(
                            "malformed number \"{lit}\": digit separators (_) are not supported; write {}",
                            lit.replace('_', "")
                        ),
                    ));
                }
                let lit = &text[start..at(i)];
                let x = match lit.parse::<f64>() {
                    Ok(x) if crate::json::underflows(lit, x) => {
                        return Err(Syntax(
                            start,
                            format!(
                                "the number {lit} is below the smallest f64 (≈ 4.9e-324) and would be read as 0: write 0 if 0 is meant"
                            ),
                        ));
                    }
                    Ok(x) if x.is_finite() => x,
                    Ok(_) => {
                        return Err(Syntax(
                            start,
                            format!(
                                "the number {lit} overflows f64 (the largest finite value is about 1.8e308)"
                            ),
                        ));
                    }
                    Err(_) => {
                        return Err(Syntax(start, format!("malformed number \"{lit}\"")));
                    }
                };
                tokens.push(Token {
                    tok: Tok::Num(x),
                    start,
                    end: at(i),
                });
                continue;
            }
            _ if c.is_alphabetic() || c == '_' => {
                while ch(i).is_some_and(|c| c.is_alphanumeric() || c == '_') {
                    i += 1;
                }
                tokens.push(Token {
                    tok: Tok::Name,
                    start,
                    end: at(i),
                });
                continue;
            }
            _ => {
                let hint = match c {
                    '−' | '–' | '—' => ": write - for a minus",
                    '×' | '·' | '⋅' | '∙' => ": write * for a product",
                    '÷' | '∕' => ": write / for a quotient",
                    '²' => ": write ^2 for a square",
                    '³' => ": write ^3 for a cube",
                    '[' | ']' | '{' | '}' => ": write ( ) for grouping",
                    _ => "; the operators are + - * / ^",
                };
                return Err(Syntax(start, format!("unexpected character '{c}'{hint}")));
            }
        };
        i += 1;
        tokens.push(Token {
            tok,
            start,
            end: at(i),
        });
    }
    Ok(tokens)
}

/// A level of an expression while translating: the whole text, a parenthesised group
/// or a function call's arguments.
struct Frame {
    /// The called function, its arity and where its name starts; None for a group.
    call: Option<(&'static str, usize, usize)>,
    /// Where the '(' is (0 for the whole text).
    open: usize,
    /// Arguments begun so far (a call's commas + 1).
    args: usize,
    /// Where the latest operand of this level begins (without its signs).
    operand: usize,
    /// An unparenthesised `^` of this level whose right operand is being read: where
    /// its left operand begins and where the `^` ends.
    power: Option<(usize, usize)>,
    /// Negations `(-(` opened at this level, to close when its power expression ends.
    negations: usize,
    /// Where in the output this level's current sum begins, and its `+ -` so far.
    sum: (usize, usize),
    /// Where in the output the sum's current term begins, and its `* /` so far.
    term: (usize, usize),
}

impl Frame {
    /// A level whose output begins at `out`.
    fn new(call: Option<(&'static str, usize, usize)>, open: usize, out: usize) -> Frame {
        Frame {
            call,
            open,
            args: 1,
            operand: open,
            power: None,
            negations: 0,
            sum: (out, 0),
            term: (out, 0),
        }
    }

    /// Before a binary `+ - * /` in `out`: close the negations, and parenthesise the
    /// sum (for `+ -`) or term (`* /`) so far if it has an operator of the same rank,
    /// so that exmex evaluates the level left to right (it ranks `/` above `*` and
    /// `-` above `+`: `a*b/c` was a*(b/c), `a+b-c` a+(b−c)).
    fn binary(&mut self, op: char, out: &mut String) {
        close_negations(self, out);
        self.power = None;
        let additive = matches!(op, '+' | '-');
        let (start, ops) = if additive {
            &mut self.sum
        } else {
            &mut self.term
        };
        if *ops > 0 {
            out.insert(*start, '(');
            out.push(')');
        }
        *ops += 1;
        out.push(op);
        if additive {
            self.term = (out.len(), 0);
        }
    }

    /// After a ',' in `out`: the next argument begins.
    fn next_argument(&mut self, out: &str) {
        self.args += 1;
        self.power = None;
        self.sum = (out.len(), 0);
        self.term = (out.len(), 0);
    }
}

/// Check an expression's text and translate it to exmex's syntax, with the meaning
/// this module documents, which is not always exmex's. Returns the text and the
/// values of its literals.
///
/// - Numbers and constants become variables `{#k}`, `k` indexing the values
///   returned. exmex ranks an operator between two number leaves above its equals
///   (to fold constants), yet applies a function written around a group after the
///   group's rightmost lowest-ranked operator: `sin(t*2*PI)` was t·sin(2π) ≈ 0,
///   `-(t+2+3)` was t − 5. With no number leaves it keeps the ranks as written.
///   (And exmex's literals have no exponent: `1e-5` would need rewriting.)
/// - Params and `t` become `{name}`, exmex's quoted variables: its tokenizer read a
///   param `maxv` as the function `max` and a variable `v`.
/// - A negation becomes `(-(…))` around the power expression it applies to: exmex
///   binds a unary minus tighter than every binary operator (`-x^2` would be (−x)²),
///   and the former rewrite as `(-1)*` lost to `/`'s higher rank (`2/-3` was −6).
/// - `a*b/c` becomes `(a*b)/c` and `a+b-c` becomes `(a+b)-c` (`Frame::binary`): one
///   level is evaluated left to right, as in mathematics and every calculator; exmex
///   ranks `/` above `*` and `-` above `+` (a·(b/c) and a+(b−c), other last bits:
///   `m*t/m - t` was not 0).
/// - `min(a, b)` becomes `((a)min(b))`, exmex's infix form: its comma rewriting
///   failed on a two-argument call inside a second argument, `min(1, max(2, 3))`.
///
/// Negation is exact, so the values are those of the operations in this order, bit
/// for bit (`random_expressions_mean_what_the_grammar_says`).
fn translate(
    text: &str,
    params: &BTreeMap<String, f64>,
    path: &str,
    allow_t: bool,
) -> Result<(String, Vec<f64>), FieldError> {
    let syntax =
        |at: usize, what: String| FieldError::new(path, syntax_message(text, Syntax(at, what)));
    let tokens = lex(text).map_err(|Syntax(at, what)| syntax(at, what))?;
    let lang = language();
    let comma_outside = || {
        format!(
            "a ',' outside a function's arguments (only {} take two)",
            lang.binary.join(", ")
        )
    };
    let mut out = String::with_capacity(text.len() + 16);
    // The numbers and constants, each passed to exmex as a variable `{#k}`.
    let mut literals: Vec<f64> = Vec::new();
    let mut literal = |x: f64, out: &mut String| {
        let k = match literals.iter().position(|l| l.to_bits() == x.to_bits()) {
            Some(k) => k,
            None => {
                literals.push(x);
                literals.len() - 1
            }
        };
        out.push_str(&format!("{{#{k}}}"));
    };
    // The whole text's level, and the open parentheses within it.
    let mut whole = Frame::new(None, 0, 0);
    let mut stack: Vec<Frame> = Vec::new();
    let mut expect_operand = true;
    // The unary signs before the coming operand: an odd number of minuses.
    let mut negate = false;
    let mut i = 0;
    while i < tokens.len() {
        let token = tokens[i];
        let prev = i.checked_sub(1).map(|p| tokens[p]);
        let nested = !stack.is_empty();
        let frame = stack.last_mut().unwrap_or(&mut whole);
        if !expect_operand {
            match token.tok {
                Tok::Op('^') => {
                    if let Some((left, caret)) = frame.power {
                        return Err(syntax(
                            token.start,
                            ambiguous_power(text, &tokens, i, left, caret),
                        ));
                    }
                    frame.power = Some((frame.operand, token.end));
                    out.push('^');
                }
                Tok::Op(c) => frame.binary(c, &mut out),
                Tok::Comma => {
                    let Some((name, arity, at)) = frame.call else {
                        return Err(syntax(token.start, comma_outside()));
                    };
                    if frame.args == arity {
                        return Err(syntax(
                            at,
                            too_many_arguments(text, name, arity, token.start),
                        ));
                    }
                    close_negations(frame, &mut out);
                    out.push_str(&format!("){name}("));
                    frame.next_argument(&out);
                }
                Tok::Close => {
                    let Some(mut frame) = stack.pop() else {
                        return Err(unbalanced_close(text, path, token.start));
                    };
                    close_negations(&mut frame, &mut out);
                    match frame.call {
                        Some((name, arity, at)) if frame.args < arity => {
                            // Only a two-argument call can close with too few.
                            return Err(syntax(
                                at,
                                format!(
                                    "{name}(…) takes exactly two arguments, got one: write {name}(a, b)"
                                ),
                            ));
                        }
                        Some((_, 2, _)) => out.push_str("))"),
                        _ => out.push(')'),
                    }
                }
                Tok::Num(_) | Tok::Name | Tok::Open => {
                    let left = &text[frame.operand..prev.map_or(0, |p| p.end)];
                    let right = operand_text(text, &tokens, i);
                    return Err(syntax(
                        token.start,
                        format!(
                            "an operator is missing between \"{left}\" and \"{right}\": implicit multiplication is not supported; write {left}*{right}"
                        ),
                    ));
                }
            }
            expect_operand = token.tok != Tok::Close;
            i += 1;
            continue;
        }
        // An operand is expected.
        match token.tok {
            Tok::Op('+' | '-') => negate ^= token.tok == Tok::Op('-'),
            Tok::Op(c) => {
                return Err(match prev.map(|p| p.tok) {
                    Some(Tok::Op('*')) if c == '*' => syntax(
                        prev.map_or(token.start, |p| p.start),
                        "\"**\" is not an operator: write ^ for a power".to_string(),
                    ),
                    Some(Tok::Op(p)) => syntax(
                        token.start,
                        format!("\"{c}\" follows \"{p}\" with no operand between them"),
                    ),
                    _ => syntax(token.start, format!("\"{c}\" has no left operand")),
                });
            }
            Tok::Close if !nested => {
                return Err(unbalanced_close(text, path, token.start));
            }
            Tok::Comma if frame.call.is_none() => {
                return Err(syntax(token.start, comma_outside()));
            }
            Tok::Close | Tok::Comma => {
                // Within parentheses: a token precedes, their '(' at least.
                let before = prev.map_or(token.start, |p| p.start);
                let close = token.tok == Tok::Close;
                return Err(match (prev.map(|p| p.tok), frame.call) {
                    (Some(Tok::Op(c)), _) => {
                        syntax(before, format!("\"{c}\" has no right operand"))
                    }
                    (Some(Tok::Open), Some((name, arity, at))) if close => syntax(
                        at,
                        if arity == 1 {
                            format!("{name}(…) takes one argument, got none")
                        } else {
                            format!("{name}(…) takes exactly two arguments, got none")
                        },
                    ),
                    (Some(Tok::Open), None) if close => {
                        syntax(before, "empty parentheses".to_string())
                    }
                    (Some(Tok::Comma), _) if close => {
                        syntax(before, "an argument is missing after the ','".to_string())
                    }
                    _ => syntax(
                        token.start,
                        "an argument is missing before the ','".to_string(),
                    ),
                });
            }
            Tok::Num(x) => {
                begin_operand(frame, &mut negate, token.start, &mut out);
                literal(x, &mut out);
                expect_operand = false;
            }
            Tok::Open => {
                begin_operand(frame, &mut negate, token.start, &mut out);
                out.push('(');
                stack.push(Frame::new(None, token.start, out.len()));
            }
            Tok::Name => {
                let name = &text[token.start..token.end];
                let called = tokens.get(i + 1).filter(|t| t.tok == Tok::Open);
                let function = lang
                    .unary
                    .iter()
                    .map(|&f| (f, 1))
                    .chain(lang.binary.iter().map(|&f| (f, 2)))
                    .find(|&(f, _)| f == name);
                let constant = lang.constant(name);
                let known = constant.is_some() || params.contains_key(name) || name == "t";
                match (function, called) {
                    (Some((function, arity)), Some(open)) => {
                        begin_operand(frame, &mut negate, token.start, &mut out);
                        out.push_str(&if arity == 1 {
                            format!("{function}(")
                        } else {
                            "((".to_string()
                        });
                        let call = Some((function, arity, token.start));
                        stack.push(Frame::new(call, open.start, out.len()));
                        i += 1; // the '('
                    }
                    (Some((_, arity)), None) => {
                        let example = if arity == 1 {
                            "argument in parentheses, as in {name}(x)"
                        } else {
                            "arguments in parentheses, as in {name}(a, b)"
                        };
                        return Err(syntax(
                            token.start,
                            format!(
                                "{name} is a function: write its {}",
                                example.replace("{name}", name)
                            ),
                        ));
                    }
                    (None, Some(open)) if known => {
                        let right = operand_text(text, &tokens, i + 1);
                        return Err(syntax(
                            open.start,
                            format!(
                                "an operator is missing between \"{name}\" and \"{right}\" ({name} is not a function): implicit multiplication is not supported; write {name}*{right}"
                            ),
                        ));
                    }
                    (None, Some(_)) => {
                        return Err(unknown_function(text, name, path, token.start));
                    }
                    (None, None) if name == "t" && !allow_t => {
                        return Err(FieldError::new(
                            path,
                            format!(
                                "\"{text}\" depends on t, but this field must be constant (t at position {})",
                                char_pos(text, token.start) + 1
                            ),
                        ));
                    }
                    (None, None) if known => {
                        begin_operand(frame, &mut negate, token.start, &mut out);
                        match constant {
                            Some(x) => literal(x, &mut out),
                            // Quoted: exmex would read `maxv` as `max` and `v`.
                            None => out.push_str(&format!("{{{name}}}")),
                        }
                        expect_operand = false;
                    }
                    (None, None) => {
                        let mut e = unknown(text, name, params, path, allow_t);
                        e.message = format!(
                            "{} (at position {})",
                            e.message,
                            char_pos(text, token.start) + 1
                        );
                        return Err(e);
                    }
                }
            }
        }
        i += 1;
    }
    if let Some(first) = stack.first() {
        return Err(FieldError::new(
            path,
            format!(
                "unbalanced '(' in \"{text}\": {} not closed (the '(' at position {})",
                stack.len(),
                char_pos(text, first.open) + 1
            ),
        ));
    }
    if expect_operand {
        // The text is not blank (checked before): an operator or sign ends it.
        if let Some(last) = tokens.last() {
            return Err(syntax(
                last.start,
                format!("\"{}\" has no right operand", &text[last.start..last.end]),
            ));
        }
    }
    close_negations(&mut whole, &mut out);
    Ok((out, literals))
}

/// Start an operand at byte `start` of the current level, opening the negation its
/// signs call for (closed by `close_negations` when its power expression ends).
fn begin_operand(frame: &mut Frame, negate: &mut bool, start: usize, out: &mut String) {
    if std::mem::take(negate) {
        out.push_str("(-(");
        frame.negations += 1;
    }
    frame.operand = start;
}

/// Close the level's open negations: its power expression has ended.
fn close_negations(frame: &mut Frame, out: &mut String) {
    for _ in 0..std::mem::take(&mut frame.negations) {
        out.push_str("))");
    }
}

/// The text of the operand that begins at token `i`: its signs, then a number, a
/// name, a call or a parenthesised group (as far as the text goes).
fn operand_text<'a>(text: &'a str, tokens: &[Token], i: usize) -> &'a str {
    let Some(first) = tokens.get(i) else {
        return "";
    };
    let mut j = i;
    while matches!(tokens[j].tok, Tok::Op('+' | '-')) && j + 1 < tokens.len() {
        j += 1;
    }
    if tokens[j].tok == Tok::Name && tokens.get(j + 1).is_some_and(|t| t.tok == Tok::Open) {
        j += 1;
    }
    if tokens[j].tok == Tok::Open {
        let mut depth = 0usize;
        for (k, t) in tokens.iter().enumerate().skip(j) {
            j = k;
            match t.tok {
                Tok::Open => depth += 1,
                Tok::Close => depth -= 1,
                _ => {}
            }
            if depth == 0 {
                break;
            }
        }
    }
    &text[first.start..tokens[j].end]
}

/// `a^b^c` without parentheses, found at the second `^` (token `i`): `left` is where
/// `a` begins, `caret` where the first `^` ends.
///
/// Rejected rather than given a meaning, because engineers' tools disagree: Excel and
/// MATLAB read `2^3^2` as (2^3)^2 = 64 (exmex too), mathematics, Python's `**`, Julia,
/// R and Fortran as 2^(3^2) = 512. Either choice silently gives some readers another
/// number; asking for parentheses gives everyone theirs.
fn ambiguous_power(text: &str, tokens: &[Token], i: usize, left: usize, caret: usize) -> String {
    let a = text[left..caret - 1].trim();
    let b = text[caret..tokens[i].start].trim();
    let c = match operand_text(text, tokens, i + 1) {
        "" => "c",
        c => c,
    };
    format!(
        "\"{a}^{b}^{c}\" is ambiguous: some tools read a^b^c as (a^b)^c (Excel, MATLAB), others as a^(b^c) (mathematics, Python, Julia); write {a}^({b}^{c}) or ({a}^{b})^{c}"
    )
}

/// A call of `name` (of `arity` arguments) with a ',' at byte `comma` too many.
fn too_many_arguments(text: &str, name: &str, arity: usize, comma: usize) -> String {
    let comma = char_pos(text, comma) + 1;
    if arity == 1 {
        let note = if name == "log" {
            " (log is the natural logarithm, like ln; for the logarithm of x to base b write ln(x)/ln(b))"
        } else {
            ""
        };
        format!("{name}(…) takes one argument; the ',' at position {comma} begins a second{note}")
    } else {
        let note = if name == "min" || name == "max" {
            format!(" (for three, nest them: {name}(a, {name}(b, c)))")
        } else {
            String::new()
        };
        format!(
            "{name}(…) takes exactly two arguments; the ',' at position {comma} begins a third{note}"
        )
    }
}

fn unbalanced_close(text: &str, path: &str, at: usize) -> FieldError {
    FieldError::new(
        path,
        format!(
            "unbalanced ')' at position {} in \"{text}\"",
            char_pos(text, at) + 1
        ),
    )
}

/// `name(` where `name` is neither a function nor a known operand.
fn unknown_function(text: &str, name: &str, path: &str, at: usize) -> FieldError {
    let lang = language();
    let hint = match name {
        "pow" => "; for a power write a^b",
        "sign" | "sgn" => "; the sign function is signum",
        _ => "",
    };
    FieldError::new(
        path,
        format!(
            "unknown function \"{name}\" in \"{text}\" (at position {}){hint}; the functions are {}, and with two arguments {}",
            char_pos(text, at) + 1,
            lang.unary.join(", "),
            lang.binary.join(", ")
        ),
    )
}

/// exmex's messages can carry Debug dumps of its internals: keep the readable part.
/// (Only a text `translate` accepted reaches exmex, so its messages should never be
/// seen; one that is seen is a gap in `translate`'s checks.)
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
/// length. A parsed expression in both its forms (one value, blocks of values) holds
/// ≈ 45 KB plus ≈ 0.7 KB per character, shared by the analyses' copies, so these bound
/// a model's expressions to ≈ 85 MB (`tests/memory.rs` measures them). Entries of one matrix with the same text share one parse and count once;
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
                "more than {MAX_TIME_EXPRESSIONS} distinct time-dependent expressions in one model (the limit: each costs ≈ 45 KB while the model is compiled)"
            )
        } else if self.chars + chars > MAX_TIME_EXPRESSION_CHARS {
            format!(
                "the model's distinct time-dependent expressions exceed {MAX_TIME_EXPRESSION_CHARS} characters in total (the limit: each character costs ≈ 1 KB while an analysis runs)"
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
                self.eval_blocks(t0, dt, i);
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

    /// Every expression at grid points i .. i + LANES, into `block_values`. Out of
    /// line, so that the steps served from the cache do not set up its frame (the
    /// exmex evaluation's, a few KB).
    #[inline(never)]
    fn eval_blocks(&mut self, t0: f64, dt: f64, i: u64) {
        let ts: [f64; LANES] = std::array::from_fn(|l| t0 + (i + l as u64) as f64 * dt);
        for (f, out) in self.fns.iter_mut().zip(&mut self.block_values) {
            *out = f.eval_block(ts);
        }
        self.block_grid = Some((t0.to_bits(), dt.to_bits(), i));
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
