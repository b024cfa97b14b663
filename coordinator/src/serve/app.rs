//! `tessera serve`: wiring of the coordinator. Opens the data directory (resuming unfinished
//! jobs), serves gRPC (`JobService`, `WorkerService`) and REST on one port, over TLS when given
//! a certificate, behind the browser guard and bearer-token authentication, with connections
//! bounded by the descriptor limit ([`super::conn`]), expires leases on a timer (and, with
//! `--retain-finished`, deletes jobs that ended long enough ago on another), and shuts down
//! gracefully on SIGINT/SIGTERM.

use super::auth::Tokens;
use super::config::{Resolved, ServeArgs};
use super::conn::{LimitedListener, Limits, Peer};
use super::error::{ApiError, ErrorCode};
use super::job::service::JobService;
use super::origin::{AllowedHosts, Guard, Scheme};
use super::state::{AppState, now_ms};
use super::tls::TlsListener;
use anyhow::Context;
use axum::extract::connect_info::Connected;
use axum::serve::{IncomingStream, Listener};
use std::sync::Arc;
use std::time::Duration;

/// How long a graceful shutdown waits for open requests (long polls, watch streams).
const DRAIN_TIMEOUT: Duration = Duration::from_secs(3);
/// TCP keep-alive on accepted connections: a peer that left the network mid-request (a watch
/// stream, a long poll) is found after about 90 s instead of never.
const KEEPALIVE: socket2::TcpKeepalive = socket2::TcpKeepalive::new()
    .with_time(Duration::from_secs(60))
    .with_interval(Duration::from_secs(10))
    .with_retries(3);

/// The whole HTTP surface: gRPC and REST on one router, behind the browser guard (first, so
/// that a foreign page is refused with or without a token) and authentication, counting each
/// connection's requests in flight for the connection limits.
pub fn router(state: Arc<AppState>, tokens: Tokens, guard: Guard) -> axum::Router {
    crate::serve::grpc::router(state.clone())
        .merge(crate::serve::rest::router(state))
        // tonic's routes answer unknown paths with 200 + grpc-status 12 unless a fallback is set
        .fallback(|| async { ApiError::new(ErrorCode::NotFound, "no such route") })
        .layer(axum::middleware::from_fn(crate::serve::error::problem_json))
        .layer(axum::middleware::from_fn_with_state(Arc::new(tokens), crate::serve::auth::require_token))
        .layer(axum::middleware::from_fn_with_state(Arc::new(guard), crate::serve::origin::refuse_foreign_browsers))
        .layer(tower_http::trace::TraceLayer::new_for_http())
        .layer(axum::middleware::from_fn(crate::serve::conn::track_requests))
}

/// Raises the descriptor limit and derives the connection limits from it and the flags.
fn connection_limits(args: &ServeArgs) -> Limits {
    let fds = match super::conn::raise_fd_limit() {
        Ok(fds) => {
            tracing::info!(was = fds.was, now = fds.now, "file descriptor limit");
            fds.now
        }
        Err(e) => {
            tracing::warn!(error = %e, "cannot read or raise the file descriptor limit; assuming 1024");
            1024
        }
    };
    let (limits, lowered) = Limits::for_fds(fds, args.max_connections, args.max_connections_per_ip);
    if lowered {
        tracing::warn!(
            max_connections = limits.max_connections,
            "--max-connections lowered to fit the file descriptor limit"
        );
    }
    tracing::info!(
        max_connections = limits.max_connections,
        max_connections_per_ip = limits.max_per_peer,
        "connection limits"
    );
    limits
}

