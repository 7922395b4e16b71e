//! The names of the states and of the measurements: not empty, no spaces at their
//! ends, no invisible or control characters, no duplicates.

use super::Errors;

/// A character that shows as nothing: a name of them looks empty, and one inside a
/// name makes it look like another (`x` and `x\u{200B}`).
fn is_invisible(c: char) -> bool {
    matches!(c, '\u{00AD}' | '\u{034F}' | '\u{180E}' | '\u{200B}'..='\u{200F}'
        | '\u{202A}'..='\u{202E}' | '\u{2060}'..='\u{2064}' | '\u{2066}'..='\u{206F}'
        | '\u{FEFF}')
}

pub(crate) fn check_names(names: &[String], path: &str, errs: &mut Errors) {
    for (i, name) in names.iter().enumerate() {
        if name.chars().all(|c| c.is_whitespace() || is_invisible(c)) {
            errs.at(&format!("{path}[{i}]"), "a name must not be empty");
        } else if name.trim() != name {
            // ("x" and "x " were two states that looked one.)
            errs.at(
                &format!("{path}[{i}]"),
                format!(
                    "a name must not begin or end with a space, got {}",
                    serde_json::Value::from(name.as_str())
                ),
            );
        } else if let Some(c) = name.chars().find(|&c| is_invisible(c)) {
            errs.at(
                &format!("{path}[{i}]"),
                format!(
                    "a name must not contain an invisible character (U+{:04X}), got {}",
                    c as u32,
                    serde_json::Value::from(name.as_str())
                ),
            );
        } else if name.chars().any(char::is_control) {
            // (A line break in a name split the command line's table row in two.)
            errs.at(
                &format!("{path}[{i}]"),
                format!(
                    "a name must not contain control characters (a line break, a tab, NUL), got {}",
                    serde_json::Value::from(name.as_str())
                ),
            );
        } else if names[..i].contains(name) {
            errs.at(
                &format!("{path}[{i}]"),
                format!("duplicate name \"{name}\""),
            );
        }
    }
}
