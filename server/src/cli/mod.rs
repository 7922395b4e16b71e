//! The command-line subcommands other than `serve`: each reads its input, calls the
//! core, and prints. Errors go to stderr as `path: message`, one per line.

pub mod analyze;
pub mod presets;
pub mod simulate;
pub mod synthesize;

use std::process::ExitCode;

/// Exit code for invalid input (a model or argument the user must fix).
pub const EXIT_INVALID: u8 = 2;
/// Exit code for any other failure.
pub const EXIT_FAILURE: u8 = 1;

/// Print a core error to stderr, one `path: message` line per field error, and
/// return its exit code: 2 for invalid input, 1 otherwise.
pub fn report_error(err: &kea_core::Error) -> ExitCode {
    for e in err.field_errors() {
        eprintln!("{e}");
    }
    match err {
        kea_core::Error::Invalid(_) => ExitCode::from(EXIT_INVALID),
        _ => ExitCode::from(EXIT_FAILURE),
    }
}

/// Print a result as pretty JSON on stdout; on failure say so and return the exit code.
pub fn print_json<T: serde::Serialize>(value: &T) -> Result<(), ExitCode> {
    match serde_json::to_string_pretty(value) {
        Ok(s) => {
            print_text(&format!("{s}\n"));
            Ok(())
        }
        Err(e) => {
            eprintln!("cannot serialise the result: {e}");
            Err(ExitCode::from(EXIT_FAILURE))
        }
    }
}

/// Write to stdout; a closed pipe (`kea … | head`) ends the output quietly instead of
/// panicking as `print!` does.
pub fn print_text(text: &str) {
    use std::io::Write;
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
}

/// Parse one `--set name=value` argument.
pub fn parse_override(arg: &str) -> Result<(String, f64), String> {
    let (name, value) = arg
        .split_once('=')
        .ok_or_else(|| format!("expected name=value (e.g. q=0.5), got `{arg}`"))?;
    let name = name.trim();
    if name.is_empty() {
        return Err(format!("missing the parameter name before `=` in `{arg}`"));
    }
    let value: f64 = value
        .trim()
        .parse()
        .map_err(|_| format!("`{}` is not a number (in `{arg}`)", value.trim()))?;
    if !value.is_finite() {
        return Err(format!("`{arg}`: the value must be finite"));
    }
    Ok((name.to_string(), value))
}

#[cfg(test)]
mod tests {
    use super::parse_override;

    #[test]
    fn overrides_parse_and_reject_bad_syntax() {
        assert_eq!(parse_override("q=0.5"), Ok(("q".into(), 0.5)));
        assert_eq!(parse_override(" r = -1e3 "), Ok(("r".into(), -1000.0)));
        assert!(
            parse_override("q")
                .unwrap_err()
                .contains("expected name=value")
        );
        assert!(parse_override("=1").unwrap_err().contains("parameter name"));
        assert!(
            parse_override("q=abc")
                .unwrap_err()
                .contains("not a number")
        );
        assert!(parse_override("q=inf").unwrap_err().contains("finite"));
    }
}
