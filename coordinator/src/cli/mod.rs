//! The `tessera` command line: argument parsing and dispatch, `tessera render` (a local render
//! with no setup) and the farm client commands `submit`, `status`, `cancel`, `delete` and the job
//! controls (`pause`, `resume`, `requeue`, `priority`), which
//! talk to a coordinator only through `tessera-proto` and `tessera-link`. `tessera serve` hands
//! over to [`crate::serve`] and `tessera bench …` to [`crate::bench`].

pub mod client;
pub mod control;
pub mod exit;
pub mod fetch;
pub mod frames;
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
    /// List a coordinator's jobs, newest first, optionally of one state.
    List(client::ListArgs),
    /// Follow a submitted job until it ends and download its outputs (re-attaches after
    /// `submit --wait` was interrupted).
    Wait(fetch::FetchArgs),
    /// Download a done job's outputs.
    Download(fetch::FetchArgs),
    /// Cancel a job on a coordinator.
    Cancel(client::CancelArgs),
    /// Delete an ended job (done, failed or cancelled) and all its data from a coordinator.
    Delete(client::DeleteArgs),
    /// Pause a job: no more of its tiles are handed out (leased ones finish) until it resumes.
    Pause(control::JobControlArgs),
    /// Resume a paused job.
    Resume(control::JobControlArgs),
    /// Run a failed or cancelled job on from its last checkpoint, keeping what it merged.
    Requeue(control::JobControlArgs),
    /// Give a job a new priority (higher runs first).
    Priority(control::PriorityArgs),
    /// List a coordinator's workers with their state (idle, busy, disabled, draining,
    /// offline) and tags.
    Workers(control::WorkersArgs),
    /// Disable, enable or drain a worker from the server.
    #[command(subcommand)]
    Worker(control::WorkerCommand),
    /// Print this build: its version and renderer revision (workers must match the
    /// coordinator's).
    Version,
    /// Check that a coordinator answers on /healthz: exit 0 if it does, 1 if not.
    Healthcheck(healthcheck::HealthcheckArgs),
    /// Measure: rendering speed, equal-time quality, EMIS overheads and decisions, the farm.
    #[command(subcommand)]
    Bench(crate::bench::BenchCommand),
}

/// Parses `argv` (program name first): `tessera serve`'s settings also come from `TESSERA_*`
/// variables and its `--config` file. Clap's errors (and `--help`, `--version`) exit here, as
/// `Cli::parse` would.
pub fn parse_from<I, T>(argv: I) -> anyhow::Result<(Cli, tessera_config::Parsed)>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString>,
{
    use clap::{CommandFactory, FromArgMatches};
    let parsed = match tessera_config::parse(Cli::command(), Some("serve"), argv) {
        Ok(p) => p,
        Err(tessera_config::ParseError::Clap(e)) => e.exit(),
        Err(e) => return Err(e.into()),
    };
    let cli = Cli::from_arg_matches(&parsed.matches).unwrap_or_else(|e| e.exit());
    Ok((cli, parsed))
}

