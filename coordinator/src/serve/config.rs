//! The coordinator's configuration: the flags of `tessera serve` (each also read from its
//! `TESSERA_*` environment variable and settable in the `--config` file, see
//! [`tessera_config`]), checked and turned into the service's settings, the API tokens and the
//! TLS configuration.

use super::auth::Tokens;
use super::job::service::{
    DEFAULT_MAX_PIXELS, DEFAULT_MAX_TILES, DEFAULT_MAX_WORKERS, DEFAULT_MIN_FREE_SPACE_MIB, LeaseLifetime,
    ServiceConfig,
};
use anyhow::{Context, bail};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tessera_common::scene::{DEFAULT_MAX_TRIANGLES, SceneLimits};
use tessera_common::settings::{DEFAULT_MAX_TILE_BYTES, WorkLimits};
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
    /// Bearer token that only reads: job and worker lists, outputs, events, metrics (for
    /// dashboards, Prometheus, KEDA). Needs --client-token.
    #[arg(long, env = "TESSERA_VIEWER_TOKEN", hide_env_values = true)]
    pub viewer_token: Option<String>,
    /// File holding the viewer token.
    #[arg(long, conflicts_with = "viewer_token")]
    pub viewer_token_file: Option<PathBuf>,
    /// Serve gRPC, REST and the dashboard over TLS with this certificate chain (PEM, the
    /// server's certificate first).
    #[arg(long, value_name = "PEM", requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// The private key of --tls-cert (PEM: PKCS#8, PKCS#1 or SEC1).
    #[arg(long, value_name = "PEM", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// Allow a non-loopback address without TLS or without tokens.
    #[arg(long)]
    pub insecure: bool,
    /// A host name browsers may reach the coordinator under (the dashboard's address),
    /// besides localhost, *.localhost and IP addresses; repeatable or comma-separated
    /// (`TESSERA_ALLOWED_HOSTS`). `*.example.com` allows its subdomains, `*` any name (behind a
    /// proxy of your own). Clients that are not browsers may use any name.
    #[arg(
        long = "allowed-host",
        value_name = "NAME",
        env = "TESSERA_ALLOWED_HOSTS",
        value_delimiter = ',',
        value_parser = super::origin::parse_allowed_host
    )]
    pub allowed_hosts: Vec<String>,
    /// Most connections at once; beyond it the least recently active is closed for the newcomer
    /// [default: the file descriptor limit minus a reserve, at most 8192].
    #[arg(long, value_name = "N", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(2..))]
    pub max_connections: Option<usize>,
    /// Most connections at once from one IP address (IPv6: one /64) [default: a quarter of
    /// --max-connections; behind a proxy, raise it to --max-connections].
    #[arg(long, value_name = "N", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    pub max_connections_per_ip: Option<usize>,
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
    /// Most tiles a job may plan (vcm, bdpt and lt plan one per iteration of the spp). Not
    /// `--max-tiles`, the worker's tiles per lease, so that one environment serves both.
    #[arg(long, default_value_t = DEFAULT_MAX_TILES)]
    pub max_job_tiles: u64,
    /// Largest film a job may have, in pixels (width × height).
    #[arg(long, default_value_t = DEFAULT_MAX_PIXELS)]
    pub max_pixels: u64,
    /// Most triangles a submitted scene's shapes may hold together (each shape naming a mesh
    /// holds its own copy; loading takes up to about 440 bytes a triangle, on the coordinator
    /// and on workers, which need the same flag).
    #[arg(long, default_value_t = DEFAULT_MAX_TRIANGLES)]
    pub max_triangles: u64,
    /// Memory one tile of a job may need on a worker, in MiB, as estimated from its settings
    /// and film (light paths, EMIS moments): jobs that need more are refused at submission.
    #[arg(long, value_name = "MIB", default_value_t = DEFAULT_MAX_TILE_BYTES >> 20)]
    pub max_tile_memory: u64,
    /// Delete finished, failed and cancelled jobs with all their data this long after they
    /// ended (`90s`, `30m`, `24h`, `7d`, `1h30m`) [default: keep them until deleted].
    #[arg(long, value_name = "DURATION", value_parser = parse_duration)]
    pub retain_finished: Option<Duration>,
    /// Most workers known at once: registrations past it are refused until silent workers are
    /// forgotten.
    #[arg(long, default_value_t = DEFAULT_MAX_WORKERS)]
    pub max_workers: usize,
    /// Forget workers silent this long that hold no lease (`90s`, `30m`, `24h`, `7d`).
    #[arg(long, value_name = "DURATION", value_parser = parse_duration, default_value = "1h")]
    pub forget_workers_after: Duration,
    /// MiB of free disk space kept in reserve in the data folder: below it, submissions are
    /// refused (507) and no tile is leased, so that deleting and cancelling always have room.
    #[arg(long, value_name = "MIB", default_value_t = DEFAULT_MIN_FREE_SPACE_MIB)]
    pub min_free_space: u64,
    /// Log format.
    #[command(flatten)]
    pub log: tessera_config::LogArgs,
    /// `--config` and `--print-config`.
    #[command(flatten)]
    pub config: tessera_config::ConfigArgs,
}

/// The checked configuration.
pub struct Resolved {
    /// The API tokens.
    pub tokens: Tokens,
    /// The service's settings.
    pub service: ServiceConfig,
    /// The TLS configuration, when serving over TLS.
    pub tls: Option<Arc<rustls::ServerConfig>>,
}

