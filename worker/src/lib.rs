//! Tessera's render worker. It registers with a coordinator, pulls tiles (long poll), fetches
//! scene bundles by digest into a local cache, renders on a rayon pool on a blocking thread
//! (never on a tokio thread), uploads the unnormalised sums, heartbeats its leases, reconnects
//! with backoff and drains on SIGTERM. It keeps no state worth saving but its identity (in the
//! cache folder): killing it loses at most the tiles it holds, which the coordinator re-queues
//! when their leases expire or the worker registers again.
//!
//! ```text
//! tessera-worker --coordinator https://farm:7878 --ca-cert farm-ca.pem --threads 16 --token $TOKEN
//! ```
//!
//! Every flag can also be given as a `TESSERA_*` variable (`--token`'s is
//! `TESSERA_WORKER_TOKEN`, the coordinator's name for the same secret) or in a `--config` TOML
//! file ([`tessera_config`]).

pub mod client;
pub mod convert;
pub mod identity;
pub mod render;
pub mod runner;
pub mod scene_cache;

use std::path::PathBuf;

/// Command line of `tessera-worker`.
#[derive(clap::Parser, Debug, Clone)]
#[command(name = "tessera-worker", version, about = "Render worker for a Tessera coordinator")]
pub struct Args {
    /// Coordinator URL (`https://` when it serves TLS).
    #[arg(long, env = "TESSERA_COORDINATOR")]
    pub coordinator: String,
    /// PEM file of the CA (or self-signed certificate) an https:// coordinator's certificate
    /// chains to, trusted besides the system's roots.
    #[arg(long, env = "TESSERA_CA_CERT", value_name = "PEM")]
    pub ca_cert: Option<PathBuf>,
    /// Render threads [default: all cores].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Worker bearer token.
    #[arg(long, env = "TESSERA_WORKER_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Where scene bundles and the worker's identity are kept [default: the system temp
    /// folder]. Workers sharing it each take an identity of their own.
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// MiB of unpacked scene bundles kept in the cache folder; the least recently used go
    /// first, never the one a tile is being rendered from.
    #[arg(long, value_name = "MIB", default_value_t = scene_cache::DEFAULT_CACHE_LIMIT_MIB)]
    pub cache_limit: u64,
    /// Name shown by the coordinator [default: the host name].
    #[arg(long)]
    pub name: Option<String>,
    /// Tags of this worker, comma-separated: jobs submitted with `--require-tags` go only to
    /// workers that have all of them (e.g. `big-memory,gpu-free`).
    #[arg(long, value_delimiter = ',', value_name = "TAG")]
    pub tags: Vec<String>,
    /// Exit (with status 0) once the coordinator drains this worker and the tiles it holds are
    /// uploaded; without it a drained worker idles until it is enabled again.
    #[arg(long)]
    pub exit_when_drained: bool,
    /// Image tiles leased at once [default: the thread count].
    #[arg(long)]
    pub max_tiles: Option<u32>,
    /// Memory a scene's decoded textures and environment maps may take, in MiB [default: 1024
    /// per image, 4096 in all]; a job whose scene needs more fails on this worker.
    #[arg(long, value_name = "MIB")]
    pub texture_budget: Option<u64>,
    /// Most triangles a job's scene may hold on this worker (about 440 bytes each while it
    /// loads); a job whose scene has more fails here and runs on workers that allow it.
    #[arg(long, default_value_t = tessera_common::scene::DEFAULT_MAX_TRIANGLES)]
    pub max_triangles: u64,
    /// Memory one tile may need on this worker, in MiB, as estimated from the job's settings
    /// and film, checked before anything is allocated for it [default: the machine's memory,
    /// at most 16384].
    #[arg(long, value_name = "MIB")]
    pub max_tile_memory: Option<u64>,
    /// Log format.
    #[command(flatten)]
    pub log: tessera_config::LogArgs,
    /// `--config` and `--print-config`.
    #[command(flatten)]
    pub config: tessera_config::ConfigArgs,
}

/// Parses `argv` (program name first): flags, then `TESSERA_*` variables, then the `--config`
/// file. Clap's errors (and `--help`, `--version`) exit here, as `Args::parse` would.
pub fn parse_args<I, T>(argv: I) -> anyhow::Result<(Args, tessera_config::Parsed)>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString>,
{
    use clap::{CommandFactory, FromArgMatches};
    let parsed = match tessera_config::parse(Args::command(), None, argv) {
        Ok(p) => p,
        Err(tessera_config::ParseError::Clap(e)) => e.exit(),
        Err(e) => return Err(e.into()),
    };
    let args = Args::from_arg_matches(&parsed.matches).unwrap_or_else(|e| e.exit());
    Ok((args, parsed))
}

