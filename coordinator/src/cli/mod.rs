//! The `tessera` command line: argument parsing and dispatch, `tessera render` (a local render
//! with no setup) and the farm client commands `submit`, `status`, `cancel` and `delete`, which
//! talk to a coordinator only through `tessera-proto`. `tessera serve` hands over to [`crate::serve`] and
//! `tessera bench …` to [`crate::bench`].

pub mod client;
pub mod healthcheck;
pub mod render;
pub mod submit;

use clap::{Parser, Subcommand};

/// Tessera: a distributed renderer for Mitsuba 3 scenes.
#[derive(Parser, Debug)]
#[command(name = "tessera", version, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render a scene on this machine and write an OpenEXR image plus a PNG preview.
    Render(render::RenderArgs),
    /// Run the farm coordinator: gRPC and REST on one port, jobs kept in --data-dir.
    Serve(crate::serve::config::ServeArgs),
    /// Submit a scene (and every file it references) to a coordinator.
    Submit(submit::SubmitArgs),
    /// Show one job or all jobs of a coordinator.
    Status(client::StatusArgs),
    /// Cancel a job on a coordinator.
    Cancel(client::CancelArgs),
    /// Delete an ended job (done, failed or cancelled) and all its data from a coordinator.
    Delete(client::DeleteArgs),
    /// Check that a coordinator answers on /healthz: exit 0 if it does, 1 if not.
    Healthcheck(healthcheck::HealthcheckArgs),
    /// Measure: rendering speed, equal-time quality, EMIS overheads and decisions, the farm.
    #[command(subcommand)]
    Bench(crate::bench::BenchCommand),
}

/// Parses the command line and runs the command.
pub fn run() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Render(args) => render::render_command(&args),
        Command::Serve(args) => crate::serve::app::serve_command(&args),
        Command::Submit(args) => submit::submit_command(&args),
        Command::Status(args) => client::status_command(&args),
        Command::Cancel(args) => client::cancel_command(&args),
        Command::Delete(args) => client::delete_command(&args),
        Command::Healthcheck(args) => healthcheck::healthcheck_command(&args),
        Command::Bench(command) => crate::bench::run(&command),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_is_well_formed() {
        Cli::command().debug_assert();
    }

    #[test]
    fn bench_subcommands_parse_their_positional_arguments() {
        let cli = Cli::try_parse_from(["tessera", "bench", "equal-time", "20,60", "a.xml", "b.xml", "--seeds", "1,2"])
            .unwrap();
        let Command::Bench(crate::bench::BenchCommand::EqualTime(args)) = cli.command else { panic!("not equal-time") };
        assert_eq!(args.seconds.0, vec![20.0, 60.0]);
        assert_eq!(args.scenes.scenes.len(), 2);
        assert_eq!(args.seeds, vec![1, 2]);
        assert!(Cli::try_parse_from(["tessera", "bench", "equal-time", "0"]).is_err());
        let cli = Cli::try_parse_from(["tessera", "bench", "ground-truth", "8", "--pilot", "2"]).unwrap();
        let Command::Bench(crate::bench::BenchCommand::GroundTruth(args)) = cli.command else { panic!() };
        assert_eq!((args.iterations, args.pilot), (8, 2));
        assert!(Cli::try_parse_from(["tessera", "bench-farm", "--ingest"]).is_err());
        assert!(Cli::try_parse_from(["tessera", "bench", "farm", "--ingest"]).is_ok());
    }
}
