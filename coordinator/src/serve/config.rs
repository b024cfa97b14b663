//! The coordinator's configuration: the flags of `tessera serve` (each also read from a
//! `TESSERA_*` environment variable where a secret is concerned), checked and turned into the
//! service's settings and the API tokens.

use super::auth::Tokens;
use super::job::service::{DEFAULT_MAX_PIXELS, LeaseLifetime, ServiceConfig};
use anyhow::{Context, bail};
use std::net::SocketAddr;
use std::path::PathBuf;
use tessera_common::texture::TextureLimits;

/// Arguments of `tessera serve`.
#[derive(clap::Args, Debug, Clone)]
pub struct ServeArgs {
    /// Address to listen on (gRPC and REST share it).
    #[arg(long, default_value = "127.0.0.1:7878")]
    pub listen: SocketAddr,
    /// Where jobs, tiles and blobs are stored; a restart on the same folder resumes its jobs.
    #[arg(long, default_value = "tessera-data")]
    pub data_dir: PathBuf,
    /// Bearer token workers must present.
    #[arg(long, env = "TESSERA_WORKER_TOKEN", hide_env_values = true)]
    pub worker_token: Option<String>,
    /// File holding the worker token.
    #[arg(long, conflicts_with = "worker_token")]
    pub worker_token_file: Option<PathBuf>,
    /// Bearer token clients (submit, status, REST) must present.
    #[arg(long, env = "TESSERA_CLIENT_TOKEN", hide_env_values = true)]
    pub client_token: Option<String>,
    /// File holding the client token.
    #[arg(long, conflicts_with = "client_token")]
    pub client_token_file: Option<PathBuf>,
    /// Allow a non-loopback address without tokens.
    #[arg(long)]
    pub insecure: bool,
    /// Seconds a lease lives without a heartbeat before its tile is re-queued.
    #[arg(long, default_value_t = 30.0)]
    pub lease_timeout: f64,
    /// Least seconds a lease may be held with heartbeats but no result (doubled at each
    /// earlier failure of its tile): the floor of its lifetime.
    #[arg(long, default_value_t = 120.0, value_name = "SECONDS")]
    pub lease_max_floor: f64,
    /// A lease's lifetime is this many times what its tile should take at the slowest rate
    /// measured for its job (never below --lease-max-floor).
    #[arg(long, default_value_t = 8.0)]
    pub lease_max_factor: f64,
    /// Least seconds between film checkpoints of a job (big films wait longer: at least 20 times
    /// the last checkpoint's write time).
    #[arg(long, default_value_t = 2.0)]
    pub checkpoint_interval: f64,
    /// Largest accepted upload (scene bundle) in MiB.
    #[arg(long, default_value_t = 1024)]
    pub max_upload_mb: usize,
    /// Memory a submitted scene's decoded textures and environment maps may take while the
    /// coordinator validates it, in MiB [default: 1024 per image, 4096 in all].
    #[arg(long, value_name = "MIB")]
    pub texture_budget: Option<u64>,
    /// Largest film a job may have, in pixels (width × height).
    #[arg(long, default_value_t = DEFAULT_MAX_PIXELS)]
    pub max_pixels: u64,
}

impl ServeArgs {
    /// Checks the flags and reads the token files: the API tokens and the service settings.
    pub fn resolve(&self) -> anyhow::Result<(Tokens, ServiceConfig)> {
        let tokens = Tokens {
            worker: read_token(&self.worker_token, &self.worker_token_file)?,
            client: read_token(&self.client_token, &self.client_token_file)?,
        };
        if !self.listen.ip().is_loopback() && (tokens.worker.is_none() || tokens.client.is_none()) && !self.insecure {
            bail!(
                "refusing to listen on {} without --worker-token and --client-token (pass --insecure to allow it)",
                self.listen
            );
        }
        if !(self.lease_timeout > 0.0 && self.lease_timeout.is_finite()) {
            bail!("--lease-timeout must be a positive number of seconds, got {}", self.lease_timeout);
        }
        if !(self.lease_max_floor > 0.0 && self.lease_max_floor.is_finite()) {
            bail!("--lease-max-floor must be a positive number of seconds, got {}", self.lease_max_floor);
        }
        if !(self.lease_max_factor >= 1.0 && self.lease_max_factor.is_finite()) {
            bail!("--lease-max-factor must be a number of at least 1, got {}", self.lease_max_factor);
        }
        let cfg = ServiceConfig {
            lease_timeout_ms: (self.lease_timeout * 1000.0) as u64,
            lease_lifetime: LeaseLifetime {
                floor_ms: (self.lease_max_floor * 1000.0) as u64,
                factor: self.lease_max_factor,
            },
            checkpoint_interval_ms: (self.checkpoint_interval.max(0.0) * 1000.0) as u64,
            texture_limits: self
                .texture_budget
                .map_or_else(TextureLimits::default, |mib| TextureLimits::total(mib << 20)),
            max_pixels: self.max_pixels,
        };
        Ok((tokens, cfg))
    }
}

fn read_token(value: &Option<String>, file: &Option<PathBuf>) -> anyhow::Result<Option<String>> {
    if let Some(f) = file {
        let t = std::fs::read_to_string(f).with_context(|| format!("cannot read token file {}", f.display()))?;
        let t = t.trim().to_string();
        if t.is_empty() {
            bail!("token file {} is empty", f.display());
        }
        return Ok(Some(t));
    }
    Ok(value.clone().filter(|t| !t.is_empty()))
}
