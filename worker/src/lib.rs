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
    /// Image tiles leased at once [default: the thread count].
    #[arg(long)]
    pub max_tiles: Option<u32>,
    /// Memory a scene's decoded textures and environment maps may take, in MiB [default: 1024
    /// per image, 4096 in all]; a job whose scene needs more fails on this worker.
    #[arg(long, value_name = "MIB")]
    pub texture_budget: Option<u64>,
}

/// Installs the `tracing` subscriber (`RUST_LOG`, default `tessera_worker=info`).
pub fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("tessera_worker=info"));
    let _ =
        tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_target(false).try_init();
}

/// Runs the worker until it is told to stop.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.threads == Some(0) {
        anyhow::bail!("--threads must be at least 1");
    }
    let runtime = tokio::runtime::Runtime::new()?;
    runtime.block_on(runner::run(args))
}
