//! `kea synthesize [REQUEST.json] [--model FILE|preset:NAME | --preset NAME]
//! [--set name=value]… [--threads N] [--json]`: the error levels that reach a desired
//! filtering effect (METHOD §1.7), on every core. Without a request, a preset's own
//! example (`presets/synthesis/NAME.json`).

use crate::Run;
use crate::parallel::Rayon;
use kea_core::synthesis::Status;
use serde_json::Value;
use std::process::ExitCode;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The synthesis request (JSON: `target`, `mode`, and `model` unless given below);
    /// see docs/synthesis.md. Left out with a preset's model: that preset's example
    /// (`kea preset NAME --synthesis` prints it).
    pub request: Option<String>,
    /// Take the model from this file, or `preset:NAME` (replaces the request's `model`).
    #[arg(long, conflicts_with = "preset")]
    pub model: Option<String>,
    /// Take the model from a preset (see `kea presets`): the same as `--model preset:NAME`.
    #[arg(long)]
    pub preset: Option<String>,
    /// Override a model parameter at every point, e.g. `--set c=0.25` (repeatable; not
    /// a name the request's `set` gives too).
    #[arg(long = "set", value_name = "NAME=VALUE", value_parser = super::parse_override)]
    pub set: Vec<(String, f64)>,
    /// Threads for the analyses (default or 0: every core; at most 256). Answers do not
    /// depend on it.
    #[arg(long, value_parser = super::parse_threads)]
    pub threads: Option<usize>,
    /// Print the whole result as JSON instead of the table and message.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub limit: super::WorkLimit,
}

impl Args {
    /// The example of the preset given by `--preset NAME` or `--model preset:NAME`,
    /// for a command without a request.
    fn preset_example(&self) -> Result<Value, ExitCode> {
        let name = self
            .preset
            .as_deref()
            .or_else(|| self.model.as_deref()?.strip_prefix("preset:"));
        let Some(name) = name else {
            eprintln!(
                "missing: the synthesis request (a file, or `-` for stdin); or --preset NAME alone for that preset's example"
            );
            return Err(ExitCode::from(super::EXIT_INVALID));
        };
        let text = kea_core::presets::synthesis_json(name).ok_or_else(|| {
            eprintln!("{}", super::no_preset(name));
            ExitCode::from(super::EXIT_INVALID)
        })?;
        Ok(kea_core::parse_json(text.as_bytes()).expect("the examples parse (tested)"))
    }
}

impl Run for Args {
    fn run(self) -> ExitCode {
        if self.request.as_deref() == Some("-") && self.model.as_deref() == Some("-") {
            eprintln!(
                "the request and --model are both `-`, but stdin can be read once: give one of them as a file"
            );
            return ExitCode::from(super::EXIT_INVALID);
        }
        let mut value = match &self.request {
            Some(arg) => match super::read_json(arg) {
                Ok(v) => v,
                Err(c) => return c,
            },
            None => match self.preset_example() {
                Ok(v) => v,
                Err(c) => return c,
            },
        };
        let Value::Object(obj) = &mut value else {
            return super::report_error(&kea_core::Error::invalid(
                "",
                "a synthesis request is a JSON object ({\"target\": …, \"mode\": …, \"model\": …}, docs/synthesis.md)",
            ));
        };
        let model = match (&self.model, &self.preset) {
            (Some(arg), _) => Some(arg.clone()),
            (None, Some(name)) => Some(format!("preset:{name}")),
            (None, None) => None,
        };
        if let Some(arg) = model {
            match super::read_json(&arg) {
                Ok(m) => {
                    obj.insert("model".into(), m);
                }
                Err(c) => return c,
            }
        } else if !obj.contains_key("model") {
            return super::report_error(&kea_core::Error::invalid(
                "model",
                "missing: give the model in the request, or with --model FILE|preset:NAME",
            ));
        }
        let overrides = match super::overrides(&self.set) {
            Ok(s) => s,
            Err(code) => return code,
        };
        if !overrides.is_empty() {
            let set = obj
                .entry("set")
                .or_insert_with(|| Value::Object(Default::default()));
            if let Value::Object(set) = set {
                // As with a name given twice to --set: refused, not the last one winning.
                for (name, value) in &overrides {
                    if let Some(before) = set.get(name) {
                        eprintln!(
                            "--set {name}={} and the request's set.{name} = {before} both give {name}: give it once (drop one of them)",
                            kea_core::text::short(*value)
                        );
                        return ExitCode::from(super::EXIT_INVALID);
                    }
                }
                for (k, v) in overrides {
                    set.insert(k, v.into());
                }
            }
        }
        let exec = match Rayon::new(self.threads) {
            Ok(x) => x,
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::from(super::EXIT_FAILURE);
            }
        };
        let run = super::KindRun {
            kind: "synthesis",
            input: self.request.as_deref().unwrap_or("-"),
            json: self.json,
            csv: None,
            limit: &self.limit,
            model_file: false,
        };
        let result = match run.outcome(value, &exec) {
            Ok(kea_core::registry::Outcome::Synthesis(r)) => r,
            Ok(_) => unreachable!("a synthesis request gives a synthesis"),
            Err(code) => return code,
        };
        match result.status {
            Status::Found | Status::Table => ExitCode::SUCCESS,
            // A valid run without an answer (not found, non-monotonic, whole range).
            _ => ExitCode::from(super::EXIT_FAILURE),
        }
    }
}
