//! The `kea` binary: parses the command line and hands over to [`kea_server::Cli::run`].

use clap::Parser;

fn main() -> std::process::ExitCode {
    kea_server::Cli::parse().run()
}
