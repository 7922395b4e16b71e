//! `kea monte-carlo MODEL.json|preset:NAME [--runs R] [--seed S]
//! [--truth process|mean|FILE|preset:NAME] [--truth-set name=value]…
//! [--model-error white|constant] [--trace-points ROWS] [--set name=value]… [--threads T]
//! [--max-work UNITS] [--json] [--csv FILE|-]`: the Monte Carlo of METHOD §1.8 — real
//! (simulated) against potential (Riccati) accuracy; with a truth model or
//! `--truth-set`, of the mismatched filter (the runs imitate the truth). R is 1000
//! unless given. The report is text, or JSON with `--json`; `--csv` also writes the
//! traces to a file (or, as `-`, to stdout in place of the text). `kea simulate`, its
//! former name, is an alias.

use crate::Run;
use crate::parallel::Rayon;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum ModelErrorArg {
    White,
    Constant,
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The model file (JSON), `-` for stdin, or `preset:NAME` for a preset (see `kea presets`).
    pub model: String,
    /// Number of runs R.
    #[arg(long, default_value_t = 1000)]
    pub runs: u64,
    /// Seed of the random streams (same seed, same numbers, whatever --threads).
    #[arg(long, default_value_t = kea_core::monte_carlo::DEFAULT_SEED)]
    pub seed: u64,
    /// What the filter is compared with: `process` (the noisy process Y), `mean` (the
    /// mean y, seed 000), or a truth model (a file, `preset:NAME`): the mismatched
    /// filter, designed on MODEL, in the truth's world (`./process` for a file of
    /// that name).
    #[arg(long, value_name = "process|mean|FILE", default_value = "process")]
    pub truth: String,
    /// A param the truth has another value of, e.g. `--truth-set sd=10` (repeatable):
    /// the runs imitate MODEL with these values, the filter is designed on MODEL.
    #[arg(long = "truth-set", value_name = "NAME=VALUE", value_parser = super::parse_override)]
    pub truth_set: Vec<(String, f64)>,
    /// Model error drawn at every step (white) or once per run (a constant bias).
    #[arg(long, value_enum, default_value = "white")]
    pub model_error: ModelErrorArg,
    /// Rows of the traces (bucket averages).
    #[arg(long)]
    pub trace_points: Option<usize>,
    /// Threads (default or 0: every core; at most 256). Results do not depend on it.
    #[arg(long, value_parser = super::parse_threads)]
    pub threads: Option<usize>,
    /// Override a model parameter, e.g. `--set q=0.5` (repeatable).
    #[arg(long = "set", value_name = "NAME=VALUE", value_parser = super::parse_override)]
    pub set: Vec<(String, f64)>,
    /// Print the whole result as JSON.
    #[arg(long)]
    pub json: bool,
    /// Also write the traces (potential against real SKOs) as CSV to this file; `-`
    /// writes them to stdout in place of the report (not with --json). The model file
    /// itself is refused.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    #[command(flatten)]
    pub limit: super::WorkLimit,
}

impl Run for Args {
    fn run(self) -> ExitCode {
        let model = match super::read_json(&self.model) {
            Ok(m) => m,
            Err(code) => return code,
        };
        let exec = match Rayon::new(self.threads) {
            Ok(x) => x,
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::from(super::EXIT_FAILURE);
            }
        };
        let set = match super::overrides(&self.set) {
            Ok(s) => s,
            Err(code) => return code,
        };
        let mut request = serde_json::json!({
            "model": model,
            "set": set,
            "runs": self.runs,
            "seed": self.seed,
            // (the names of the JSON and of the flags: process, white…)
            "model_error": match self.model_error {
                ModelErrorArg::White => "white",
                ModelErrorArg::Constant => "constant",
            },
        });
        let reading = matches!(self.truth.as_str(), "process" | "mean");
        if reading && self.truth_set.is_empty() {
            request["truth"] = self.truth.clone().into();
        } else {
            if self.truth == "mean" {
                eprintln!(
                    "--truth-set imitates the truth's process: it cannot go with --truth mean"
                );
                return ExitCode::from(super::EXIT_INVALID);
            }
            let truth_set = match super::overrides(&self.truth_set) {
                Ok(s) => s,
                Err(code) => return code,
            };
            let mut truth = serde_json::json!({ "set": truth_set });
            if !reading {
                truth["model"] = match super::read_json(&self.truth) {
                    Ok(m) => m,
                    Err(code) => return code,
                };
            }
            request["truth"] = truth;
        }
        if let Some(rows) = self.trace_points {
            request["trace_points"] = rows.into();
        }
        let run = super::KindRun {
            kind: "monte_carlo",
            input: &self.model,
            json: self.json,
            csv: self.csv.as_deref(),
            limit: &self.limit,
            model_file: true,
        };
        run.run(request, &exec)
    }
}
