//! How kea writes numbers, counts and names in its messages, tables and CSV: one
//! wording for every kind and every shell.

/// A number for a message: plain in [1e-4, 1e15), else in exponent form (never 300
/// digits). (Also the report's, for times.)
pub fn num(x: f64) -> String {
    if x == 0.0 || (1e-4..1e15).contains(&x.abs()) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// A time for reading: 12 significant digits, so t0 + kΔt's rounding does not show
/// (15.600000000000001 → 15.6), in exponent form where plain would be long (1e-300).
pub fn short(t: f64) -> String {
    num(format!("{t:.11e}").parse().unwrap_or(t))
}

/// Width of the table's number columns.
pub const CELL: usize = 10;

/// A number for a column of [`CELL`] characters: four decimals, or the exponent form
/// where those would not fit or would show fewer than two significant digits; `—`
/// where there is no finite value. Every text table of kea writes its numbers so.
pub fn cell(x: Option<f64>) -> String {
    let Some(v) = x.filter(|v| v.is_finite()) else {
        return "—".to_string();
    };
    let fixed = format!("{v:.4}");
    if (v == 0.0 || v.abs() >= 1e-3) && fixed.len() <= CELL {
        return fixed;
    }
    // (A three-digit exponent leaves room for three decimals.)
    let exp = format!("{v:.4e}");
    if exp.len() <= CELL {
        exp
    } else {
        format!("{v:.3e}")
    }
}

/// "1 entry", "3 entries": a count of a list's entries, for messages.
pub fn entries(n: usize) -> String {
    if n == 1 {
        "1 entry".into()
    } else {
        format!("{n} entries")
    }
}

/// A name an expression can use (and a key `error::member_path` writes unquoted).
pub fn is_identifier(s: &str) -> bool {
    let mut it = s.chars();
    matches!(it.next(), Some(c) if c.is_alphabetic() || c == '_')
        && it.all(|c| c.is_alphanumeric() || c == '_')
}

/// Records as CSV text (RFC 4180: a field holding a comma, a quote or a line break —
/// a state may be named so — is quoted).
pub fn csv_text<R, F>(header: F, rows: impl Iterator<Item = R>) -> String
where
    R: IntoIterator<Item = String>,
    F: IntoIterator<Item = String>,
{
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new());
    // (Writing to a Vec cannot fail: the results are ignored.)
    let _ = w.write_record(header);
    for row in rows {
        let _ = w.write_record(row);
    }
    let bytes = w.into_inner().unwrap_or_default();
    String::from_utf8(bytes).unwrap_or_default()
}
