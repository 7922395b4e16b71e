//! The command-line subcommands other than `serve`: each reads its input, calls the
//! core, and prints. Errors go to stderr as `path: message`, one per line.

pub mod analyze;
pub mod identify;
pub mod monte_carlo;
pub mod nonlinear;
pub mod presets;
pub mod sensitivity;
pub mod synthesize;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use kea_core::work::Work;
use std::io::Write;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

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

/// Print a result as pretty JSON on stdout ([`print_text`]); on failure say so and
/// return the exit code.
pub fn print_json<T: serde::Serialize>(value: &T) -> Result<(), ExitCode> {
    match serde_json::to_string_pretty(value) {
        Ok(s) => print_text(&format!("{s}\n")),
        Err(e) => {
            eprintln!("cannot serialise the result: {e}");
            Err(ExitCode::from(EXIT_FAILURE))
        }
    }
}

/// Write a command's output to stdout and flush it: every command prints through here
/// (or [`print_json`]), so that no output is lost unsaid.
pub fn print_text(text: &str) -> Result<(), ExitCode> {
    let mut out = std::io::stdout().lock();
    stdout_written(out.write_all(text.as_bytes()).and_then(|()| out.flush()))
}

/// What a write to stdout came to. A failure (a full disk, a closed terminal) is said on
/// stderr, exit 1. A closed pipe (`kea … | head`) is not a failure: the reader has all it
/// wanted, so the output ends quietly, as a Unix filter's does (no panic as `print!`'s).
pub fn stdout_written(result: std::io::Result<()>) -> Result<(), ExitCode> {
    match result {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            eprintln!("cannot write to stdout: {e}");
            Err(ExitCode::from(EXIT_FAILURE))
        }
        _ => Ok(()),
    }
}

/// The JSON a command names: a file, `-` for stdin, or `preset:NAME` for a preset. Every failure
/// to get it is the user's to fix (exit 2): an unreadable file (with a hint when a
/// preset has that name), text that is not JSON (named with the file), an unknown
/// preset. The reason is on stderr.
pub fn read_json(arg: &str) -> Result<serde_json::Value, ExitCode> {
    let invalid = |message: String| {
        eprintln!("{message}");
        ExitCode::from(EXIT_INVALID)
    };
    if let Some(name) = arg.strip_prefix("preset:") {
        let text = kea_core::presets::get_json(name).ok_or_else(|| invalid(no_preset(name)))?;
        return kea_core::parse_json(text.as_bytes())
            .map_err(|e| invalid(format!("preset {name}: not valid JSON: {e}")));
    }
    // (Read as bytes: the parser names the encoding of a text that is not UTF-8.)
    if arg == "-" {
        let text = read_capped(std::io::stdin())
            .map_err(|e| invalid(format!("cannot read stdin: {e}")))?;
        return kea_core::parse_json(&text)
            .map_err(|e| invalid(format!("stdin: not valid JSON: {e}")));
    }
    let text = std::fs::File::open(arg)
        .and_then(read_capped)
        .map_err(|e| {
            let hint = if kea_core::presets::get_json(arg).is_some() {
                format!(" (for the preset, write preset:{arg})")
            } else {
                String::new()
            };
            invalid(format!("cannot read {arg}: {e}{hint}"))
        })?;
    kea_core::parse_json(&text).map_err(|e| invalid(format!("{arg}: not valid JSON: {e}")))
}

/// The most a command reads of its JSON input: 32 times the server's default body
/// limit, far beyond any model (a 200 × 200 matrix of 1000-character expressions is
/// refused by the expression limits long before), so that `/dev/zero` or a wrong
/// multi-gigabyte file is refused instead of read until memory runs out.
pub const MAX_INPUT_BYTES: u64 = 64 * 1024 * 1024;

/// All of `source`, or an error once it passes [`MAX_INPUT_BYTES`].
fn read_capped(source: impl std::io::Read) -> std::io::Result<Vec<u8>> {
    let mut text = Vec::new();
    std::io::Read::read_to_end(&mut source.take(MAX_INPUT_BYTES + 1), &mut text)?;
    if text.len() as u64 > MAX_INPUT_BYTES {
        return Err(std::io::Error::other(format!(
            "it is larger than {} MiB, beyond what kea reads (a model or request is far smaller: is it the right file?)",
            MAX_INPUT_BYTES / (1024 * 1024)
        )));
    }
    Ok(text)
}

