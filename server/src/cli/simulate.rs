//! `kea simulate MODEL.json|preset:NAME [--runs R] [--seed S] [--truth process|mean]
//! [--model-error white|constant] [--trace-points ROWS] [--set name=value]… [--threads T]
//! [--max-work UNITS] [--json] [--csv FILE|-]`: the Monte Carlo of METHOD §1.8 — real
//! (simulated) against potential (Riccati) accuracy. R is 1000 unless given. The report
//! is text, or JSON with `--json`; `--csv` also writes the traces to a file (or, as
//! `-`, to stdout in place of the text).

use crate::Run;
use crate::parallel::Rayon;
use kea_core::report::{cell, short};
use kea_core::simulation::{
    Executor, ModelError, SimulationRequest, SimulationResult, Truth, Verdict,
};
use std::fmt::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum TruthArg {
    Process,
    Mean,
}

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
    #[arg(long, default_value_t = kea_core::simulation::DEFAULT_SEED)]
    pub seed: u64,
    /// What the filter is compared with: the noisy process Y, or the mean y (seed 000).
    #[arg(long, value_enum, default_value = "process")]
    pub truth: TruthArg,
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
        let model = match super::load_model(&self.model) {
            Ok(m) => m,
            Err(code) => return code,
        };
        let req = SimulationRequest {
            runs: self.runs,
            seed: self.seed,
            truth: match self.truth {
                TruthArg::Process => Truth::Process,
                TruthArg::Mean => Truth::Mean,
            },
            model_error: match self.model_error {
                ModelErrorArg::White => ModelError::White,
                ModelErrorArg::Constant => ModelError::Constant,
            },
            trace_points: self.trace_points,
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
        let work = kea_core::validate::compile(&model, &set)
            .map(|c| crate::serve::jobs::simulation::work_of(&c, Some(&model), &req));
        if let Err(code) = self.limit.check(work) {
            return code;
        }
        let csv = match super::Csv::open(self.csv.as_deref(), &self.model, self.json) {
            Ok(c) => c,
            Err(code) => return code,
        };
        let start = Instant::now();
        let mut bar = super::Bar::new("simulation");
        let result = kea_core::simulation::simulate(&model, &set, &req, &exec, &mut bar);
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
            kea_core::simulation::traces_csv,
            |r| table(r, exec.threads()),
        ) {
            Ok(()) => ExitCode::SUCCESS,
            Err(code) => code,
        }
    }
}

fn verdict(v: Verdict) -> &'static str {
    match v {
        Verdict::Consistent => "consistent",
        Verdict::Optimistic => "optimistic (real worse than potential)",
        Verdict::Pessimistic => "pessimistic (real better than potential)",
        Verdict::Undefined => "undefined",
    }
}

/// The plain-text report: final SKOs, verdicts, and the three criteria sets; numbers as
/// in the analysis table ([`number`]), `—` where undefined.
pub fn table(r: &SimulationResult, threads: usize) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Monte Carlo: {} runs × {} steps, seed {}, truth = {}, model error = {} ({:.0} ms, {threads} threads)",
        r.request.runs,
        r.steps,
        r.request.seed,
        // (the names of the JSON and of the flags: process, white…)
        serde_json::to_value(r.request.truth)
            .unwrap_or_default()
            .as_str()
            .unwrap_or("?"),
        serde_json::to_value(r.request.model_error)
            .unwrap_or_default()
            .as_str()
            .unwrap_or("?"),
        r.timing.wall_ms
    );
    let _ = writeln!(
        s,
        "\nAt t = {}: SKO of the errors (sample) against the potential sqrt(R_ii) and the bound χ",
        short(r.t_end)
    );
    let _ = writeln!(
        s,
        "{:<12} {:>12} {:>12} {:>12} {:>12} {:>12}   verdict (mean s²/R_ii, band)",
        "state", "a-priori", "measured", "filtered", "potential", "bound χ"
    );
    for (i, st) in r.states.iter().enumerate() {
        let f = &r.final_;
        let v = &r.consistency.per_state[i];
        let _ = writeln!(
            s,
            "{:<12} {:>12} {:>12} {:>12} {:>12} {:>12}   {} ({} in [{}, {}])",
            st,
            cell(Some(f.a_priori_sko[i])),
            cell(f.measured_sko[i]),
            cell(Some(f.filtered_sko[i])),
            cell(Some(f.potential_sko[i])),
            cell(Some(f.chi[i])),
            verdict(v.verdict),
            cell(v.variance_ratio),
            cell(Some(v.band[0])),
            cell(Some(v.band[1]))
        );
    }
    let c = &r.consistency;
    for (name, st) in [("NEES", &c.nees), ("NIS", &c.nis)] {
        let _ = writeln!(
            s,
            "{name}: average {} (dof {:.2}), {:.0} % band [{}, {}], {} of steps in band: {}",
            cell(st.time_average),
            st.dof,
            c.band_probability * 100.0,
            cell(Some(st.band[0])),
            cell(Some(st.band[1])),
            st.fraction_in_band
                .map_or("—".into(), |f| format!("{:.1} %", f * 100.0)),
            verdict(st.verdict)
        );
    }
    let _ = writeln!(
        s,
        "\nCriteria (weighted F): bound / covariance / monte_carlo"
    );
    let sets = [
        Some(&r.criteria.bound),
        Some(&r.criteria.covariance),
        r.criteria.monte_carlo.as_ref(),
    ];
    for (name, get) in [("F_YZ", 0usize), ("F_ZX", 1), ("F_YX", 2)] {
        let vals: Vec<String> = sets
            .iter()
            .map(|set| {
                cell(set.and_then(|c| match get {
                    0 => c.weighted.yz,
                    1 => c.weighted.zx,
                    _ => c.weighted.yx,
                }))
            })
            .collect();
        let _ = writeln!(
            s,
            "{name:<6} {:>12} {:>12} {:>12}",
            vals[0], vals[1], vals[2]
        );
    }
    for w in &r.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    s
}
