//! `kea presets` (list) and `kea preset NAME [--synthesis]` (print the model's JSON, or
//! its synthesis example's).

use crate::Run;
use std::fmt::Write;
use std::process::ExitCode;

#[derive(Debug, clap::Args)]
pub struct ListArgs {
    /// Print the list as JSON.
    #[arg(long)]
    pub json: bool,
}

impl Run for ListArgs {
    fn run(self) -> ExitCode {
        let list = kea_core::presets::list();
        let printed = if self.json {
            super::print_json(&list)
        } else {
            let w = list.iter().map(|p| p.name.len()).max().unwrap_or(0);
            let mut text = String::new();
            for p in list {
                let _ = writeln!(
                    text,
                    "{:<w$}  N={} n={}  {}",
                    p.name, p.states, p.measurements, p.title
                );
            }
            super::print_text(&text)
        };
        match printed {
            Ok(()) => ExitCode::SUCCESS,
            Err(code) => code,
        }
    }
}

#[derive(Debug, clap::Args)]
pub struct ShowArgs {
    /// The preset's name (see `kea presets`).
    pub name: String,
    /// Print the preset's synthesis example instead: a request's `target` and `mode`
    /// (`kea synthesize --preset NAME` runs it; add `"model"` to use it elsewhere).
    #[arg(long)]
    pub synthesis: bool,
}

impl Run for ShowArgs {
    fn run(self) -> ExitCode {
        let text = if self.synthesis {
            kea_core::presets::synthesis_json(&self.name)
        } else {
            kea_core::presets::get_json(&self.name)
        };
        match text {
            Some(json) => {
                let end = if json.ends_with('\n') { "" } else { "\n" };
                match super::print_text(&format!("{json}{end}")) {
                    Ok(()) => ExitCode::SUCCESS,
                    Err(code) => code,
                }
            }
            None => {
                eprintln!("{}", super::no_preset(&self.name));
                ExitCode::from(super::EXIT_INVALID)
            }
        }
    }
}
