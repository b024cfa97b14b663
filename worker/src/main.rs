//! `tessera-worker`: a render worker for a Tessera coordinator. Parses arguments (flags,
//! `TESSERA_*` variables, the `--config` file) and runs the lease → render → upload loop until
//! SIGTERM/SIGINT (which drains: finishes and uploads the tiles in hand, then exits).

use std::process::ExitCode;

fn main() -> ExitCode {
    if let Err(e) = tessera_common::cpu::check_cpu_features() {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    let result = tessera_worker::parse_args(std::env::args_os()).and_then(|(args, parsed)| {
        if args.config.print_config {
            print!("{}", parsed.print_config());
            return Ok(());
        }
        tessera_worker::init_logging(args.log.log_format);
        tessera_worker::run(args)
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
