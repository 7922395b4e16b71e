//! `kea analyze MODEL.json|preset:NAME [--set name=value]… [--json] [--csv FILE|-]`.

use crate::Run;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The model file (JSON, the format of `kea preset NAME`), `-` for stdin, or `preset:NAME`.
    pub model: String,
    /// Override a model parameter, e.g. `--set q=0.5` (repeatable).
    #[arg(long = "set", value_name = "NAME=VALUE", value_parser = super::parse_override)]
    pub set: Vec<(String, f64)>,
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
        let model = match super::load_model(&self.model) {
            Ok(m) => m,
            Err(code) => return code,
        };
        let set = match super::overrides(&self.set) {
            Ok(s) => s,
            Err(code) => return code,
        };
        if let Err(code) = self
            .limit
            .check(crate::serve::jobs::analysis::work(&model, &set))
        {
            return code;
        }
        let csv = match super::Csv::open(self.csv.as_deref(), &self.model, self.json) {
            Ok(c) => c,
            Err(code) => return code,
        };
        let start = Instant::now();
        let mut bar = super::Bar::new("analysis");
        let result = kea_core::analyze(&model, &set, &mut bar);
        bar.finish();
        let mut result = match result {
            Ok(r) => r,
            Err(e) => return super::report_error(&e),
        };
        result.timing.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        match super::print_run(
            &result,
            self.json,
            csv,
            kea_core::report::traces_csv,
            kea_core::report::criteria_table,
        ) {
            Ok(()) => ExitCode::SUCCESS,
            Err(code) => code,
        }
    }
}
