//! The coordinator's configuration: the flags of `tessera serve` (each also read from a
//! `TESSERA_*` environment variable where a secret is concerned), checked and turned into the
//! service's settings and the API tokens.

use super::auth::Tokens;
use super::job::service::{DEFAULT_MAX_PIXELS, DEFAULT_MAX_TILES, LeaseLifetime, ServiceConfig};
use anyhow::{Context, bail};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;
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
    /// Most tiles a job may plan (vcm, bdpt and lt plan one per iteration of the spp).
    #[arg(long, default_value_t = DEFAULT_MAX_TILES)]
    pub max_tiles: u64,
    /// Largest film a job may have, in pixels (width × height).
    #[arg(long, default_value_t = DEFAULT_MAX_PIXELS)]
    pub max_pixels: u64,
    /// Delete finished, failed and cancelled jobs with all their data this long after they
    /// ended (`90s`, `30m`, `24h`, `7d`, `1h30m`) [default: keep them until deleted].
    #[arg(long, value_name = "DURATION", value_parser = parse_duration)]
    pub retain_finished: Option<Duration>,
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
            max_tiles: self.max_tiles,
            retain_finished_ms: self.retain_finished.map(|d| d.as_millis() as u64),
        };
        Ok((tokens, cfg))
    }
}

/// A duration as a sequence of numbers with units `ms`, `s`, `m`, `h` or `d`: `90s`, `1.5h`,
/// `1h30m`, `7d`.
pub fn parse_duration(text: &str) -> Result<Duration, String> {
    let bad = || format!("invalid duration {text:?} (write e.g. 90s, 30m, 24h, 7d or 1h30m)");
    let mut rest = text.trim();
    if rest.is_empty() {
        return Err(bad());
    }
    let mut total = 0.0;
    while !rest.is_empty() {
        let digits = rest.find(|c: char| !(c.is_ascii_digit() || c == '.')).ok_or_else(bad)?;
        let unit_len = rest[digits..].find(|c: char| c.is_ascii_digit()).unwrap_or(rest.len() - digits);
        let value: f64 = rest[..digits].parse().map_err(|_| bad())?;
        let seconds = match &rest[digits..digits + unit_len] {
            "ms" => 1e-3,
            "s" => 1.0,
            "m" => 60.0,
            "h" => 3600.0,
            "d" => 86_400.0,
            _ => return Err(bad()),
        };
        total += value * seconds;
        rest = &rest[digits + unit_len..];
    }
    Duration::try_from_secs_f64(total).map_err(|_| bad())
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_parse_with_units_and_bad_ones_are_refused() {
        let secs = |t: &str| parse_duration(t).map(|d| d.as_secs_f64());
        assert_eq!(secs("90s"), Ok(90.0));
        assert_eq!(secs("30m"), Ok(1800.0));
        assert_eq!(secs("24h"), Ok(86_400.0));
        assert_eq!(secs("7d"), Ok(604_800.0));
        assert_eq!(secs("1h30m"), Ok(5400.0));
        assert_eq!(secs("1.5s"), Ok(1.5));
        assert_eq!(secs("250ms"), Ok(0.25));
        for bad in ["", "90", "s", "5x", "1h30", "-3s", "1..2s", "5 s"] {
            assert!(parse_duration(bad).is_err(), "{bad:?} accepted");
        }
    }
}
