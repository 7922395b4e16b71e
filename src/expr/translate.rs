//! The checking translator: every text is given the one meaning the module's docs
//! describe (or an error naming its position) before exmex sees it, and is rewritten
//! into exmex's syntax with that meaning.

use super::language;
use super::lex::{Syntax, Tok, Token, lex};
use crate::error::FieldError;
use std::collections::BTreeMap;

/// The message of a syntax error at byte `at` of `text`.
fn syntax_message(text: &str, Syntax(at, what): Syntax) -> String {
    format!(
        "cannot parse expression \"{text}\" at position {}: {what}",
        char_pos(text, at) + 1
    )
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
pub(super) fn translate(
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
pub(super) fn describe(msg: &str) -> String {
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

pub(super) fn unknown(
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
