//! The `kea` binary: parses the command line and hands over to [`kea_server::Cli::run`].

fn main() -> std::process::ExitCode {
    match kea_server::Cli::parse_or_exit() {
        Ok(cli) => cli.run(),
        Err(code) => code,
    }
}
