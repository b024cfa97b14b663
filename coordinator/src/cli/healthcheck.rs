//! `tessera healthcheck URL`: GETs the coordinator's `/healthz` and exits 0 when it answers
//! 200, 1 otherwise. Container images have no shell or curl (deploy/docker), so their
//! `HEALTHCHECK` runs this; it goes through the same connection code as the other client
//! commands (HTTP/2 over the tonic channel the coordinator also serves REST on), so `https://`
//! and `--ca-cert` work as they do for `tessera status`.
//!
//! Without a URL it checks `TESSERA_SERVER`, else `TESSERA_COORDINATOR` (the variable
//! `tessera-worker` reads), else `http://127.0.0.1:7878`: the worker image's `HEALTHCHECK`
//! thereby reports whether that worker reaches its coordinator, with no per-deployment setting.

use anyhow::{Context, bail};
use std::time::Duration;
use tonic::codegen::Service;

/// Arguments of `tessera healthcheck`.
#[derive(clap::Args, Debug, Clone)]
pub struct HealthcheckArgs {
    /// Coordinator URL (`https://` when it serves TLS); `/healthz` is appended [default:
    /// $TESSERA_COORDINATOR, else http://127.0.0.1:7878].
    #[arg(env = "TESSERA_SERVER")]
    pub url: Option<String>,
    /// PEM file of the CA (or self-signed certificate) an https:// coordinator's certificate
    /// chains to, trusted besides the system's roots.
    #[arg(long, env = "TESSERA_CA_CERT", value_name = "PEM")]
    pub ca_cert: Option<std::path::PathBuf>,
    /// Seconds to wait for the connection and the answer together.
    #[arg(long, default_value_t = 5.0, value_name = "SECONDS")]
    pub timeout: f64,
    /// Print nothing when healthy (for frequent probes whose output is kept, as Docker's).
    #[arg(long, short)]
    pub quiet: bool,
}

/// Runs `tessera healthcheck`.
pub fn healthcheck_command(args: &HealthcheckArgs) -> anyhow::Result<()> {
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        bail!("--timeout must be a positive number of seconds");
    }
    let timeout = Duration::from_secs_f64(args.timeout);
    let url = match &args.url {
        Some(url) => url.clone(),
        None => std::env::var("TESSERA_COORDINATOR").unwrap_or_else(|_| "http://127.0.0.1:7878".into()),
    };
    let base = url.trim_end_matches('/');
    // the base URL names the server; a URL already ending in /healthz is taken as it is
    let base = base.strip_suffix("/healthz").unwrap_or(base);
    let endpoint = tessera_link::connect::endpoint(base, args.ca_cert.as_deref())?.connect_timeout(timeout);
    let runtime = super::client::runtime()?;
    let status = runtime.block_on(async {
        tokio::time::timeout(timeout, async {
            let mut channel = endpoint.connect().await.with_context(|| format!("cannot connect to {base}"))?;
            let request =
                http::Request::get("/healthz").body(tonic::body::Body::empty()).context("cannot build the request")?;
            std::future::poll_fn(|cx| channel.poll_ready(cx)).await.with_context(|| format!("{base} is not ready"))?;
            let response = channel.call(request).await.with_context(|| format!("GET {base}/healthz failed"))?;
            anyhow::Ok(response.status())
        })
        .await
        .with_context(|| format!("no answer from {base}/healthz within {:.1} s", args.timeout))?
    });
    // a name lookup stuck in its blocking thread (no network) must not hold the exit past the
    // timeout, as dropping the runtime would
    runtime.shutdown_background();
    let status = status?;
    if !status.is_success() {
        bail!("{base}/healthz answered {status}");
    }
    if !args.quiet {
        println!("{base}: healthy");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[test]
    fn an_unreachable_coordinator_is_unhealthy_within_the_timeout() {
        // a port nobody listens on: bind one, note it, drop the listener
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let cli = crate::cli::Cli::try_parse_from([
            "tessera",
            "healthcheck",
            &format!("http://127.0.0.1:{port}"),
            "--timeout",
            "2",
        ])
        .unwrap();
        let crate::cli::Command::Healthcheck(args) = cli.command else { panic!("not healthcheck") };
        let started = std::time::Instant::now();
        assert!(healthcheck_command(&args).is_err());
        assert!(started.elapsed() < Duration::from_secs(5));
    }

    #[test]
    fn a_coordinator_answering_200_is_healthy_and_an_error_status_is_not() {
        // axum::serve as the coordinator uses it (HTTP/1.1 and HTTP/2 on one port)
        let runtime = tokio::runtime::Runtime::new().unwrap();
        let listener = runtime.block_on(tokio::net::TcpListener::bind("127.0.0.1:0")).unwrap();
        let port = listener.local_addr().unwrap().port();
        let healthy = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
        let flag = healthy.clone();
        let app = axum::Router::new().route(
            "/healthz",
            axum::routing::get(move || async move {
                if flag.load(std::sync::atomic::Ordering::SeqCst) {
                    http::StatusCode::OK
                } else {
                    http::StatusCode::SERVICE_UNAVAILABLE
                }
            }),
        );
        runtime.spawn(async move { axum::serve(listener, app).await });
        for url in [format!("http://127.0.0.1:{port}"), format!("http://127.0.0.1:{port}/healthz")] {
            let args = HealthcheckArgs { url: Some(url), ca_cert: None, timeout: 5.0, quiet: true };
            healthcheck_command(&args).unwrap();
        }
        healthy.store(false, std::sync::atomic::Ordering::SeqCst);
        let args = HealthcheckArgs {
            url: Some(format!("http://127.0.0.1:{port}/")),
            ca_cert: None,
            timeout: 5.0,
            quiet: true,
        };
        let e = healthcheck_command(&args).unwrap_err().to_string();
        assert!(e.contains("503"), "{e}");
    }

    #[test]
    fn a_bad_timeout_or_url_is_refused() {
        let args = HealthcheckArgs { url: Some("http://127.0.0.1:1".into()), ca_cert: None, timeout: 0.0, quiet: true };
        assert!(healthcheck_command(&args).is_err());
        let args = HealthcheckArgs { url: Some("ftp://x".into()), ca_cert: None, timeout: 1.0, quiet: true };
        assert!(healthcheck_command(&args).is_err());
    }
}