impl ServeArgs {
    /// Checks the flags and reads the token, certificate and key files.
    pub fn resolve(&self) -> anyhow::Result<Resolved> {
        let tokens = Tokens {
            worker: read_token(&self.worker_token, &self.worker_token_file)?,
            client: read_token(&self.client_token, &self.client_token_file)?,
            viewer: read_token(&self.viewer_token, &self.viewer_token_file)?,
        };
        // without a client token everything is open, so a viewer token would protect nothing
        if tokens.viewer.is_some() && tokens.client.is_none() {
            bail!("--viewer-token needs --client-token: without it every request may write");
        }
        if tokens.viewer.is_some() && tokens.viewer == tokens.client {
            bail!("--viewer-token must differ from --client-token");
        }
        let tls = match (&self.tls_cert, &self.tls_key) {
            (Some(cert), Some(key)) => Some(super::tls::server_config(cert, key)?),
            (None, None) => None,
            // clap checks this for flags and variables, not for values from the settings file
            _ => bail!("--tls-cert and --tls-key go together: give both or neither"),
        };
        // beyond loopback, tokens would cross the network in the clear without TLS
        let missing: Vec<&str> = [
            (tls.is_none(), "TLS (--tls-cert, --tls-key)"),
            (tokens.worker.is_none() || tokens.client.is_none(), "tokens (--worker-token, --client-token)"),
        ]
        .into_iter()
        .filter_map(|(missing, what)| missing.then_some(what))
        .collect();
        if !self.listen.ip().is_loopback() && !missing.is_empty() && !self.insecure {
            bail!(
                "refusing to listen on {} without {} (pass --insecure to allow it)",
                self.listen,
                missing.join(" and ")
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
            scene_limits: SceneLimits {
                textures: self
                    .texture_budget
                    .map_or_else(TextureLimits::default, |mib| TextureLimits::total(mib << 20)),
                max_triangles: self.max_triangles,
            },
            work_limits: WorkLimits { max_tile_bytes: self.max_tile_memory << 20, ..WorkLimits::default() },
            max_pixels: self.max_pixels,
            max_tiles: self.max_job_tiles,
            retain_finished_ms: self.retain_finished.map(|d| d.as_millis() as u64),
            result_file_bytes: crate::serve::storage::blobs::RESULT_FILE_BYTES,
            max_workers: self.max_workers,
            forget_workers_ms: self.forget_workers_after.as_millis() as u64,
            min_free_bytes: self.min_free_space << 20,
        };
        Ok(Resolved { tokens, service: cfg, tls })
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
    if let (Some(_), Some(f)) = (value, file) {
        // one from the settings file, the other from a flag or variable: which was meant?
        bail!("a token and a token file ({}) are both given: set one of them", f.display());
    }
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

    use clap::Parser;

    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        serve: ServeArgs,
    }

    fn resolve(args: &[&str]) -> anyhow::Result<Resolved> {
        Cli::try_parse_from(std::iter::once("serve").chain(args.iter().copied()))?.serve.resolve()
    }

    /// A certificate and key for localhost in `dir`.
    fn pair(dir: &std::path::Path) -> (String, String) {
        let made = rcgen::generate_simple_self_signed(vec!["localhost".to_string()]).unwrap();
        let (cert, key) = (dir.join("cert.pem"), dir.join("key.pem"));
        std::fs::write(&cert, made.cert.pem()).unwrap();
        std::fs::write(&key, made.signing_key.serialize_pem()).unwrap();
        (cert.to_str().unwrap().to_string(), key.to_str().unwrap().to_string())
    }

    #[test]
    fn a_viewer_token_needs_a_client_token_of_its_own() {
        let e = format!("{:#}", resolve(&["--viewer-token", "v"]).err().unwrap());
        assert!(e.contains("--viewer-token needs --client-token"), "{e}");
        let e = format!("{:#}", resolve(&["--viewer-token", "same", "--client-token", "same"]).err().unwrap());
        assert!(e.contains("must differ"), "{e}");
        let ok = resolve(&["--viewer-token", "v", "--client-token", "c"]).unwrap();
        assert_eq!(ok.tokens.viewer.as_deref(), Some("v"));
    }

    #[test]
    fn resolve_requires_tls_and_tokens_beyond_loopback() {
        let dir = tempfile::tempdir().unwrap();
        let (cert, key) = pair(dir.path());
        let tokens = ["--worker-token", "w", "--client-token", "c"];
        let tls = ["--tls-cert", cert.as_str(), "--tls-key", key.as_str()];
        let public = ["--listen", "0.0.0.0:7878"];
        let e = format!("{:#}", resolve(&public).err().unwrap());
        assert!(e.contains("without TLS (--tls-cert, --tls-key) and tokens") && e.contains("--insecure"), "{e}");
        let e = format!("{:#}", resolve(&[&public[..], &tokens[..]].concat()).err().unwrap());
        assert!(e.contains("without TLS") && !e.contains("tokens"), "{e}");
        let e = format!("{:#}", resolve(&[&public[..], &tls[..]].concat()).err().unwrap());
        assert!(e.contains("without tokens") && !e.contains("TLS"), "{e}");
        let ok = resolve(&[&public[..], &tls[..], &tokens[..]].concat()).unwrap();
        assert!(ok.tls.is_some() && ok.tokens.client.is_some());
        assert!(resolve(&[&public[..], &["--insecure"][..]].concat()).unwrap().tls.is_none());
        assert!(resolve(&[]).is_ok(), "loopback needs neither");
    }

    #[test]
    fn resolve_needs_both_tls_files_and_names_a_bad_one() {
        let dir = tempfile::tempdir().unwrap();
        let (cert, _) = pair(dir.path());
        assert!(resolve(&["--tls-cert", &cert]).is_err(), "--tls-cert without --tls-key");
        let missing = dir.path().join("nokey.pem");
        let e = format!("{:#}", resolve(&["--tls-cert", &cert, "--tls-key", missing.to_str().unwrap()]).err().unwrap());
        assert!(e.contains("nokey.pem"), "{e}");
    }
}
