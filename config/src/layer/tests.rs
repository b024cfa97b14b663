//! Tests of the layering on a small command shaped like the services' (no environment
//! variables: those are tested on the real binaries, in child processes).

use super::*;
use crate::ConfigArgs;
use clap::{CommandFactory, FromArgMatches, Parser};

#[derive(Parser, Debug)]
#[command(name = "toy")]
struct Toy {
    #[arg(long, default_value = "127.0.0.1:1")]
    listen: String,
    #[arg(long, default_value_t = 30.0)]
    timeout: f64,
    #[arg(long, hide_env_values = true)]
    token: Option<String>,
    #[arg(long)]
    insecure: bool,
    #[arg(long, value_delimiter = ',')]
    updates: Vec<u32>,
    #[arg(long)]
    url: String,
    #[arg(long, value_enum, default_value = "text")]
    format: crate::LogFormat,
    #[command(flatten)]
    config: ConfigArgs,
}

#[derive(Parser, Debug)]
#[command(name = "tool")]
enum Tool {
    Serve(ToyArgs),
    Other,
}

#[derive(clap::Args, Debug)]
struct ToyArgs {
    #[arg(long, default_value_t = 1)]
    threads: u32,
    #[command(flatten)]
    config: ConfigArgs,
}

/// Writes `text` to a settings file in `dir`; returns its path.
fn file(dir: &tempfile::TempDir, text: &str) -> String {
    let path = dir.path().join("farm.toml");
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

fn toy(args: &[&str]) -> Result<(Toy, Parsed), ParseError> {
    let parsed = parse(Toy::command(), None, std::iter::once("toy").chain(args.iter().copied()))?;
    Ok((Toy::from_arg_matches(&parsed.matches).unwrap(), parsed))
}

#[test]
fn env_names_follow_the_long_flags_and_keep_explicit_ones() {
    assert_eq!(env_name("client-token"), "TESSERA_CLIENT_TOKEN");
    let cmd =
        with_env(Command::new("x").arg(Arg::new("a").long("data-dir")).arg(Arg::new("t").long("token").env("OLD")));
    let envs: Vec<_> = cmd.get_arguments().map(|a| a.get_env().unwrap().to_str().unwrap().to_string()).collect();
    assert_eq!(envs, ["TESSERA_DATA_DIR", "OLD"]);
    let toy = with_env(Toy::command());
    let print = toy.get_arguments().find(|a| a.get_id() == PRINT_CONFIG_ARG).unwrap();
    assert!(print.get_env().is_none(), "--print-config is not a setting");
    let config = toy.get_arguments().find(|a| a.get_id() == CONFIG_ARG).unwrap();
    assert_eq!(config.get_env().unwrap(), "TESSERA_CONFIG");
}

#[test]
fn the_file_sets_what_flags_do_not() {
    let dir = tempfile::tempdir().unwrap();
    let f = file(
        &dir,
        "listen = \"0.0.0.0:9\"\ntimeout = 2.5\ninsecure = true\nupdates = [1, 4]\nurl = \"http://c\"\nformat = \"json\"\n",
    );
    let (t, parsed) = toy(&["--config", &f, "--timeout", "7"]).unwrap();
    assert_eq!(t.listen, "0.0.0.0:9");
    assert_eq!(t.timeout, 7.0, "the flag wins over the file");
    assert!(t.insecure);
    assert_eq!(t.updates, [1, 4]);
    assert_eq!(t.url, "http://c", "a required flag may come from the file");
    assert_eq!(t.format, crate::LogFormat::Json);
    assert!(parsed.from_file("listen") && !parsed.from_file("timeout"));
    // without the file, the required flag is missing again
    assert!(matches!(toy(&[]), Err(ParseError::Clap(_))));
    let (t, _) = toy(&[&format!("--config={f}"), "--updates", "2"]).unwrap();
    assert_eq!(t.updates, [2]);
    let f = file(&dir, "insecure = false\nurl = \"u\"\n");
    assert!(toy(&["--config", &f, "--insecure"]).unwrap().0.insecure);
}

#[test]
fn unknown_keys_and_bad_values_are_errors_naming_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let err = |text: &str| match toy(&["--config", &file(&dir, text)]) {
        Err(ParseError::Config(e)) => e.to_string(),
        other => panic!("{text:?} was accepted: {other:?}"),
    };
    let e = err("url = \"u\"\n\nlisetn = \"x\"\n");
    assert!(e.contains("farm.toml, line 3: unknown key `lisetn`") && e.contains("listen, timeout"), "{e}");
    let e = err("lease_timeout = 1\n");
    assert!(e.contains("unknown key `lease_timeout`"), "{e}");
    let e = err("data_dir = 1\n");
    assert!(e.contains("unknown key"), "{e}");
    assert!(err("url = \"u\"\nconfig = \"other.toml\"\n").contains("unknown key `config`"));
    assert!(err("print-config = true\n").contains("unknown key `print-config`"));
    let e = err("url = \"u\"\ntimeout = \"soon\"\n");
    assert!(e.contains("farm.toml, line 2: `timeout`: invalid value 'soon' for '--timeout"), "{e}");
    let e = err("format = \"xml\"\n");
    assert!(e.contains("line 1: `format`") && e.contains("possible values: text, json"), "{e}");
    assert!(err("insecure = \"yes\"\n").contains("`insecure`"));
    assert!(err("updates = [1, \"x\"]\n").contains("`updates`"));
    assert!(err("listen = [\"a\", \"b\"]\n").contains("an array, but --listen takes one value"));
    assert!(err("url = ").contains("farm.toml"));
    let missing = dir.path().join("missing.toml");
    match toy(&["--config", missing.to_str().unwrap()]) {
        Err(ParseError::Config(ConfigError::Read { path, .. })) => assert_eq!(path, missing),
        other => panic!("{other:?}"),
    }
}

