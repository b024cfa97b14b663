//! `tessera-worker`: a render worker for a Tessera coordinator. Parses arguments and runs the
//! lease → render → upload loop until SIGTERM/SIGINT (which drains: finishes and uploads the
//! tiles in hand, then exits).

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    if let Err(e) = tessera_common::cpu::check_cpu_features() {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    tessera_worker::init_logging();
    let args = tessera_worker::Args::parse();
    match tessera_worker::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
