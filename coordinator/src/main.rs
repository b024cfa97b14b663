//! `tessera`: the command-line entry point. Parses arguments and hands over to the library.

use std::process::ExitCode;

fn main() -> ExitCode {
    if let Err(e) = tessera_common::cpu::check_cpu_features() {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    match tessera_coordinator::cli::run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            // distinct codes per kind of failure (cli/exit.rs)
            ExitCode::from(tessera_coordinator::cli::exit::code(&e))
        }
    }
}