/// Installs the `tracing` subscriber (`RUST_LOG`, default: the worker's own events at `info`).
pub fn init_logging(format: tessera_config::LogFormat) {
    tessera_config::logging::init(format, "warn,tessera_worker=info");
}

/// What a tile may ask of this worker: `--max-tile-memory` MiB, or the machine's memory (at
/// most the coordinator's default), so that a job too large for this machine fails here with a
/// reason instead of aborting the process on an allocation.
pub fn work_limits(max_tile_memory_mib: Option<u64>) -> tessera_common::settings::WorkLimits {
    let machine = std::fs::read_to_string("/proc/meminfo").ok().and_then(|text| {
        let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
        line.split_whitespace().nth(1)?.parse::<u64>().ok().map(|kib| kib << 10)
    });
    let default = tessera_common::settings::DEFAULT_MAX_TILE_BYTES;
    let max_tile_bytes =
        max_tile_memory_mib.map_or_else(|| machine.map_or(default, |m| m.min(default)), |mib| mib << 20);
    tessera_common::settings::WorkLimits { max_tile_bytes, ..Default::default() }
}

/// Runs the worker until it is told to stop.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.threads == Some(0) {
        anyhow::bail!("--threads must be at least 1");
    }
    let runtime = tokio::runtime::Runtime::new()?;
    runtime.block_on(runner::run(args))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// Every flag of the worker can be set in its settings file: a new flag without a sample
    /// here fails this test until one is added.
    #[test]
    fn every_flag_can_be_set_in_the_config_file() {
        let samples = [
            ("coordinator", "\"https://farm:7878\""),
            ("ca-cert", "\"farm-ca.pem\""),
            ("threads", "3"),
            ("token", "\"w-secret\""),
            ("cache-dir", "\"/var/cache/tessera\""),
            ("cache-limit", "512"),
            ("name", "\"node-7\""),
            ("max-tiles", "2"),
            ("tags", "[\"big\", \"fast\"]"),
            ("exit-when-drained", "true"),
            ("texture-budget", "256"),
            ("max-triangles", "2000000"),
            ("max-tile-memory", "4096"),
            ("log-format", "\"json\""),
        ];
        let keys = tessera_config::file_keys(&Args::command());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("worker.toml");
        for key in &keys {
            let (_, sample) = samples
                .iter()
                .find(|(k, _)| k == key)
                .unwrap_or_else(|| panic!("--{key} is new: add a sample value for it to this test"));
            // the one required flag comes from the command line unless it is the one tested
            let (text, flags) = match key.as_str() {
                "coordinator" => (format!("{key} = {sample}\n"), vec![]),
                _ => (format!("{key} = {sample}\n"), vec!["--coordinator", "http://c"]),
            };
            std::fs::write(&path, text).unwrap();
            let argv = ["tessera-worker", "--config", path.to_str().unwrap()].into_iter().chain(flags);
            let (_, parsed) = parse_args(argv).unwrap();
            let shown = if *key == "token" { "\"<redacted>\"" } else { sample };
            let line = format!("{key} = {shown}  # file, line 1");
            let printed = parsed.print_config();
            assert!(printed.lines().any(|l| l == line), "{key}: no {line:?} in\n{printed}");
        }
        assert_eq!(keys.len(), samples.len(), "samples for flags that are gone: {keys:?}");
    }

    #[test]
    fn the_file_gives_the_coordinator_and_flags_win() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("worker.toml");
        std::fs::write(&path, "coordinator = \"http://farm:7878\"\nthreads = 4\nname = \"from-file\"\n").unwrap();
        let (args, _) = parse_args(["tessera-worker", "--config", path.to_str().unwrap(), "--threads", "2"]).unwrap();
        assert_eq!(args.coordinator, "http://farm:7878");
        assert_eq!((args.threads, args.name.as_deref()), (Some(2), Some("from-file")));
        std::fs::write(&path, "coordinator = \"http://farm:7878\"\nthread = 4\n").unwrap();
        let e = parse_args(["tessera-worker", "--config", path.to_str().unwrap()]).err().unwrap().to_string();
        assert!(e.contains("worker.toml, line 2: unknown key `thread`"), "{e}");
    }
}
