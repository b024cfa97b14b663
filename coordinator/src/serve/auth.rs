//! Bearer-token authentication for every endpoint but `/healthz`, `/api/v1/openapi.json` and
//! the dashboard page: the worker token guards `WorkerService`, the client token guards
//! `JobService` and the REST API, and the viewer token opens the requests that only read
//! ([`only_reads`]); its writes get 403 / `PERMISSION_DENIED`. A missing or wrong token gets
//! HTTP 401, or gRPC `UNAUTHENTICATED` on gRPC paths. Without tokens configured, everything is
//! open (the server refuses to listen beyond loopback then, see `config.rs`).

use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::sync::Arc;

/// The configured tokens.
#[derive(Clone, Debug, Default)]
pub struct Tokens {
    /// Required of workers.
    pub worker: Option<String>,
    /// Required of clients.
    pub client: Option<String>,
    /// Taken, where a client token is set, for requests that only read.
    pub viewer: Option<String>,
}

/// The gRPC calls that only read, which the viewer token may make.
const GRPC_READS: [&str; 5] = ["GetJob", "ListJobs", "WatchJob", "GetResult", "ListWorkers"];

/// Whether a request only reads: an HTTP GET or HEAD (the REST reads, events, metrics) or a
/// reading gRPC call (a gRPC call is always a POST), server reflection included.
fn only_reads(method: &http::Method, path: &str) -> bool {
    if let Some(call) = path.strip_prefix("/tessera.v1.JobService/") {
        return GRPC_READS.contains(&call);
    }
    if path.starts_with("/tessera.v1.") {
        return false;
    }
    path.starts_with("/grpc.reflection.") || method == http::Method::GET || method == http::Method::HEAD
}

const WORKER_PREFIX: &str = "/tessera.v1.WorkerService/";
/// gRPC paths: Tessera's services and server reflection (which needs the client token).
const GRPC_PREFIXES: [&str; 2] = ["/tessera.v1.", "/grpc.reflection."];

/// Compares in time independent of the contents and of both lengths: the tokens are hashed to
/// fixed-size digests first, which are compared in constant time.
fn same(a: &[u8], b: &[u8]) -> bool {
    use sha2::Digest;
    use subtle::ConstantTimeEq;
    sha2::Sha256::digest(a).ct_eq(&sha2::Sha256::digest(b)).into()
}

/// The axum middleware.
pub async fn require_token(State(tokens): State<Arc<Tokens>>, req: Request, next: Next) -> Response {
    let path = req.uri().path();
    // liveness, the API's description and the dashboard page (none carries data) are public
    if matches!(path, "/healthz" | "/api/v1/healthz" | "/api/v1/openapi.json" | "/" | "/dashboard") {
        return next.run(req).await;
    }
    let expected = if path.starts_with(WORKER_PREFIX) { &tokens.worker } else { &tokens.client };
    let Some(expected) = expected else { return next.run(req).await };
    let given = req
        .headers()
        .get(http::header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    if given.is_some_and(|g| same(g.as_bytes(), expected.as_bytes())) {
        return next.run(req).await;
    }
    let viewer = !path.starts_with(WORKER_PREFIX)
        && tokens.viewer.as_ref().zip(given).is_some_and(|(v, g)| same(g.as_bytes(), v.as_bytes()));
    if viewer && only_reads(req.method(), path) {
        return next.run(req).await;
    }
    if viewer {
        let message = format!("the viewer token only reads: {} {path} needs the client token", req.method());
        return refuse(path, crate::serve::error::ErrorCode::PermissionDenied, &message);
    }
    let message = if given.is_some() { "wrong bearer token" } else { "missing bearer token (authorization header)" };
    refuse(path, crate::serve::error::ErrorCode::Unauthenticated, message)
}

/// A refusal as a gRPC status on gRPC paths, else as a problem document.
fn refuse(path: &str, code: crate::serve::error::ErrorCode, message: &str) -> Response {
    if GRPC_PREFIXES.iter().any(|p| path.starts_with(p)) {
        tonic::Status::new(code.grpc(), message).into_http::<axum::body::Body>().into_response()
    } else {
        crate::serve::error::ApiError::new(code, message).into_response()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_match_only_when_equal() {
        assert!(same(b"secret", b"secret"));
        assert!(!same(b"secret", b"secreT"));
        assert!(!same(b"secret", b"secret2"));
        assert!(!same(b"", b"secret"));
        assert!(same(b"", b""));
    }

    #[test]
    fn viewers_read_and_do_not_write() {
        use http::Method;
        assert!(only_reads(&Method::GET, "/api/v1/jobs"));
        assert!(only_reads(&Method::GET, "/api/v1/events"));
        assert!(only_reads(&Method::GET, "/metrics"));
        assert!(!only_reads(&Method::POST, "/api/v1/jobs"));
        assert!(!only_reads(&Method::DELETE, "/api/v1/jobs/j1"));
        assert!(!only_reads(&Method::PATCH, "/api/v1/jobs/j1"));
        assert!(only_reads(&Method::POST, "/tessera.v1.JobService/WatchJob"));
        assert!(!only_reads(&Method::POST, "/tessera.v1.JobService/SubmitJobStream"));
        assert!(!only_reads(&Method::POST, "/tessera.v1.JobService/CancelJob"));
        assert!(!only_reads(&Method::POST, "/tessera.v1.WorkerService/LeaseTiles"));
        assert!(!only_reads(&Method::GET, "/tessera.v1.JobService/Unknown"));
    }
}
