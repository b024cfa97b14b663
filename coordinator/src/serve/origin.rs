//! Cross-site request forgery guard: a browser showing a page of another origin must not
//! submit or cancel jobs, whether the farm uses tokens or not (without tokens on loopback, any
//! web page could otherwise post a multipart form to `/api/v1/jobs`).
//!
//! A state-changing request (any method but GET, HEAD, OPTIONS and TRACE) is refused with 403
//! when its `Origin` header names another origin than the server's own (the scheme it serves
//! plus the `Host` it was reached at), or, lacking `Origin`, when `Sec-Fetch-Site` says
//! `cross-site` or `same-site`. Requests without either header (the `tessera` command, workers,
//! curl) pass: only browsers send them, and browsers always do on such requests. The dashboard
//! calls the API from the server's own origin and passes. gRPC paths are guarded too, since a
//! form can post to any path.

use crate::serve::error::{ApiError, ErrorCode};
use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use http::{HeaderMap, Method};

/// The scheme the server is reached by, part of its origin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scheme {
    /// Plain text.
    Http,
    /// TLS.
    Https,
}

impl Scheme {
    /// `http` or `https`.
    pub fn as_str(self) -> &'static str {
        match self {
            Scheme::Http => "http",
            Scheme::Https => "https",
        }
    }

    fn default_port(self) -> &'static str {
        match self {
            Scheme::Http => "80",
            Scheme::Https => "443",
        }
    }
}

/// Why a request was refused: the foreign origin it came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Foreign(pub String);

/// Whether a request may proceed. `host` is where the client reached the server (the `Host`
/// header, or the `:authority` of HTTP/2).
pub fn check(scheme: Scheme, method: &Method, host: Option<&str>, headers: &HeaderMap) -> Result<(), Foreign> {
    if matches!(*method, Method::GET | Method::HEAD | Method::OPTIONS | Method::TRACE) {
        return Ok(());
    }
    if let Some(origin) = headers.get(http::header::ORIGIN) {
        let origin = origin.to_str().unwrap_or("(unreadable)");
        let own = host.map(|h| normalize(scheme, &format!("{}://{h}", scheme.as_str())));
        return match own {
            Some(own) if own == normalize(scheme, origin) => Ok(()),
            _ => Err(Foreign(origin.to_string())),
        };
    }
    match headers.get("sec-fetch-site").and_then(|v| v.to_str().ok()) {
        Some(site @ ("cross-site" | "same-site")) => Err(Foreign(format!("a {site} page"))),
        _ => Ok(()),
    }
}

/// An origin in the form the comparison needs: lowercase, without the scheme's default port.
fn normalize(scheme: Scheme, origin: &str) -> String {
    let origin = origin.trim().to_ascii_lowercase();
    let prefix = format!("{}://", scheme.as_str());
    let default_port = format!(":{}", scheme.default_port());
    match origin.strip_prefix(&prefix).and_then(|authority| authority.strip_suffix(&default_port)) {
        Some(host) => format!("{prefix}{host}"),
        None => origin,
    }
}

