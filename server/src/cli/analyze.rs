//! `kea analyze MODEL.json|preset:NAME [--set name=value]… [--budget] [--json] [--csv FILE|-]`.

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
        let request = serde_json::json!({ "model": model, "set": set, "budget": self.budget });
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