/// The one wording of an unknown preset, with the list.
pub fn no_preset(name: &str) -> String {
    format!(
        "no preset \"{name}\" (presets: {})",
        kea_core::presets::names().join(", ")
    )
}

/// Where a command's `--csv` goes.
pub enum Csv {
    /// A regular file (or one still to be made): the CSV is written whole to a
    /// temporary file beside it and renamed over it only once the run is done
    /// ([`write_replacing`]), so that a run that fails or is stopped leaves the file as
    /// it was.
    File(PathBuf),
    /// Something that is not a regular file (`/dev/null`, a named pipe): opened up
    /// front and written in place, as there is nothing to replace.
    Device(PathBuf, std::fs::File),
    /// Stdout (`--csv -`), in place of the command's table.
    Stdout,
}

impl Csv {
    /// Check a command's `--csv` against its model argument and `--json`, before any
    /// work: `-` is stdout, refused with `--json` (which prints there too); a path that
    /// is the model file is refused, not overwritten; any other must be writable now
    /// ([`check_writable`]), but is not touched until the run is done. A refusal is
    /// input to fix (exit 2).
    pub fn open(csv: Option<&Path>, model: &str, json: bool) -> Result<Option<Csv>, ExitCode> {
        let refuse = |message: String| {
            eprintln!("{message}");
            Err(ExitCode::from(EXIT_INVALID))
        };
        let Some(path) = csv else {
            return Ok(None);
        };
        if path == Path::new("-") {
            if json {
                return refuse(
                    "--csv -: stdout carries the --json result; write the CSV to a file".into(),
                );
            }
            return Ok(Some(Csv::Stdout));
        }
        let is_file = model != "-" && !model.starts_with("preset:");
        if is_file
            && let (Ok(a), Ok(b)) = (path.canonicalize(), Path::new(model).canonicalize())
            && a == b
        {
            return refuse(format!(
                "--csv {}: that is the model file; write the CSV to another file",
                path.display()
            ));
        }
        match std::fs::metadata(path) {
            Ok(m) if !m.is_file() && !m.is_dir() => {
                let file = std::fs::OpenOptions::new()
                    .write(true)
                    .open(path)
                    .map_err(|e| cannot_write(path, &e, EXIT_INVALID))?;
                Ok(Some(Csv::Device(path.to_path_buf(), file)))
            }
            _ => check_writable(path).map(|()| Some(Csv::File(path.to_path_buf()))),
        }
    }

    /// Write the CSV text to its file or stdout.
    pub fn write(self, text: &str) -> Result<(), ExitCode> {
        match self {
            Csv::File(path) => write_replacing(&path, text),
            Csv::Device(path, mut file) => file
                .write_all(text.as_bytes())
                .and_then(|()| file.flush())
                .map_err(|e| cannot_write(&path, &e, EXIT_FAILURE)),
            Csv::Stdout => print_text(text),
        }
    }
}

/// Say on stderr that `path` cannot be written, and return `code`: [`EXIT_INVALID`]
/// before a run (a path to fix), [`EXIT_FAILURE`] after it (a full disk…).
fn cannot_write(path: &Path, e: &std::io::Error, code: u8) -> ExitCode {
    // tempfile ends its errors with ` at path "…"`, the temporary file's name; the
    // user named `path`, which is said first.
    let text = e.to_string();
    let reason = text
        .split_once(" at path \"")
        .map_or(text.as_str(), |(r, _)| r);
    eprintln!("cannot write {}: {reason}", path.display());
    ExitCode::from(code)
}

/// The file a written `path` really is: a symbolic link's target (which is replaced,
/// not the link), or `path` itself when it does not exist yet.
fn replaced_file(path: &Path) -> PathBuf {
    path.canonicalize().unwrap_or_else(|_| path.to_path_buf())
}