/// The axum middleware, with the scheme the server serves.
pub async fn refuse_foreign_origins(State(scheme): State<Scheme>, req: Request, next: Next) -> Response {
    let host = req
        .headers()
        .get(http::header::HOST)
        .and_then(|v| v.to_str().ok())
        .or_else(|| req.uri().authority().map(|a| a.as_str()));
    let Err(Foreign(origin)) = check(scheme, req.method(), host, req.headers()) else {
        return next.run(req).await;
    };
    tracing::warn!(origin = %origin, method = %req.method(), path = %req.uri().path(), "cross-origin request refused");
    let error = ApiError::new(
        ErrorCode::PermissionDenied,
        format!("requests from {origin} may not change jobs: use the dashboard at this server's own address"),
    );
    if req.uri().path().starts_with("/tessera.v1.") {
        error.to_status().into_http::<axum::body::Body>().into_response()
    } else {
        error.into_response()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::routing::post;
    use tower::ServiceExt;

    fn headers(pairs: &[(&'static str, &str)]) -> HeaderMap {
        pairs.iter().map(|(k, v)| (http::HeaderName::from_static(k), v.parse().unwrap())).collect()
    }

    #[test]
    fn check_passes_safe_methods_and_clients_without_browser_headers() {
        let evil = headers(&[("origin", "https://evil.example")]);
        assert_eq!(check(Scheme::Http, &Method::GET, Some("127.0.0.1:7878"), &evil), Ok(()));
        assert_eq!(check(Scheme::Http, &Method::POST, Some("127.0.0.1:7878"), &HeaderMap::new()), Ok(()));
        let own = headers(&[("sec-fetch-site", "same-origin")]);
        assert_eq!(check(Scheme::Http, &Method::DELETE, Some("127.0.0.1:7878"), &own), Ok(()));
        let typed = headers(&[("sec-fetch-site", "none")]);
        assert_eq!(check(Scheme::Http, &Method::POST, None, &typed), Ok(()));
    }

    #[test]
    fn check_compares_origin_with_scheme_and_host() {
        let origin = |o: &str| headers(&[("origin", o)]);
        let host = Some("farm.example:7878");
        let ok = |scheme, o: &str| check(scheme, &Method::POST, host, &origin(o)).is_ok();
        assert!(ok(Scheme::Https, "https://farm.example:7878"));
        assert!(ok(Scheme::Https, "HTTPS://Farm.Example:7878"));
        assert!(!ok(Scheme::Http, "https://farm.example:7878"), "another scheme is another origin");
        assert!(!ok(Scheme::Https, "https://farm.example:7879"));
        assert!(!ok(Scheme::Https, "https://farm.example"));
        assert!(!ok(Scheme::Https, "https://evil.example:7878"));
        assert!(!ok(Scheme::Https, "null"), "sandboxed pages and files");
        // default ports: browsers leave them out, a Host header may not
        assert!(check(Scheme::Https, &Method::PUT, Some("farm.example:443"), &origin("https://farm.example")).is_ok());
        assert!(check(Scheme::Http, &Method::PATCH, Some("farm.example"), &origin("http://farm.example:80")).is_ok());
        // an Origin with no Host to compare with cannot be vouched for
        let e = check(Scheme::Http, &Method::POST, None, &origin("http://127.0.0.1:7878")).unwrap_err();
        assert_eq!(e, Foreign("http://127.0.0.1:7878".into()));
    }

    #[test]
    fn check_refuses_cross_site_fetches_without_origin() {
        for site in ["cross-site", "same-site"] {
            let h = headers(&[("sec-fetch-site", site)]);
            assert_eq!(check(Scheme::Http, &Method::POST, Some("h"), &h), Err(Foreign(format!("a {site} page"))));
        }
    }

    async fn call(app: axum::Router, path: &str, pairs: &[(&'static str, &str)]) -> (u16, serde_json::Value) {
        let mut req = Request::builder().method(Method::POST).uri(path).header("host", "127.0.0.1:7878");
        for (k, v) in pairs {
            req = req.header(*k, *v);
        }
        let res = app.oneshot(req.body(axum::body::Body::empty()).unwrap()).await.unwrap();
        let status = res.status().as_u16();
        let grpc = res.headers().get("grpc-status").map(|v| v.to_str().unwrap().to_string());
        let body = axum::body::to_bytes(res.into_body(), 1 << 20).await.unwrap();
        let json = serde_json::from_slice(&body).unwrap_or_else(|_| serde_json::json!({ "grpc-status": grpc }));
        (status, json)
    }

    #[tokio::test]
    async fn middleware_answers_403_naming_the_origin() {
        let app = axum::Router::new()
            .route("/api/v1/jobs", post(|| async { "submitted" }))
            .route("/tessera.v1.JobService/CancelJob", post(|| async { "cancelled" }))
            .layer(axum::middleware::from_fn_with_state(Scheme::Http, refuse_foreign_origins));
        let (status, body) = call(app.clone(), "/api/v1/jobs", &[("origin", "https://evil.example")]).await;
        assert_eq!(status, 403);
        assert_eq!(body["code"], "permission_denied");
        assert!(body["error"].as_str().unwrap().contains("https://evil.example"), "{body}");
        let (status, _) = call(app.clone(), "/api/v1/jobs", &[("origin", "http://127.0.0.1:7878")]).await;
        assert_eq!(status, 200, "the dashboard's own origin");
        let (status, _) = call(app.clone(), "/api/v1/jobs", &[]).await;
        assert_eq!(status, 200, "no browser headers: the CLI, curl");
        let (status, body) = call(app, "/tessera.v1.JobService/CancelJob", &[("sec-fetch-site", "cross-site")]).await;
        assert_eq!((status, body["grpc-status"].as_str()), (200, Some("7")), "gRPC PERMISSION_DENIED: {body}");
    }
}