/// Runs `tessera serve`.
pub fn serve_command(args: &ServeArgs) -> anyhow::Result<()> {
    let Resolved { tokens, service: cfg, tls } = args.resolve()?;
    let limits = connection_limits(args);
    let hosts = AllowedHosts::new(&args.allowed_hosts);
    let runtime = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    runtime.block_on(async {
        let data_dir = args.data_dir.clone();
        let svc = tokio::task::spawn_blocking(move || JobService::open(&data_dir, cfg, now_ms()))
            .await?
            .with_context(|| format!("cannot open data dir {}", args.data_dir.display()))?;
        let svc = Arc::new(svc);
        let state = Arc::new(AppState::new(svc.clone(), args.max_upload_mb << 20));
        let listener = tokio::net::TcpListener::bind(args.listen)
            .await
            .with_context(|| format!("cannot listen on {}", args.listen))?;
        let addr = listener.local_addr()?;
        let listener = axum::serve::ListenerExt::tap_io(listener, |tcp| {
            // small gRPC answers (upload outcomes, leases) must not wait for Nagle's algorithm
            // to see the ACK of the previous segment: that costs tens of milliseconds a request
            if let Err(e) = tcp.set_nodelay(true) {
                tracing::warn!(error = %e, "cannot set TCP_NODELAY");
            }
            if let Err(e) = socket2::SockRef::from(&*tcp).set_tcp_keepalive(&KEEPALIVE) {
                tracing::warn!(error = %e, "cannot set TCP keep-alive");
            }
        });
        let listener = LimitedListener::new(listener, limits);
        let scheme = if tls.is_some() { Scheme::Https } else { Scheme::Http };
        tracing::info!(extra = ?hosts.extra(), "browsers allowed at localhost, IP addresses and the extra host names");
        // the one line of stdout: scripts and tests read the address from it
        println!("tessera serve: listening on {}://{addr}", scheme.as_str());
        tracing::info!(%addr, scheme = scheme.as_str(), data_dir = %args.data_dir.display(), "coordinator started");
        let ticker = {
            let svc = svc.clone();
            let period = Duration::from_millis(svc.expiry_period_ms());
            tokio::spawn(async move {
                let mut tick = tokio::time::interval(period);
                loop {
                    tick.tick().await;
                    let svc = svc.clone();
                    let run = move || {
                        // jobs of frames plan the next frames as earlier ones end
                        svc.plan_frames(now_ms()).map_err(|e| ("frame planning", e))?;
                        svc.expire(now_ms()).map_err(|e| ("lease expiry", e))
                    };
                    if let Ok(Err((what, e))) = tokio::task::spawn_blocking(run).await {
                        tracing::error!(error = %e, "{what} failed");
                    }
                }
            })
        };
        let retention = svc.retain_finished_ms().map(|retain_ms| {
            let svc = svc.clone();
            // often enough that a job goes within about a quarter of its retention
            let period = Duration::from_millis((retain_ms / 4).clamp(200, 60_000));
            tokio::spawn(async move {
                let mut tick = tokio::time::interval(period);
                tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
                loop {
                    tick.tick().await;
                    let svc = svc.clone();
                    if let Ok(Err(e)) = tokio::task::spawn_blocking(move || svc.expire_finished(now_ms())).await {
                        tracing::error!(error = %e, "deleting expired jobs failed");
                    }
                }
            })
        });
        let publisher = crate::serve::events::spawn_publisher(svc.clone(), state.events.clone());
        let app = router(state, tokens, Guard { scheme, hosts });
        match tls {
            Some(config) => serve_until_stopped(TlsListener::new(listener, config), app).await?,
            None => serve_until_stopped(listener, app).await?,
        }
        ticker.abort();
        publisher.abort();
        if let Some(r) = retention {
            r.abort();
        }
        tracing::info!("coordinator stopped");
        Ok(())
    })
}

/// Serves `app` on `listener` until SIGINT/SIGTERM. Graceful shutdown waits for requests in
/// flight, but long polls and watch streams may not end by themselves: they get DRAIN_TIMEOUT,
/// then the server stops (every transition is already persisted, so stopping is safe).
async fn serve_until_stopped<L>(listener: L, app: axum::Router) -> std::io::Result<()>
where
    L: Listener<Addr = Peer>,
    Peer: for<'a> Connected<IncomingStream<'a, L>>,
{
    let (stopping_tx, mut stopping) = tokio::sync::watch::channel(false);
    let app = app.into_make_service_with_connect_info::<Peer>();
    let server = axum::serve(listener, app).with_graceful_shutdown(async move {
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
    Ok(())
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
