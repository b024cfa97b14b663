//! Layering a clap command's settings: every long flag gets a `TESSERA_*` environment variable,
//! a settings file's values become the arguments' defaults (checked by each flag's own value
//! parser first, so a bad one is named with its file and line), and the effective settings
//! can be printed back as TOML with where each came from.

use crate::file::SettingsFile;
use crate::{CONFIG_ARG, ConfigError, PRINT_CONFIG_ARG, ParseError};
use clap::parser::ValueSource;
use clap::{Arg, ArgAction, ArgMatches, Command};
use std::any::TypeId;
use std::collections::BTreeMap;
use std::ffi::OsString;
use std::fmt::Write;
use std::path::PathBuf;

/// The environment variable of long flag `long`: `--client-token` → `TESSERA_CLIENT_TOKEN`.
pub fn env_name(long: &str) -> String {
    format!("TESSERA_{}", long.to_ascii_uppercase().replace('-', "_"))
}

/// Flags that are not settings: clap's own and `--print-config`.
fn is_builtin(arg: &Arg) -> bool {
    matches!(arg.get_id().as_str(), "help" | "version" | PRINT_CONFIG_ARG)
}

/// Whether `arg` is a setting the file may hold (every long flag but `--config` and the
/// built-ins).
fn is_setting(arg: &Arg) -> bool {
    arg.get_long().is_some() && !is_builtin(arg) && arg.get_id().as_str() != CONFIG_ARG
}

/// Gives every long flag of `cmd` without an environment variable the one [`env_name`] makes;
/// variables set explicitly (older names) are kept.
pub fn with_env(cmd: Command) -> Command {
    // `mut_args` keeps the arguments' order (`mut_arg` moves one to the end of `--help`)
    cmd.mut_args(|a| match a.get_long() {
        Some(long) if a.get_env().is_none() && !is_builtin(&a) => {
            let name = env_name(long);
            a.env(name)
        }
        _ => a,
    })
}

/// The keys a settings file for `cmd` may hold: its long flags but `--config`,
/// `--print-config`, `--help` and `--version`.
pub fn file_keys(cmd: &Command) -> Vec<String> {
    let mut cmd = cmd.clone();
    cmd.build();
    cmd.get_arguments().filter(|a| is_setting(a)).filter_map(|a| a.get_long().map(str::to_string)).collect()
}

/// The parsed command line with the settings file applied.
#[derive(Debug)]
pub struct Parsed {
    /// The matches of the whole command (pass them to `FromArgMatches`).
    pub matches: ArgMatches,
    /// The command as parsed (environment variables and the file's defaults added).
    command: Command,
    /// The subcommand the settings belong to, if not the command itself.
    sub: Option<String>,
    /// The settings file, when one was given.
    file: Option<SettingsFile>,
}

/// Parses `argv` (program name first) with `cmd`, whose settings are those of subcommand `sub`
/// (or of `cmd` itself): flags, then `TESSERA_*` variables, then the `--config` file (or
/// `TESSERA_CONFIG`'s), then the defaults. The file is read only when `argv` runs `sub`.
pub fn parse<I, T>(cmd: Command, sub: Option<&str>, argv: I) -> Result<Parsed, ParseError>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString>,
{
    let argv: Vec<OsString> = argv.into_iter().map(Into::into).collect();
    let mut cmd = match sub {
        Some(s) => cmd.mut_subcommand(s, with_env),
        None => with_env(cmd),
    };
    let file = config_path(&argv, sub).map(|p| SettingsFile::load(&p)).transpose()?;
    if let Some(f) = &file {
        cmd = match sub {
            Some(s) => {
                let layered = apply(cmd.find_subcommand(s).expect("invariant: sub is a subcommand").clone(), f)?;
                cmd.mut_subcommand(s, |_| layered)
            }
            None => apply(cmd, f)?,
        };
    }
    let matches = cmd.try_get_matches_from_mut(argv)?;
    Ok(Parsed { matches, command: cmd, sub: sub.map(str::to_string), file })
}