/// A new temporary file beside `target` (hidden, named after it), with the mode a file
/// created there would get (0666 less the umask) or, when `target` exists, its mode.
fn temporary_beside(target: &Path) -> std::io::Result<tempfile::NamedTempFile> {
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let prefix = format!(
        ".{}.",
        target.file_name().unwrap_or_default().to_string_lossy()
    );
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".tmp");
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let file = builder.tempfile_in(dir)?;
    if let Ok(m) = std::fs::metadata(target) {
        file.as_file().set_permissions(m.permissions())?;
    }
    Ok(file)
}

/// Refuse up front (exit 2) an output path that could not be written after the run:
/// a directory, a file without write permission, a directory that is missing or
/// without write permission (where the temporary file goes). Nothing is left behind.
fn check_writable(path: &Path) -> Result<(), ExitCode> {
    let target = replaced_file(path);
    if target.exists() {
        // (a directory: "Is a directory", from the system where it says so)
        std::fs::OpenOptions::new()
            .write(true)
            .open(&target)
            .map_err(|e| cannot_write(path, &e, EXIT_INVALID))?;
    }
    if target.is_dir() {
        let e = std::io::Error::from(std::io::ErrorKind::IsADirectory);
        return Err(cannot_write(path, &e, EXIT_INVALID));
    }
    temporary_beside(&target)
        .map(drop)
        .map_err(|e| cannot_write(path, &e, EXIT_INVALID))
}

/// Write `text` as the whole of the file `path` (after [`check_writable`]): into a
/// temporary file beside it, flushed to disk, then renamed over `path`, so that `path`
/// holds either its old contents or all of `text`, never a part. On failure (a full
/// disk…) the temporary file is removed and the failure said (exit 1: the run is done,
/// the input was not at fault).
fn write_replacing(path: &Path, text: &str) -> Result<(), ExitCode> {
    let target = replaced_file(path);
    let written = temporary_beside(&target).and_then(|mut file| {
        file.as_file_mut().write_all(text.as_bytes())?;
        file.as_file().sync_all()?;
        file.persist(&target).map(drop).map_err(|e| e.error)
    });
    written.map_err(|e| cannot_write(path, &e, EXIT_FAILURE))
}

/// A command that runs one of the core's kinds on a request it made of its arguments
/// ([`kea_core::registry`]): the request is read and compiled once, its work held to
/// `--max-work`, then it runs with the progress bar and prints its text, JSON or CSV.
/// The model is a file here, not a request's member: its errors are at the file's
/// own paths (`system.a[0][1]`, not `model.system.a[0][1]`).
pub struct KindRun<'a> {
    pub kind: &'static str,
    /// The model argument (a file, `-` or `preset:NAME`), for `--csv`'s checks.
    pub input: &'a str,
    pub json: bool,
    pub csv: Option<&'a Path>,
    pub limit: &'a WorkLimit,
    /// The input is a model file (`kea analyze`, `kea monte-carlo`), not a request.
    pub model_file: bool,
}

