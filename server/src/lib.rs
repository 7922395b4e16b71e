//! kea-server: the `kea` binary's command line and HTTP service, as adapters over
//! `kea_core`.
//!
//! Architecture invariant: this crate contains no estimation maths. A command or a
//! handler parses its input, calls one core function, maps the error, and formats
//! the output. Anything about filtering belongs in `kea_core`.

pub mod cli;
pub mod parallel;
pub mod serve;

use clap::{CommandFactory, Parser, Subcommand};
use std::io::Write;
use std::process::ExitCode;

/// What every subcommand's arguments implement: run it, return the exit code
/// (0 success, 1 failure, 2 invalid input).
pub trait Run {
    fn run(self) -> ExitCode;
}

/// Declares the subcommands: adding one is one line here (its arguments type
/// implements [`Run`]); the doc comment becomes its `--help` summary.
macro_rules! commands {
    ($( $(#[$meta:meta])* $name:ident($args:ty), )*) => {
        #[derive(Debug, Subcommand)]
        pub enum Command {
            $( $(#[$meta])* $name($args), )*
        }

        impl Command {
            fn run(self) -> ExitCode {
                match self {
                    $( Command::$name(args) => Run::run(args), )*
                }
            }
        }
    };
}

commands! {
    /// Analyse a model file: the filtering-effect criteria (table or JSON).
    Analyze(cli::analyze::Args),
    /// List the preset models.
    Presets(cli::presets::ListArgs),
    /// Print a preset model's JSON (a starting point for your own model).
    Preset(cli::presets::ShowArgs),
    /// Monte Carlo: real (simulated) against potential (Riccati) accuracy.
    // `simulate`: its former name, still read as it (scripts).
    #[command(visible_alias = "simulate")]
    MonteCarlo(cli::monte_carlo::Args),
    /// Synthesis: the error levels that reach a desired filtering effect.
    Synthesize(cli::synthesize::Args),
    /// Sensitivity: which param moves the filtering effect most (d ln F / d ln p).
    Sensitivity(cli::sensitivity::Args),
    /// Identification: the maximum-likelihood params of a model from measured data.
    Identify(cli::identify::Args),
    /// Nonlinear: the EKF and the iterative regularised procedure over measured data.
    Nonlinear(cli::nonlinear::Args),
    /// Run the HTTP service (API, jobs, web UI).
    Serve(serve::Args),
}

/// kea — how much more accurate will the filtered information be than the model's own
/// prediction and the raw measurements?
#[derive(Debug, Parser)]
#[command(name = "kea", version)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// The core's SIMD ceiling from the environment, for comparing the builds:
/// `KEA_NO_SIMD` (set to anything) the portable baseline, `KEA_NO_AVX512` at most AVX2
/// + FMA. The results are the same bits whichever runs (`kea_core::cpu`).
pub fn cpu_limit_from_env() {
    let set = |var: &str| std::env::var_os(var).is_some();
    kea_core::cpu::set_limit(kea_core::cpu::Limit::from_switches(
        set("KEA_NO_SIMD"),
        set("KEA_NO_AVX512"),
    ));
}

impl Cli {
    pub fn run(self) -> ExitCode {
        cpu_limit_from_env();
        match self.command {
            Some(command) => command.run(),
            None => {
                // `kea` alone: the help, as a successful answer.
                let help = Cli::command().print_help();
                match cli::stdout_written(help.and_then(|()| std::io::stdout().flush())) {
                    Ok(()) => ExitCode::SUCCESS,
                    Err(code) => code,
                }
            }
        }
    }

    /// Parse the command line, or the exit code where parsing was the whole answer:
    /// `--help` and `--version` are printed here, checked like any output
    /// ([`cli::stdout_written`]); a usage error exits with clap's message (status 2).
    pub fn parse_or_exit() -> Result<Cli, ExitCode> {
        let err = match Cli::try_parse() {
            Ok(cli) => return Ok(cli),
            Err(err) => err,
        };
        if err.use_stderr() {
            err.exit();
        }
        cli::stdout_written(err.print().and_then(|()| std::io::stdout().flush()))?;
        Err(ExitCode::from(
            u8::try_from(err.exit_code()).unwrap_or(cli::EXIT_FAILURE),
        ))
    }
}
