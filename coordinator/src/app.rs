//! `tessera serve`: wiring of the coordinator. Opens the data directory (resuming unfinished
//! jobs), serves gRPC (`JobService`, `WorkerService`) and REST on one port behind bearer-token
//! authentication, expires leases on a timer, and shuts down gracefully on SIGINT/SIGTERM.

use crate::auth::Tokens;
use crate::error::{ApiError, ErrorCode};
use crate::job::service::{JobService, ServiceConfig, ServiceError};
use anyhow::{Context, bail};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

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
    /// Least seconds between film checkpoints of a job (big films wait longer: at least 20 times
    /// the last checkpoint's write time).
    #[arg(long, default_value_t = 2.0)]
    pub checkpoint_interval: f64,
    /// Largest accepted upload (scene bundle) in MiB.
    #[arg(long, default_value_t = 1024)]
    pub max_upload_mb: usize,
}

/// How long a graceful shutdown waits for open requests (long polls, watch streams).
const DRAIN_TIMEOUT: Duration = Duration::from_secs(3);

/// What the API layers share.
pub struct AppState {
    /// The domain service.
    pub svc: Arc<JobService>,
    /// Upload limit in bytes.
    pub max_upload_bytes: usize,
}

/// Milliseconds since the Unix epoch: the clock the pure model is fed with.
pub fn now_ms() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_millis() as u64)
}

/// Runs a synchronous service call on a blocking thread.
pub async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, ServiceError> + Send + 'static,
) -> Result<T, ApiError> {
    match tokio::task::spawn_blocking(f).await {
        Ok(r) => r.map_err(ApiError::from),
        Err(e) => {
            tracing::error!(error = %e, "blocking task failed");
            Err(ApiError::new(ErrorCode::Internal, "internal error (see the coordinator's log)"))
        }
    }
}

impl From<ApiError> for tonic::Status {
    fn from(e: ApiError) -> Self {
        e.to_status()
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

/// The whole HTTP surface: gRPC and REST on one router, behind authentication.
pub fn router(state: Arc<AppState>, tokens: Tokens) -> axum::Router {
    crate::grpc::router(state.clone())
        .merge(crate::rest::router(state))
        // tonic's routes answer unknown paths with 200 + grpc-status 12 unless a fallback is set
        .fallback(|| async { ApiError::new(ErrorCode::NotFound, "no such route") })
        .layer(axum::middleware::from_fn_with_state(Arc::new(tokens), crate::auth::require_token))
        .layer(tower_http::trace::TraceLayer::new_for_http())
}

/// Runs `tessera serve`.
pub fn serve_command(args: &ServeArgs) -> anyhow::Result<()> {
    let tokens = Tokens {
        worker: read_token(&args.worker_token, &args.worker_token_file)?,
        client: read_token(&args.client_token, &args.client_token_file)?,
    };
    if !args.listen.ip().is_loopback() && (tokens.worker.is_none() || tokens.client.is_none()) && !args.insecure {
        bail!(
            "refusing to listen on {} without --worker-token and --client-token (pass --insecure to allow it)",
            args.listen
        );
    }
    if !(args.lease_timeout > 0.0 && args.lease_timeout.is_finite()) {
        bail!("--lease-timeout must be a positive number of seconds, got {}", args.lease_timeout);
    }
    let cfg = ServiceConfig {
        lease_timeout_ms: (args.lease_timeout * 1000.0) as u64,
        checkpoint_interval_ms: (args.checkpoint_interval.max(0.0) * 1000.0) as u64,
    };
    let runtime = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    runtime.block_on(async {
        let data_dir = args.data_dir.clone();
        let svc = tokio::task::spawn_blocking(move || JobService::open(&data_dir, cfg, now_ms()))
            .await?
            .with_context(|| format!("cannot open data dir {}", args.data_dir.display()))?;
        let svc = Arc::new(svc);
        let state = Arc::new(AppState { svc: svc.clone(), max_upload_bytes: args.max_upload_mb << 20 });
        let listener = tokio::net::TcpListener::bind(args.listen)
            .await
            .with_context(|| format!("cannot listen on {}", args.listen))?;
        let addr = listener.local_addr()?;
        // small gRPC answers (upload outcomes, leases) must not wait for Nagle's algorithm to
        // see the ACK of the previous segment: that costs tens of milliseconds per request
        let listener = axum::serve::ListenerExt::tap_io(listener, |tcp| {
            if let Err(e) = tcp.set_nodelay(true) {
                tracing::warn!(error = %e, "cannot set TCP_NODELAY");
            }
        });
        // the one line of stdout: scripts and tests read the address from it
        println!("tessera serve: listening on http://{addr}");
        tracing::info!(%addr, data_dir = %args.data_dir.display(), "coordinator started");
        let ticker = {
            let svc = svc.clone();
            let period = Duration::from_millis((svc.lease_timeout_ms() / 4).clamp(50, 1000));
            tokio::spawn(async move {
                let mut tick = tokio::time::interval(period);
                loop {
                    tick.tick().await;
                    let svc = svc.clone();
                    if let Ok(Err(e)) = tokio::task::spawn_blocking(move || svc.expire(now_ms())).await {
                        tracing::error!(error = %e, "lease expiry failed");
                    }
                }
            })
        };
        // graceful shutdown waits for requests in flight, but long polls and watch streams may
        // not end by themselves: give them DRAIN_TIMEOUT, then stop (every transition is
        // already persisted, so stopping is safe)
        let (stopping_tx, mut stopping) = tokio::sync::watch::channel(false);
        let server = axum::serve(listener, router(state, tokens)).with_graceful_shutdown(async move {
            shutdown_signal().await;
            tracing::info!("shutting down");
            let _ = stopping_tx.send(true);
        });
        tokio::select! {
            r = server => r?,
            _ = async {
                let _ = stopping.wait_for(|s| *s).await;
                tokio::time::sleep(DRAIN_TIMEOUT).await;
            } => tracing::warn!("requests still open after the drain timeout; stopping anyway"),
        }
        ticker.abort();
        tracing::info!("coordinator stopped");
        Ok(())
    })
}

/// Resolves on SIGINT or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        let mut term = match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(s) => s,
            Err(_) => return ctrl_c.await.unwrap_or(()),
        };
        tokio::select! {
            _ = ctrl_c => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    ctrl_c.await.unwrap_or(());
}