impl KindRun<'_> {
    /// Run the request and print its outcome; exit 0, or the failure's code.
    pub fn run<E: kea_core::exec::Executor>(
        &self,
        request: serde_json::Value,
        exec: &E,
    ) -> ExitCode {
        match self.outcome(request, exec) {
            Ok(_) => ExitCode::SUCCESS,
            Err(code) => code,
        }
    }

    /// Run the request and print its outcome, which is returned (a command whose exit
    /// code depends on it: a synthesis that found no answer).
    pub fn outcome<E: kea_core::exec::Executor>(
        &self,
        request: serde_json::Value,
        exec: &E,
    ) -> Result<kea_core::registry::Outcome, ExitCode> {
        self.outcome_with(request, exec, |_| Ok(()))
    }

    /// [`KindRun::outcome`], with `inspect` given the prepared request before its work
    /// is checked (`kea identify --data-csv` writes the data it read or simulated).
    pub fn outcome_with<E: kea_core::exec::Executor>(
        &self,
        request: serde_json::Value,
        exec: &E,
        inspect: impl FnOnce(&kea_core::registry::Prepared) -> Result<(), ExitCode>,
    ) -> Result<kea_core::registry::Outcome, ExitCode> {
        let prepared = kea_core::registry::prepare(self.kind, request)
            .map_err(|e| report_error(&self.located(e)))?;
        inspect(&prepared)?;
        self.limit.check(Ok(prepared.work()))?;
        // (After the work: a run too large is told so first, whatever else it asks.)
        prepared
            .check()
            .map_err(|e| report_error(&self.located(e)))?;
        let csv = Csv::open(self.csv, self.input, self.json)?;
        let start = Instant::now();
        let mut bar = Bar::new(self.kind);
        let outcome = prepared.run(exec, &mut bar, &kea_core::exec::Forgetful);
        bar.finish();
        let mut outcome = outcome.map_err(|e| report_error(&self.located(e)))?;
        outcome.timing().wall_ms = start.elapsed().as_secs_f64() * 1e3;
        let text_on_stdout = !matches!(csv, Some(Csv::Stdout));
        if let Some(csv) = csv {
            csv.write(&outcome.csv().unwrap_or_default())?;
        }
        if self.json {
            print_text(&format!("{}\n", outcome.to_json_pretty()))?;
        } else if text_on_stdout {
            print_text(&outcome.text())?;
        }
        Ok(outcome)
    }

    /// An error at the request's paths as the command's input has them: a model
    /// file's own (`model.x` is `x`), a request file's as they are.
    fn located(&self, e: kea_core::Error) -> kea_core::Error {
        if self.model_file {
            e.without_prefix("model")
        } else {
            e
        }
    }
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
    let value_text = value;
    let value: f64 = value
        .trim()
        .parse()
        .map_err(|_| format!("`{}` is not a number (in `{arg}`)", value.trim()))?;
    if !value.is_finite() {
        return Err(format!("`{arg}`: the value must be finite"));
    }
    if kea_core::json::underflows(value_text.trim(), value) {
        return Err(format!(
            "`{arg}`: the value is below the smallest f64 (≈ 4.9e-324) and would be read as 0: write 0 if 0 is meant"
        ));
    }
    Ok((name.to_string(), value))
}

/// The most threads `--threads` accepts: more than any machine here has cores, and
/// far below what would exhaust the process (each thread reserves a stack).
pub const MAX_THREADS: usize = 256;

/// `--threads T`: 0 (every core) to [`MAX_THREADS`].
pub fn parse_threads(arg: &str) -> Result<usize, String> {
    let t: usize = arg
        .trim()
        .parse()
        .map_err(|_| format!("expected a whole number of threads (0: every core), got `{arg}`"))?;
    if t > MAX_THREADS {
        return Err(format!(
            "at most {MAX_THREADS} threads (0: every core), got {t}"
        ));
    }
    Ok(t)
}

/// The `--set` arguments as overrides; a name given twice is refused (exit 2), as a
/// key given twice in JSON is, rather than the last one silently winning.
pub fn overrides(set: &[(String, f64)]) -> Result<kea_core::Overrides, ExitCode> {
    let mut out = kea_core::Overrides::new();
    for (name, value) in set {
        if let Some(before) = out.insert(name.clone(), *value) {
            eprintln!(
                "--set {name} is given twice ({name}={}, then {name}={}): give each param once",
                kea_core::text::short(before),
                kea_core::text::short(*value)
            );
            return Err(ExitCode::from(EXIT_INVALID));
        }
    }
    Ok(out)
}

/// The work limit of the commands that run the core: the server's estimate and its
/// default, so that a model the service refuses is not silently left running for hours.
#[derive(Debug, clap::Args)]
pub struct WorkLimit {
    /// Refuse a run whose estimated work is above this. A unit is about a nanosecond
    /// of one core (the server's estimate, openapi.yaml "Work": for an analysis, steps
    /// × (N³ + 16N² + 200 + what varying inputs and expressions in t cost)), so the
    /// default is ≈ 17 minutes; `--max-work inf` lifts the limit.
    #[arg(long, env = "KEA_MAX_WORK", default_value_t = kea_core::work::DEFAULT_MAX_WORK, value_name = "UNITS",
          value_parser = parse_limit)]
    pub max_work: f64,
}

impl WorkLimit {
    /// Ok to run; else the estimate's error, or why the work is refused, on stderr and
    /// the exit code for invalid input.
    pub fn check(&self, work: Result<Work, kea_core::Error>) -> Result<(), ExitCode> {
        let work = work.map_err(|e| report_error(&e))?;
        if work.units <= self.max_work {
            return Ok(());
        }
        // The model file is the root here, not a request's `model` member.
        let path = work.path.strip_prefix("model.").unwrap_or(&work.path);
        eprintln!(
            "{path}: estimated work {:.3e} ({}) is above --max-work {:.3e}; make it smaller, or raise --max-work (KEA_MAX_WORK) to run it anyway",
            work.units, work.explain, self.max_work
        );
        Err(ExitCode::from(EXIT_INVALID))
    }
}