/// The file `argv` names with `--config FILE` or `--config=FILE` after `sub` (`None` when it
/// does not run `sub`), else `TESSERA_CONFIG`'s. Read before clap parses, because the file
/// decides the defaults clap parses with.
fn config_path(argv: &[OsString], sub: Option<&str>) -> Option<PathBuf> {
    let rest = match sub {
        // the commands with settings take no options before their subcommand
        Some(s) if argv.get(1).is_some_and(|a| a == s) => &argv[2..],
        Some(_) => return None,
        None => argv.get(1..).unwrap_or_default(),
    };
    let mut args = rest.iter().take_while(|a| *a != "--");
    while let Some(a) = args.next() {
        let a = a.to_string_lossy();
        if a == "--config" {
            return args.next().map(PathBuf::from);
        }
        if let Some(path) = a.strip_prefix("--config=") {
            return Some(PathBuf::from(path));
        }
    }
    std::env::var_os(crate::layer::env_name("config")).filter(|p| !p.is_empty()).map(PathBuf::from)
}

/// Makes the file's values the defaults of their arguments in `cmd`.
fn apply(cmd: Command, file: &SettingsFile) -> Result<Command, ConfigError> {
    let mut defaults = BTreeMap::new();
    let mut built = cmd.clone();
    built.build();
    let args: BTreeMap<&str, &Arg> =
        built.get_arguments().filter(|a| is_setting(a)).filter_map(|a| Some((a.get_long()?, a))).collect();
    for entry in &file.entries {
        let bad = |message: String| ConfigError::BadValue {
            path: file.path.clone(),
            line: entry.line,
            key: entry.key.clone(),
            message,
        };
        let Some(arg) = args.get(entry.key.as_str()) else {
            return Err(ConfigError::UnknownKey {
                path: file.path.clone(),
                line: entry.line,
                key: entry.key.clone(),
                hint: hint(&entry.key, &args.keys().copied().collect::<Vec<_>>()),
            });
        };
        if entry.array && !takes_several(arg) {
            return Err(bad(format!("an array, but --{} takes one value", entry.key)));
        }
        for value in &entry.values {
            check_value(arg, value).map_err(bad)?;
        }
        defaults.insert(arg.get_id().clone(), entry.values.clone());
    }
    // the arguments the file gives need not be given again
    Ok(cmd.mut_args(|a| match defaults.remove(a.get_id()) {
        Some(values) => a.default_values(values).required(false),
        None => a,
    }))
}

/// A suggestion for an unknown key: the flag with `_` for `-`, else the keys there are.
fn hint(key: &str, known: &[&str]) -> String {
    let kebab = key.replace('_', "-");
    if known.contains(&kebab.as_str()) {
        return format!(" (did you mean `{kebab}`? keys are the long flags' names)");
    }
    format!(" (the keys are: {})", known.join(", "))
}

/// Whether `arg` takes several values (appends, or splits at a delimiter).
fn takes_several(arg: &Arg) -> bool {
    matches!(arg.get_action(), ArgAction::Append)
        || arg.get_value_delimiter().is_some()
        || arg.get_num_args().is_some_and(|r| r.max_values() > 1)
}

/// Runs `value` through `arg`'s value parser alone (none of its relations to other flags), so
/// that a bad value is reported as the file's.
fn check_value(arg: &Arg, value: &str) -> Result<(), String> {
    let long = arg.get_long().expect("invariant: settings have a long flag");
    let mut probe = Arg::new("value").long(long.to_string()).value_parser(arg.get_value_parser().clone());
    if let Some(names) = arg.get_value_names() {
        probe = probe.value_names(names.to_vec());
    }
    // a delimited list's elements are checked one by one
    let parts: Vec<&str> = match arg.get_value_delimiter() {
        Some(d) => value.split(d).collect(),
        None => vec![value],
    };
    let cmd = Command::new("file").no_binary_name(true).arg(probe.action(ArgAction::Set).num_args(1));
    for part in parts {
        if let Err(e) = cmd.clone().try_get_matches_from([format!("--{long}"), part.to_string()]) {
            // clap's message without its "error: " prefix and the help tip after a blank line
            let text = e.render().to_string();
            let first = text.split("\n\n").next().unwrap_or_default();
            return Err(first.trim_start_matches("error: ").lines().map(str::trim).collect::<Vec<_>>().join(" "));
        }
    }
    Ok(())
}

