//! The expressions' limits: the longest text, and a model's budget of distinct
//! time-dependent expressions (their number and total length).

use super::Value;

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
    pub(super) exceeded: bool,
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
