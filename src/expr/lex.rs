//! The lexer of the expression language: a text's tokens (numbers with their values,
//! names, operators, parentheses, commas), or the malformed number or stray character
//! that stops it, located for `translate`'s messages.

/// One token of an expression's text: where it is (bytes `start..end`) and what.
#[derive(Clone, Copy, Debug)]
pub(super) struct Token {
    pub(super) tok: Tok,
    pub(super) start: usize,
    pub(super) end: usize,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Tok {
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
pub(super) struct Syntax(pub(super) usize, pub(super) String);

/// Split `text` into tokens. Numbers are `1`, `1.5`, `.5`, `1.` with an optional
/// exponent (`1e-5`, `2.5E3`); names are letters, digits and `_`, not starting with a
/// digit; whitespace separates.
pub(super) fn lex(text: &str) -> Result<Vec<Token>, Syntax> {
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