#[test]
fn print_config_shows_every_setting_with_its_source_and_redacts_tokens() {
    let dir = tempfile::tempdir().unwrap();
    let f = file(&dir, "# farm\ntoken = \"s3cret\"\nurl = \"http://c\"\nupdates = [1, 4]\n");
    let (_, parsed) = toy(&["--config", &f, "--timeout", "2"]).unwrap();
    let text = parsed.print_config();
    assert!(!text.contains("s3cret"), "{text}");
    for line in [
        "listen = \"127.0.0.1:1\"  # default",
        "timeout = 2.0  # flag",
        "token = \"<redacted>\"  # file, line 2",
        "insecure = false  # default",
        "updates = [1, 4]  # file, line 4",
        "url = \"http://c\"  # file, line 3",
        "format = \"text\"  # default",
    ] {
        assert!(text.lines().any(|l| l == line), "no {line:?} in\n{text}");
    }
    assert!(!text.contains("config"), "{text}");
    // what it prints is a settings file that gives the same values
    let again = file(&dir, &text.replace("<redacted>", "s3cret"));
    let (t, _) = toy(&["--config", &again]).unwrap();
    assert_eq!((t.timeout, t.token.as_deref(), t.updates), (2.0, Some("s3cret"), vec![1, 4]));
    let (_, parsed) = toy(&["--url", "u"]).unwrap();
    assert!(parsed.print_config().lines().any(|l| l == "# token is not set"));
}

#[test]
fn a_subcommand_reads_the_file_only_when_it_runs() {
    let dir = tempfile::tempdir().unwrap();
    let f = file(&dir, "threads = 8\n");
    let run = |args: &[&str]| {
        let parsed = parse(Tool::command(), Some("serve"), std::iter::once("tool").chain(args.iter().copied()))?;
        Ok::<_, ParseError>((Tool::from_arg_matches(&parsed.matches).unwrap(), parsed))
    };
    let (tool, parsed) = run(&["serve", "--config", &f]).unwrap();
    assert!(matches!(tool, Tool::Serve(ToyArgs { threads: 8, .. })));
    assert!(parsed.print_config().contains("threads = 8  # file, line 1"));
    // another subcommand ignores a --config that is not its own (and clap refuses it)
    assert!(run(&["other", "--config", &f]).is_err());
    assert_eq!(file_keys(Tool::command().find_subcommand("serve").unwrap()), ["threads"]);
}
