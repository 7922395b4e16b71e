//! `kea presets` (list) and `kea preset NAME` (print the JSON).

use crate::Run;
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
        if self.json {
            println!(
                "{}",
                serde_json::to_string_pretty(&list).expect("plain data")
            );
            return ExitCode::SUCCESS;
        }
        let w = list.iter().map(|p| p.name.len()).max().unwrap_or(0);
        for p in list {
            println!(
                "{:<w$}  N={} n={}  {}",
                p.name, p.states, p.measurements, p.title
            );
        }
        ExitCode::SUCCESS
    }
}

#[derive(Debug, clap::Args)]
pub struct ShowArgs {
    /// The preset's name (see `kea presets`).
    pub name: String,
}

impl Run for ShowArgs {
    fn run(self) -> ExitCode {
        match kea_core::presets::get_json(&self.name) {
            Some(json) => {
                super::print_text(json);
                if !json.ends_with('\n') {
                    println!();
                }
                ExitCode::SUCCESS
            }
            None => {
                eprintln!("{}", super::no_preset(&self.name));
                ExitCode::from(super::EXIT_INVALID)
            }
        }
    }
}