/// Parses the command line, installs logging and runs the command.
pub fn run() -> anyhow::Result<()> {
    use crate::serve::telemetry;
    let (cli, parsed) = parse_from(std::env::args_os())?;
    match &cli.command {
        Command::Serve(args) if args.config.print_config => {
            print!("{}", parsed.print_config());
            return Ok(());
        }
        Command::Serve(args) => telemetry::init(args.log.log_format, telemetry::SERVE_FILTER),
        _ => telemetry::init(tessera_config::LogFormat::Text, telemetry::CLI_FILTER),
    }
    match cli.command {
        Command::Render(args) => render::render_command(&args),
        Command::Serve(args) => crate::serve::app::serve_command(&args),
        Command::Submit(args) => submit::submit_command(&args),
        Command::Status(args) => client::status_command(&args),
        Command::List(args) => client::list_command(&args),
        Command::Wait(args) => fetch::wait_command(&args),
        Command::Download(args) => fetch::download_command(&args),
        Command::Cancel(args) => client::cancel_command(&args),
        Command::Delete(args) => client::delete_command(&args),
        Command::Pause(args) => control::control_command(control::Control::Pause, &args),
        Command::Resume(args) => control::control_command(control::Control::Resume, &args),
        Command::Requeue(args) => control::control_command(control::Control::Requeue, &args),
        Command::Priority(args) => control::priority_command(&args),
        Command::Workers(args) => control::workers_command(&args),
        Command::Worker(command) => control::worker_command(&command),
        Command::Version => {
            println!("tessera {}", tessera_common::build_id());
            Ok(())
        }
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

    /// Every flag of `tessera serve` can be set in its settings file: a new flag without a
    /// sample here fails this test until one is added.
    #[test]
    fn every_serve_flag_can_be_set_in_the_config_file() {
        let samples = [
            ("listen", "\"0.0.0.0:9000\""),
            ("data-dir", "\"/srv/tessera\""),
            ("worker-token", "\"w-secret\""),
            ("worker-token-file", "\"/run/secrets/worker\""),
            ("client-token", "\"c-secret\""),
            ("client-token-file", "\"/run/secrets/client\""),
            ("viewer-token", "\"v\""),
            ("viewer-token-file", "\"/run/secrets/viewer\""),
            ("tls-cert", "\"farm.pem\""),
            ("tls-key", "\"farm.key\""),
            ("insecure", "true"),
            ("allowed-host", "[\"farm1\", \"*.farm.example\"]"),
            ("max-connections", "512"),
            ("max-connections-per-ip", "64"),
            ("lease-timeout", "2.5"),
            ("lease-max-floor", "60.0"),
            ("lease-max-factor", "4.0"),
            ("checkpoint-interval", "0.5"),
            ("max-upload-mb", "64"),
            ("texture-budget", "512"),
            ("max-triangles", "1000000"),
            ("max-tile-memory", "8192"),
            ("max-workers", "100"),
            ("forget-workers-after", "\"2h\""),
            ("min-free-space", "256"),
            ("max-job-tiles", "99"),
            ("max-pixels", "1000"),
            ("retain-finished", "\"7d\""),
            ("log-format", "\"json\""),
        ];
        let serve = Cli::command().find_subcommand("serve").unwrap().clone();
        let keys = tessera_config::file_keys(&serve);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("serve.toml");
        for key in &keys {
            let (_, sample) = samples
                .iter()
                .find(|(k, _)| k == key)
                .unwrap_or_else(|| panic!("--{key} is new: add a sample value for it to this test"));
            std::fs::write(&path, format!("{key} = {sample}\n")).unwrap();
            let (cli, parsed) = parse_from(["tessera", "serve", "--config", path.to_str().unwrap()]).unwrap();
            assert!(matches!(cli.command, Command::Serve(_)));
            let shown = if key.ends_with("-token") { "\"<redacted>\"" } else { sample };
            let line = format!("{key} = {shown}  # file, line 1");
            let printed = parsed.print_config();
            assert!(printed.lines().any(|l| l == line), "{key}: no {line:?} in\n{printed}");
        }
        assert_eq!(keys.len(), samples.len(), "samples for flags that are gone: {keys:?}");
    }

    /// clap's `requires` and `conflicts_with` do not see the file's values: `resolve` checks
    /// the pairs itself.
    #[test]
    fn serve_pairs_from_the_config_file_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("serve.toml");
        let resolve = |text: &str, flags: &[&str]| {
            std::fs::write(&path, text).unwrap();
            let argv =
                ["tessera", "serve", "--config", path.to_str().unwrap()].into_iter().chain(flags.iter().copied());
            let Command::Serve(args) = parse_from(argv).unwrap().0.command else { panic!("not serve") };
            args.resolve().err().map(|e| format!("{e:#}")).unwrap_or_default()
        };
        let e = resolve("tls-cert = \"farm.pem\"\n", &[]);
        assert!(e.contains("--tls-cert and --tls-key go together"), "{e}");
        let e = resolve("worker-token = \"w\"\n", &["--worker-token-file", "w.token"]);
        assert!(e.contains("a token and a token file (w.token) are both given"), "{e}");
        assert_eq!(resolve("worker-token = \"w\"\nclient-token = \"c\"\n", &[]), "");
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
