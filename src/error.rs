//! Errors the core reports: each names the field path in the submitted JSON
//! (`measurement.c[1][2]`) and says what was expected.

use serde::Serialize;
use std::fmt;

/// One problem with a submitted model, at `path` (empty for the whole document).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FieldError {
    pub path: String,
    pub message: String,
}

impl FieldError {
    pub fn new(path: impl Into<String>, message: impl Into<String>) -> Self {
        FieldError {
            path: path.into(),
            message: message.into(),
        }
    }
}

impl fmt::Display for FieldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.path.is_empty() {
            write!(f, "{}", self.message)
        } else {
            write!(f, "{}: {}", self.path, self.message)
        }
    }
}

/// The path of member `key` of the object at `parent`: `parent.key` where the key is an
/// identifier, else `parent["key"]` (JSON-quoted), so that a key with a dot, a space or
/// a bracket in it (`params["a.b"]`) does not read as a path of its own.
pub fn member_path(parent: &str, key: &str) -> String {
    match (crate::text::is_identifier(key), parent.is_empty()) {
        (true, true) => key.to_string(),
        (true, false) => format!("{parent}.{key}"),
        (false, _) => format!(
            "{parent}[{}]",
            serde_json::to_string(key).unwrap_or_else(|_| format!("\"{key}\""))
        ),
    }
}

/// Everything that can stop an analysis. None of these is a panic or a NaN.
#[derive(Clone, Debug, PartialEq)]
pub enum Error {
    /// The model (or a request around it) is invalid; every problem found is listed.
    Invalid(Vec<FieldError>),
    /// The model is valid but the computation cannot go on at step k (time t),
    /// e.g. a singular innovation covariance or a diverging covariance.
    Numerical {
        step: u64,
        t: f64,
        path: String,
        message: String,
    },
    /// The caller asked to stop (progress callback returned `Break`).
    Cancelled,
}

impl Error {
    pub fn invalid(path: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Invalid(vec![FieldError::new(path, message)])
    }

    /// The field errors of this error (a numerical error is one error at its path).
    pub fn field_errors(&self) -> Vec<FieldError> {
        match self {
            Error::Invalid(v) => v.clone(),
            Error::Numerical {
                path,
                message,
                step,
                t,
                ..
            } => vec![FieldError::new(
                path.clone(),
                format!("{message} (at step {step}, t = {})", crate::text::short(*t)),
            )],
            Error::Cancelled => vec![FieldError::new("", "cancelled")],
        }
    }

    /// Prefix every path with `prefix` (e.g. `model`), joining with a dot.
    pub fn with_prefix(self, prefix: &str) -> Self {
        let join = |p: &str| {
            if prefix.is_empty() {
                p.to_string()
            } else if p.is_empty() {
                prefix.to_string()
            } else if p.starts_with('[') {
                format!("{prefix}{p}")
            } else {
                format!("{prefix}.{p}")
            }
        };
        self.map_paths(join)
    }

    /// The error's paths without `prefix` (`model.x` is `x`, `model` the root), the
    /// inverse of [`Error::with_prefix`]: a request's errors as those of its member.
    pub fn without_prefix(self, prefix: &str) -> Self {
        let strip = |p: &str| match p.strip_prefix(prefix) {
            Some("") => String::new(),
            Some(rest) if rest.starts_with('.') => rest[1..].to_string(),
            Some(rest) if rest.starts_with('[') => rest.to_string(),
            _ => p.to_string(),
        };
        self.map_paths(strip)
    }

    /// The error with every path mapped by `f`.
    pub fn map_paths(self, f: impl Fn(&str) -> String) -> Self {
        self.map(f, |m| m)
    }

    /// The error with every message mapped by `f` (a note added to each, say).
    pub fn map_messages(self, f: impl Fn(String) -> String) -> Self {
        self.map(str::to_string, f)
    }