impl Parsed {
    /// The settings' command and matches.
    fn settings(&self) -> Option<(&Command, &ArgMatches)> {
        match &self.sub {
            Some(s) => Some((self.command.find_subcommand(s)?, self.matches.subcommand_matches(s)?)),
            None => Some((&self.command, &self.matches)),
        }
    }

    /// The effective settings as a TOML settings file, each with a comment saying where it
    /// came from (flag, environment variable, file, default); unset ones are comments. Tokens
    /// (flags whose environment values clap hides) are redacted.
    pub fn print_config(&self) -> String {
        let Some((cmd, matches)) = self.settings() else { return String::new() };
        let mut out = String::new();
        for arg in cmd.get_arguments().filter(|a| is_setting(a)) {
            let (id, key) = (arg.get_id().as_str(), arg.get_long().expect("invariant: settings have a long flag"));
            let raw: Vec<String> =
                matches.get_raw(id).into_iter().flatten().map(|v| v.to_string_lossy().into_owned()).collect();
            let source = match matches.value_source(id) {
                Some(ValueSource::CommandLine) => "flag".to_string(),
                Some(ValueSource::EnvVariable) => {
                    format!("env {}", arg.get_env().map(|e| e.to_string_lossy()).unwrap_or_default())
                }
                Some(ValueSource::DefaultValue) => match self.file_line(key) {
                    Some(line) => format!("file, line {line}"),
                    None => "default".to_string(),
                },
                _ => String::new(),
            };
            if raw.is_empty() {
                let _ = writeln!(out, "# {key} is not set");
                continue;
            }
            let value = if arg.is_hide_env_values_set() {
                toml_string("<redacted>")
            } else if takes_several(arg) {
                format!("[{}]", raw.iter().map(|v| toml_value(arg, v)).collect::<Vec<_>>().join(", "))
            } else {
                toml_value(arg, &raw[0])
            };
            let _ = writeln!(out, "{key} = {value}  # {source}");
        }
        out
    }

    /// The line of `key` in the settings file, if the file has it.
    fn file_line(&self, key: &str) -> Option<usize> {
        self.file.as_ref()?.entries.iter().find(|e| e.key == key).map(|e| e.line)
    }

    /// Whether the settings file gave `key`'s value (neither a flag nor the environment did).
    pub fn from_file(&self, key: &str) -> bool {
        let Some((cmd, matches)) = self.settings() else { return false };
        let Some(arg) = cmd.get_arguments().find(|a| a.get_long() == Some(key)) else { return false };
        matches.value_source(arg.get_id().as_str()) == Some(ValueSource::DefaultValue) && self.file_line(key).is_some()
    }
}

/// `raw` as a TOML value of `arg`'s type: numbers and booleans bare, anything else a string.
fn toml_value(arg: &Arg, raw: &str) -> String {
    let t = arg.get_value_parser().type_id();
    let integer = [
        TypeId::of::<u8>(),
        TypeId::of::<u16>(),
        TypeId::of::<u32>(),
        TypeId::of::<u64>(),
        TypeId::of::<usize>(),
        TypeId::of::<i8>(),
        TypeId::of::<i16>(),
        TypeId::of::<i32>(),
        TypeId::of::<i64>(),
        TypeId::of::<isize>(),
    ];
    if integer.iter().any(|i| t == *i)
        && let Ok(n) = raw.parse::<i64>()
    {
        return n.to_string();
    }
    if (t == TypeId::of::<f64>() || t == TypeId::of::<f32>())
        && let Ok(x) = raw.parse::<f64>()
        && x.is_finite()
    {
        // `{:?}` always writes a decimal point or an exponent, as TOML floats need
        return format!("{x:?}");
    }
    if t == TypeId::of::<bool>() && (raw == "true" || raw == "false") {
        return raw.to_string();
    }
    toml_string(raw)
}

/// `s` as a quoted TOML string.
fn toml_string(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

#[cfg(test)]
mod tests;
