//! `kea nonlinear REQUEST.json [--model FILE|preset:NAME] [--json] [--csv FILE|-]
//! [--data-csv FILE] [--max-work UNITS]`: the EKF and the iterative regularised
//! procedure over measured or simulated data (METHOD §4, docs/nonlinear.md). The
//! request's `data.csv` names a CSV file relative to the request file; it is read here
//! and sent to the core as `data.csv_text`.

use crate::Run;
use crate::parallel::Rayon;
use kea_core::registry::Prepared;
use serde_json::Value;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The request (JSON: `model`, `data`, `procedure`); see docs/nonlinear.md. `-`
    /// reads it from stdin.
    pub request: String,
    /// Take the model from this file, or `preset:NAME` (`preset:seed-002`; replaces the
    /// request's `model`).
    #[arg(long)]
    pub model: Option<String>,
    /// Print the whole result as JSON instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Also write the decimated traces as CSV to this file; `-` writes them to stdout in
    /// place of the table (not with --json).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Also write the data the run uses — read, or simulated from the request's
    /// `data.truth` — as CSV to this file (`t`, the measurements, `STATE_true`: the
    /// format `data.csv` reads), before the run.
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
                "a nonlinear request is a JSON object ({\"model\": …, \"data\": …}, docs/nonlinear.md)",
            ));
        };
        match self.model.as_deref() {
            // (The nonlinear presets are the core's: it reads "preset:NAME" itself.)
            Some(p) if p.starts_with("preset:") => {
                obj.insert("model".into(), p.into());
            }
            Some(file) => match super::read_json(file) {
                Ok(m) => {
                    obj.insert("model".into(), m);
                }
                Err(c) => return c,
            },
            None => {}
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
            kind: "nonlinear",
            input: &self.request,
            json: self.json,
            csv: self.csv.as_deref(),
            limit: &self.limit,
            model_file: false,
        };
        let write_data = |prepared: &Prepared| {
            let (Some(path), Prepared::Nonlinear(r)) = (&self.data_csv, prepared) else {
                return Ok(());
            };
            let text = match kea_core::nonlinear::data_csv(r) {
                Ok(t) => t,
                Err(e) => return Err(super::report_error(&e)),
            };
            super::Csv::open(Some(path), &self.request, false)?
                .expect("a path was given")
                .write(&text)
        };
        match run.outcome_with(value, &exec, write_data) {
            Ok(_) => ExitCode::SUCCESS,
            Err(code) => code,
        }
    }
}