    /// The error with every path mapped by `path` and every message by `message`.
    pub(crate) fn map(
        self,
        path: impl Fn(&str) -> String,
        message: impl Fn(String) -> String,
    ) -> Self {
        match self {
            Error::Invalid(v) => Error::Invalid(
                v.into_iter()
                    .map(|e| FieldError::new(path(&e.path), message(e.message)))
                    .collect(),
            ),
            Error::Numerical {
                step,
                t,
                path: p,
                message: m,
            } => Error::Numerical {
                step,
                t,
                path: path(&p),
                message: message(m),
            },
            Error::Cancelled => Error::Cancelled,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Invalid(v) => {
                for (i, e) in v.iter().enumerate() {
                    if i > 0 {
                        writeln!(f)?;
                    }
                    write!(f, "{e}")?;
                }
                Ok(())
            }
            Error::Numerical {
                step,
                t,
                path,
                message,
            } => {
                if path.is_empty() {
                    write!(
                        f,
                        "{message} (at step {step}, t = {})",
                        crate::text::short(*t)
                    )
                } else {
                    write!(
                        f,
                        "{path}: {message} (at step {step}, t = {})",
                        crate::text::short(*t)
                    )
                }
            }
            Error::Cancelled => write!(f, "cancelled"),
        }
    }
}

impl std::error::Error for Error {}

/// What a JSON value is, in the words of kea's messages: "an array", "a number"…
pub fn json_kind(v: &serde_json::Value) -> &'static str {
    use serde_json::Value;
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

/// A value as a message's "got …": a number as written, a string quoted, else its kind.
pub fn got(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::Number(n) => n.to_string(),
        serde_json::Value::String(_) => format!("a string ({v})"),
        other => json_kind(other).to_string(),
    }
}

/// serde's messages in plain words, at the path of the member concerned: "missing
/// field `mode`" at the root becomes `mode`: "missing: …", "invalid type: string
/// \"2\", expected f64" becomes "expected a number, got a string (\"2\")". `hints`
/// say what a missing member is, by name. "duplicate field" can only be a member given
/// under its name and a former name (an alias: the reader refuses a key given twice
/// before serde sees it). A message of another form is kept.
pub fn plain_serde_error(e: FieldError, hints: &[(&str, &str)]) -> FieldError {
    let FieldError { path, message } = e;
    let join = |field: &str| {
        if path.is_empty() {
            field.to_string()
        } else {
            format!("{path}.{field}")
        }
    };
    if let Some(field) = backticked(&message, "missing field ") {
        let hint = hints
            .iter()
            .find(|(name, _)| *name == field)
            .map_or("this member is required", |(_, hint)| hint);
        return FieldError::new(join(field), format!("missing: {hint}"));
    }
    if let Some(field) = backticked(&message, "duplicate field ") {
        let at = if path.rsplit('.').next() == Some(field) {
            path.clone()
        } else {
            join(field)
        };
        return FieldError::new(
            at,
            format!("given twice, under its name and a former one; give `{field}` alone"),
        );
    }
    if let Some(rest) = message.strip_prefix("unknown field `") {
        return FieldError::new(
            path,
            match rest.split_once(", ") {
                Some((_, expected)) => {
                    format!("unknown member; expected {}", one_of(expected))
                }
                None => "unknown member".into(),
            },
        );
    }
    if let Some(rest) = message.strip_prefix("unknown variant `") {
        let (value, expected) = rest.split_once("`, ").unwrap_or((rest, ""));
        return FieldError::new(
            path,
            format!("unknown value \"{value}\"; expected {}", one_of(expected)),
        );
    }
    for prefix in ["invalid type: ", "invalid value: "] {
        // (The expectation is the type's own wording, without the separator; the
        // value may hold it — a string can hold anything.)
        if let Some((got, expected)) = message
            .strip_prefix(prefix)
            .and_then(|m| m.rsplit_once(", expected "))
        {
            let got = got_kind(got);
            // An enum written as {"variant": …} with no member or several: its hint
            // (by the member's name) names the variants.
            let expected = if expected == "map with a single key" {
                let leaf = path.rsplit('.').next().unwrap_or(&path);
                hints
                    .iter()
                    .find(|(name, _)| *name == leaf)
                    .map_or("an object with exactly one member".into(), |(_, h)| {
                        h.to_string()
                    })
            } else {
                expected_kind(expected, &got)
            };
            return FieldError::new(path, format!("expected {expected}, got {got}"));
        }
    }
    if let Some((got, expected)) = message
        .strip_prefix("invalid length ")
        .and_then(|m| m.split_once(", expected "))
    {
        // (serde says "2 elements in sequence" for the entries a fixed-length array
        // left unread, and "an array of length 2" for too few.)
        let expected = match expected.strip_suffix(" elements in sequence") {
            Some(n) => format!("an array of length {n}"),
            None => expected.to_string(),
        };
        let got = got
            .parse()
            .map_or(format!("{got} entries"), crate::text::entries);
        return FieldError::new(path, format!("expected {expected}, got {got}"));
    }
    FieldError::new(path, message)
}

