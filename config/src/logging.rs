//! Logging of the services: `--log-format text|json` and the `tracing` subscriber. Lines go to
//! stderr (stdout is kept for what scripts read); the level comes from `RUST_LOG`, else from
//! the service's default (its own events at `info`).

use std::io::IsTerminal;

/// How log lines are written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormat {
    /// One line per event for people: time, level, message, `key=value` fields.
    #[default]
    Text,
    /// One JSON object per line for log collectors: `timestamp`, `level`, `message`, `target`,
    /// the event's fields (`job_id`, `worker_id`, ...) at the top level, and `span` with the
    /// fields of the span it happened in.
    Json,
}

/// `--log-format`, flattened into a service's arguments.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct LogArgs {
    /// Log lines as text for people, or as one JSON object per line for log collectors (the
    /// level is RUST_LOG's, by default info for Tessera's own events).
    #[arg(long, value_enum, default_value = "text", value_name = "FORMAT")]
    pub log_format: LogFormat,
}

/// Installs the global subscriber (once; later calls do nothing): `format`, filtered by
/// `RUST_LOG` or else by `default_filter` (an `EnvFilter` directive such as
/// `warn,tessera_coordinator=info`).
pub fn init(format: LogFormat, default_filter: &str) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default_filter));
    let builder = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr);
    let _ = match format {
        LogFormat::Text => builder.with_target(false).with_ansi(std::io::stderr().is_terminal()).try_init(),
        // flattened: `jq 'select(.job_id == "...")'` finds a job's events without knowing
        // which were logged inside a span
        LogFormat::Json => builder.json().flatten_event(true).with_current_span(true).with_span_list(false).try_init(),
    };
}
