//! `kea analyze MODEL.json|preset:NAME [--set name=value]… [--budget]
//! [--truth FILE|preset:NAME] [--truth-set name=value]… [--json] [--csv FILE|-]`.

use crate::Run;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The model file (JSON, the format of `kea preset NAME`), `-` for stdin, or `preset:NAME`.
    pub model: String,
    /// Override a model parameter, e.g. `--set q=0.5` (repeatable).
    #[arg(long = "set", value_name = "NAME=VALUE", value_parser = super::parse_override)]
    pub set: Vec<(String, f64)>,
    /// Also the error budget: each error source's share of every state's filtered and
    /// open-loop variance (one more covariance recursion per source).
    #[arg(long)]
    pub budget: bool,
    /// The mismatched filter: the world is this model (same states and measurements),
    /// the filter is designed on MODEL. With --truth-set only: MODEL with those params.
    #[arg(long, value_name = "FILE")]
    pub truth: Option<String>,
    /// A param the truth has another value of, e.g. `--truth-set sd=10` (repeatable):
    /// the filter is designed on MODEL (and --set), the world has these values.
    #[arg(long = "truth-set", value_name = "NAME=VALUE", value_parser = super::parse_override)]
    pub truth_set: Vec<(String, f64)>,
    /// Print the whole result as JSON instead of the criteria table.
    #[arg(long)]
    pub json: bool,
    /// Also write the decimated traces as CSV to this file (t, then every series of
    /// every state; an empty cell is undefined); `-` writes them to stdout in place of
    /// the table (not with --json). The model file itself is refused.
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
        let set = match super::overrides(&self.set) {
            Ok(s) => s,
            Err(code) => return code,
        };
        let mut request = serde_json::json!({ "model": model, "set": set, "budget": self.budget });
        if self.truth.is_some() || !self.truth_set.is_empty() {
            let truth_set = match super::overrides(&self.truth_set) {
                Ok(s) => s,
                Err(code) => return code,
            };
            let mut truth = serde_json::json!({ "set": truth_set });
            if let Some(file) = &self.truth {
                truth["model"] = match super::read_json(file) {
                    Ok(m) => m,
                    Err(code) => return code,
                };
            }
            request["truth"] = truth;
        }
        let run = super::KindRun {
            kind: "analysis",
            input: &self.model,
            json: self.json,
            csv: self.csv.as_deref(),
            limit: &self.limit,
            model_file: true,
        };
        run.run(request, &kea_core::exec::Sequential)
    }
}
