//! The `tessera` command line: argument parsing and dispatch, `tessera render` (a local render
//! with no setup) and the farm client commands `submit`, `status` and `cancel`, which talk to a
//! coordinator only through `tessera-proto`. `tessera serve` hands over to [`crate::serve`] and
//! `tessera bench …` to [`crate::bench`].

pub mod client;
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
        Command::Bench(command) => crate::bench::run(&command),
    }
}
