//! `kea identify REQUEST.json [--model FILE|preset:NAME] [--method M] [--json]
//! [--csv FILE|-] [--data-csv FILE] [--max-work UNITS]`: the maximum-likelihood params of a discrete
//! model from measured data (METHOD §3). The request's `data.csv` names a CSV file
//! relative to the request file; it is read here and sent to the core as
//! `data.csv_text`.

use crate::Run;
use crate::parallel::Rayon;
use serde_json::Value;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum MethodArg {
    Scoring,
    Gradient,
    Conjugate,
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The identification request (JSON: `model`, `data`, `estimate`, `method`); see
    /// docs/identification.md. `-` reads it from stdin.
    pub request: String,
    /// Take the model from this file, or `preset:NAME` (replaces the request's `model`).
    #[arg(long)]
    pub model: Option<String>,
    /// The minimiser (replaces the request's `method`; default scoring).
    #[arg(long, value_enum)]
    pub method: Option<MethodArg>,
    /// Print the whole result as JSON instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Also write the innovations at the optimum, step by step (`t,nis,innovation:NAME…`),
    /// as CSV to this file; `-` writes them to stdout in place of the table (not with --json).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Also write the measurements the fit uses — read, or simulated by the request's
    /// `data.simulate` — as CSV to this file (the format `data.csv` reads), before the fit.
    #[arg(long, value_name = "FILE")]
    pub data_csv: Option<PathBuf>,
    #[command(flatten)]
    pub limit: super::WorkLimit,
}

impl Run for Args {
    fn run(self) -> ExitCode {
        let mut value = match super::read_json(&self.request) {
            Ok(v) => v,
            Err(c) => return c,
        };
        let Value::Object(obj) = &mut value else {
            return super::report_error(&kea_core::Error::invalid(
                "",
                "an identification request is a JSON object ({\"model\": …, \"data\": …, \"estimate\": …}, docs/identification.md)",
            ));
        };
        if let Some(arg) = &self.model {
            match super::read_json(arg) {
                Ok(m) => {
                    obj.insert("model".into(), m);
                }
                Err(c) => return c,
            }
        }
        if let Some(Value::String(name)) = obj.get("model")
            && let Some(preset) = name.strip_prefix("preset:")
        {
            match super::read_json(&format!("preset:{preset}")) {
                Ok(m) => {
                    obj.insert("model".into(), m);
                }
                Err(c) => return c,
            }
        }
        if let Some(m) = self.method {
            let name = match m {
                MethodArg::Scoring => "scoring",
                MethodArg::Gradient => "gradient",
                MethodArg::Conjugate => "conjugate",
            };
            obj.insert("method".into(), name.into());
        }
        if let Err(code) = super::read_data_csv(obj, &self.request) {
            return code;
        }
        let exec = match Rayon::new(Some(1)) {
            Ok(x) => x,
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::from(super::EXIT_FAILURE);
            }
        };
        let run = super::KindRun {
            kind: "identification",
            input: &self.request,
            json: self.json,
            csv: self.csv.as_deref(),
            limit: &self.limit,
            model_file: false,
        };
        let write_data = |prepared: &kea_core::registry::Prepared| {
            let (Some(path), kea_core::registry::Prepared::Identification(r)) =
                (&self.data_csv, prepared)
            else {
                return Ok(());
            };
            let names = r.measurement_names();
            super::Csv::open(Some(path), &self.request, false)?
                .expect("a path was given")
                .write(&kea_core::identification::to_csv(&r.data, &names))
        };
        match run.outcome_with(value, &exec, write_data) {
            Ok(_) => ExitCode::SUCCESS,
            Err(code) => code,
        }
    }
}