/// Parse `--max-work`: a positive number (or `inf`).
pub(crate) fn parse_limit(arg: &str) -> Result<f64, String> {
    match arg.trim().parse::<f64>() {
        Ok(x) if x > 0.0 => Ok(x),
        _ => Err(format!("expected a positive number (or inf), got `{arg}`")),
    }
}

/// The core's progress as a bar on stderr, shown once a run has taken a second (short
/// runs print nothing extra) and never when stderr is not a terminal (pipes, files).
pub struct Bar {
    bar: ProgressBar,
    start: Instant,
    shown: bool,
}

/// Positions of the bar (per mille).
const BAR_LEN: u64 = 1000;

impl Bar {
    pub fn new(what: &'static str) -> Self {
        let bar = ProgressBar::with_draw_target(Some(BAR_LEN), ProgressDrawTarget::hidden());
        if let Ok(style) =
            ProgressStyle::with_template("{msg} [{bar:30}] {percent:>3}% {elapsed} (ETA {eta})")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_message(what);
        Bar {
            bar,
            start: Instant::now(),
            shown: false,
        }
    }

    /// Remove the bar (if it was drawn) before the result is printed.
    pub fn finish(self) {
        self.bar.finish_and_clear();
    }
}

impl kea_core::Progress for Bar {
    fn report(&mut self, fraction: f64) -> ControlFlow<()> {
        if !self.shown && self.start.elapsed() >= Duration::from_secs(1) {
            self.bar.set_draw_target(ProgressDrawTarget::stderr());
            self.shown = true;
        }
        self.bar
            .set_position((fraction.clamp(0.0, 1.0) * BAR_LEN as f64) as u64);
        ControlFlow::Continue(())
    }
}

/// `data.csv`, a path relative to the request file (or to the working directory for a
/// request on stdin), read into `data.csv_text`.
pub fn read_data_csv(
    obj: &mut serde_json::Map<String, serde_json::Value>,
    request: &str,
) -> Result<(), ExitCode> {
    let Some(serde_json::Value::Object(data)) = obj.get_mut("data") else {
        return Ok(());
    };
    let Some(serde_json::Value::String(file)) = data.get("csv") else {
        return Ok(());
    };
    let base = match Path::new(request).parent() {
        Some(dir) if request != "-" && !request.starts_with("preset:") => dir.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let path = base.join(file);
    let text = std::fs::read(&path)
        .map_err(|e| {
            eprintln!("data.csv: cannot read {}: {e}", path.display());
            ExitCode::from(EXIT_INVALID)
        })
        .and_then(|bytes| {
            String::from_utf8(bytes).map_err(|_| {
                eprintln!("data.csv: {} is not UTF-8 text", path.display());
                ExitCode::from(EXIT_INVALID)
            })
        })?;
    data.remove("csv");
    data.insert("csv_text".into(), text.into());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{parse_limit, parse_override};

    /// The limit the web page asks about before a run in the browser (the core's
    /// `DEFAULT_MAX_WORK`, through the wasm module) is the one `kea serve` holds to.
    #[test]
    fn serve_holds_to_the_cores_default_work_limit() {
        use clap::Parser;
        let cli = crate::Cli::try_parse_from(["kea", "serve"]).expect("kea serve parses");
        let Some(crate::Command::Serve(args)) = cli.command else {
            panic!("not the serve command: {cli:?}");
        };
        assert_eq!(args.max_work, kea_core::work::DEFAULT_MAX_WORK);
    }

    #[test]
    fn work_limit_parses_positive_numbers_only() {
        assert_eq!(parse_limit("1e12"), Ok(1e12));
        assert_eq!(parse_limit("inf"), Ok(f64::INFINITY));
        for bad in ["0", "-5", "NaN", "lots"] {
            assert!(parse_limit(bad).unwrap_err().contains("positive"), "{bad}");
        }
    }

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