/// The name in `prefix`\`name\`` (the whole message).
fn backticked<'a>(message: &'a str, prefix: &str) -> Option<&'a str> {
    let name = message
        .strip_prefix(prefix)?
        .strip_prefix('`')?
        .strip_suffix('`')?;
    (!name.contains('`')).then_some(name)
}

/// serde's "one of `a`, `b`" / "`a` or `b`" / "`a`" / "there are no fields" as
/// "one of: a, b" (or "nothing here").
fn one_of(expected: &str) -> String {
    let names: Vec<&str> = expected.split('`').skip(1).step_by(2).collect();
    match names.as_slice() {
        [] => "nothing here".into(),
        [one] => format!("`{one}`"),
        many => format!("one of: {}", many.join(", ")),
    }
}

/// serde's name of what it expected, in the words of JSON and kea; `got` (as
/// [`got_kind`] words it) adds the largest value where a whole number was too large.
fn expected_kind(expected: &str, got: &str) -> String {
    let whole = |max: f64| {
        if got.parse::<f64>().is_ok_and(|x| x > max) {
            let max = if max < 1e15 {
                format!("{max}")
            } else {
                format!("{max:.1e}") // (2⁶⁴ − 1 in full is 20 digits)
            };
            format!("a whole number from 0 to {max}")
        } else {
            "a whole number ≥ 0".into()
        }
    };
    match expected {
        "f64" | "f32" => "a number".into(),
        "u64" | "usize" => whole(u64::MAX as f64),
        "u32" => whole(u32::MAX as f64),
        "u16" => whole(u16::MAX as f64),
        "u8" => whole(u8::MAX as f64),
        "i64" | "i32" | "isize" => "a whole number".into(),
        "a sequence" => "an array".into(),
        "a boolean" => "true or false".into(),
        "map" | "a map" | "newtype variant" | "struct variant" => "an object".into(),
        e if e.starts_with("struct ") => "an object".into(),
        e => e.into(),
    }
}

/// serde's description of what it got: `string "x"` → `a string ("x")`.
fn got_kind(got: &str) -> String {
    let value = |prefix: &str| got.strip_prefix(prefix).map(|v| v.trim_matches('`'));
    if let Some(s) = got.strip_prefix("string ") {
        format!("a string ({s})")
    } else if let Some(v) = value("integer ").or_else(|| value("floating point ")) {
        v.to_string()
    } else if let Some(v) = value("boolean ") {
        v.to_string()
    } else {
        match got {
            "map" => "an object".into(),
            "sequence" => "an array".into(),
            "unit value" => "null".into(),
            "unit variant" => "a string".into(),
            g => g.into(),
        }
    }
}

/// The most field errors one response lists (then one line says how many more).
pub const MAX_REPORTED_ERRORS: usize = 100;

/// The entry that ends an error list cut at [`MAX_REPORTED_ERRORS`], at the top level
/// (`""`): it stands for `omitted` errors left out. (The server caps its own lists with
/// the same entry, and reads the count back with [`omitted_count`].)
pub fn omitted_entry(omitted: usize) -> FieldError {
    FieldError::new(
        "",
        format!("… and {omitted} more errors (only the first {MAX_REPORTED_ERRORS} are listed)"),
    )
}

