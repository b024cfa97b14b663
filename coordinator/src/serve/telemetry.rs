//! Logging set-up: `tracing` with an env filter (`RUST_LOG`). `tessera serve` logs its own
//! events at `info` (as text or JSON lines, `--log-format`); the other commands only warnings
//! and errors, so that command-line output stays clean.

use tessera_config::LogFormat;

/// The filter of `tessera serve` unless `RUST_LOG` says otherwise: the coordinator's events
/// (job lifecycle, workers) at `info`, libraries' at `warn`.
pub const SERVE_FILTER: &str = "warn,tessera_coordinator=info";

/// The filter of the other commands unless `RUST_LOG` says otherwise.
pub const CLI_FILTER: &str = "warn";

/// Installs the global subscriber once.
pub fn init(format: LogFormat, default_filter: &str) {
    tessera_config::logging::init(format, default_filter);
}
