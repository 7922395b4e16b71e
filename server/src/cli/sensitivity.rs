//! `kea sensitivity MODEL.json|preset:NAME [--set name=value]… [--param NAME]…
//! [--relative-step H] [--rank-by SET.CRITERION] [--threads N] [--json]`: which param
//! moves the filtering effect most (d ln F / d ln p of every weighted criterion).

use crate::Run;
use crate::parallel::Rayon;
use std::process::ExitCode;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The model file (JSON), `-` for stdin, or `preset:NAME`.
    pub model: String,
    /// Override a model parameter, e.g. `--set q=0.5` (repeatable): the point the
    /// derivatives are taken at.
    #[arg(long = "set", value_name = "NAME=VALUE", value_parser = super::parse_override)]
    pub set: Vec<(String, f64)>,
    /// A param to vary (repeatable; default every param of the model).
    #[arg(long = "param", value_name = "NAME")]
    pub params: Vec<String>,
    /// The log-scale step h: each param is analysed at p e^h and p e^−h (1e-8 to 0.1).
    #[arg(long, value_name = "H")]
    pub relative_step: Option<f64>,
    /// The criterion the params are ranked by: covariance.yx (default), covariance.zx,
    /// covariance.yz, bound.yx, bound.zx or bound.yz.
    #[arg(long, value_name = "SET.CRITERION")]
    pub rank_by: Option<String>,
    /// Threads for the analyses (default or 0: every core; at most 256). Results do
    /// not depend on it.
    #[arg(long, value_parser = super::parse_threads)]
    pub threads: Option<usize>,
    /// Print the whole result as JSON instead of the table.
    #[arg(long)]
    pub json: bool,
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
        let mut request = serde_json::json!({ "model": model, "set": set });
        if !self.params.is_empty() {
            request["params"] = serde_json::json!(self.params);
        }
        if let Some(h) = self.relative_step {
            request["relative_step"] = serde_json::json!(h);
        }
        if let Some(c) = &self.rank_by {
            request["rank_by"] = serde_json::json!(c);
        }
        let exec = match Rayon::new(self.threads) {
            Ok(x) => x,
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::from(super::EXIT_FAILURE);
            }
        };
        let run = super::KindRun {
            kind: "sensitivity",
            input: &self.model,
            json: self.json,
            csv: None,
            limit: &self.limit,
            model_file: true,
        };
        run.run(request, &exec)
    }
}