/// How many errors an entry of [`omitted_entry`]'s form (at any path) stands for;
/// `None` for an ordinary error.
pub fn omitted_count(e: &FieldError) -> Option<usize> {
    let rest = e.message.strip_prefix("… and ")?;
    let (count, tail) = rest.split_once(' ')?;
    if tail != format!("more errors (only the first {MAX_REPORTED_ERRORS} are listed)") {
        return None;
    }
    count.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn member_paths_quote_what_is_not_an_identifier() {
        assert_eq!(member_path("params", "q"), "params.q");
        assert_eq!(member_path("", "system"), "system");
        assert_eq!(member_path("params", "σ_1"), "params.σ_1");
        assert_eq!(member_path("params", "a.b"), r#"params["a.b"]"#);
        assert_eq!(member_path("set", "1x"), r#"set["1x"]"#);
        assert_eq!(member_path("set", ""), r#"set[""]"#);
        assert_eq!(member_path("set", "q\"]"), r#"set["q\"]"]"#);
        assert_eq!(member_path("", "a b"), r#"["a b"]"#);
    }

    fn plain(path: &str, message: &str) -> (String, String) {
        let e = plain_serde_error(
            FieldError::new(path, message),
            &[("target", "the desired effect")],
        );
        (e.path, e.message)
    }

    #[test]
    fn serde_messages_are_put_plainly() {
        assert_eq!(
            plain("", "missing field `target`"),
            ("target".into(), "missing: the desired effect".into())
        );
        assert_eq!(
            plain("mode.bisect", "missing field `param`"),
            (
                "mode.bisect.param".into(),
                "missing: this member is required".into()
            )
        );
        assert_eq!(
            plain(
                "target.threshold",
                "invalid type: string \"2\", expected f64"
            )
            .1,
            "expected a number, got a string (\"2\")"
        );
        assert_eq!(
            plain("runs", "invalid value: integer `-5`, expected u64").1,
            "expected a whole number ≥ 0, got -5"
        );
        assert_eq!(
            plain("mode.grid.params", "invalid type: map, expected a sequence").1,
            "expected an array, got an object"
        );
        assert_eq!(
            plain(
                "target.criterion",
                "unknown variant `xy`, expected one of `yz`, `zx`, `yx`"
            )
            .1,
            "unknown value \"xy\"; expected one of: yz, zx, yx"
        );
        assert_eq!(
            plain(
                "target.criteria",
                "unknown variant `mc`, expected `bound` or `covariance`"
            )
            .1,
            "unknown value \"mc\"; expected one of: bound, covariance"
        );
        assert_eq!(
            plain(
                "target.x",
                "unknown field `x`, expected one of `criterion`, `criteria`, `state`, `threshold`"
            )
            .1,
            "unknown member; expected one of: criterion, criteria, state, threshold"
        );
        assert_eq!(
            plain("target", "duplicate field `criteria`"),
            (
                "target.criteria".to_string(),
                "given twice, under its name and a former one; give `criteria` alone".to_string()
            )
        );
        assert_eq!(plain("a", "something else").1, "something else");
    }

    /// The messages as serde_json writes them for kea's field types, put plainly.
    #[test]
    fn serde_json_type_errors_read_in_json_words() {
        fn message<T: serde::de::DeserializeOwned + std::fmt::Debug>(json: &str) -> String {
            let m = serde_json::from_str::<T>(json).unwrap_err().to_string();
            // (the position serde_json appends to an error in text is not ours)
            let m = m.split(" at line ").next().unwrap().to_string();
            plain_serde_error(FieldError::new("", m), &[]).message
        }
        #[derive(Debug, serde::Deserialize)]
        #[allow(dead_code)]
        struct Options {
            points: usize,
        }
        assert_eq!(
            message::<usize>("-1"),
            "expected a whole number ≥ 0, got -1"
        );
        assert_eq!(
            message::<u64>("1.5"),
            "expected a whole number ≥ 0, got 1.5"
        );
        // Too large for the type: the range, not "≥ 0", which it is.
        assert_eq!(
            message::<u64>("1e20"),
            "expected a whole number from 0 to 1.8e19, got 1e+20"
        );
        assert_eq!(
            message::<u32>("5000000000"),
            "expected a whole number from 0 to 4294967295, got 5000000000"
        );
        assert_eq!(
            message::<Vec<f64>>(r#""a, expected b""#),
            r#"expected an array, got a string ("a, expected b")"#
        );
        assert_eq!(message::<f64>("true"), "expected a number, got true");
        assert_eq!(message::<bool>("null"), "expected true or false, got null");
        assert_eq!(message::<Options>("true"), "expected an object, got true");
        assert_eq!(
            message::<Vec<f64>>("{}"),
            "expected an array, got an object"
        );
        assert_eq!(message::<String>("{}"), "expected a string, got an object");
    }
}
