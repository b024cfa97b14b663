//! Settings of Tessera's long-running binaries (`tessera serve`, `tessera-worker`) and their
//! logging.
//!
//! A setting comes from, in this order of precedence: its flag, its `TESSERA_*` environment
//! variable, the TOML file named by `--config` (or `TESSERA_CONFIG`), its built-in default.
//! `--print-config` shows the result as TOML, tokens redacted ([`Parsed::print_config`]).
//!
//! No flag is listed here: a command's variables are named after its long flags
//! ([`env_name`]) and the file's keys are the long flags themselves, so a new flag can be set
//! in all three places the moment it exists. The file's values become the arguments' defaults
//! before clap parses, which gives the precedence above without a second parser, and a value
//! from the file is checked by the flag's own parser.

#![deny(missing_docs)]

mod file;
mod layer;
pub mod logging;

pub use layer::{Parsed, env_name, file_keys, parse, with_env};
pub use logging::{LogArgs, LogFormat};

use std::path::PathBuf;

/// `--config` and `--print-config`, flattened into a command's arguments.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ConfigArgs {
    /// Read settings from this TOML file: keys are the long flags' names (`listen =
    /// "0.0.0.0:7878"`); flags and TESSERA_* environment variables override it.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Print the effective settings as TOML (tokens redacted), each with where it came from,
    /// and exit.
    #[arg(long)]
    pub print_config: bool,
}

/// The arguments [`ConfigArgs`] adds, which are not settings themselves: not in the file, and
/// `--print-config` has no environment variable.
pub(crate) const CONFIG_ARG: &str = "config";
pub(crate) const PRINT_CONFIG_ARG: &str = "print_config";

/// Why the settings cannot be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The file cannot be read.
    #[error("cannot read config file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not TOML (the message gives the line and column).
    #[error("config file {path}: {message}")]
    Syntax {
        /// The file.
        path: PathBuf,
        /// The TOML parser's message.
        message: String,
    },
    /// A key the command has no flag for.
    #[error("config file {path}, line {line}: unknown key `{key}`{hint}")]
    UnknownKey {
        /// The file.
        path: PathBuf,
        /// Where.
        line: usize,
        /// The key.
        key: String,
        /// A suggestion or the keys there are.
        hint: String,
    },
    /// A value of the wrong shape or one the flag's parser refuses.
    #[error("config file {path}, line {line}: `{key}`: {message}")]
    BadValue {
        /// The file.
        path: PathBuf,
        /// Where.
        line: usize,
        /// The key.
        key: String,
        /// What is wrong.
        message: String,
    },
}

/// What can stop [`parse`]: the command line itself (clap's error prints usage, or help and
/// version with success: call `exit()` on it), or the settings file.
#[derive(Debug, thiserror::Error)]
pub enum ParseError {
    /// Flags or environment variables: clap's own error.
    #[error(transparent)]
    Clap(#[from] clap::Error),
    /// The settings file.
    #[error(transparent)]
    Config(#[from] ConfigError),
}
