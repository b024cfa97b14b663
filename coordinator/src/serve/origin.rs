//! The browser guard: what a web page may make the coordinator do. Two attacks are shut out,
//! whether the farm uses tokens or not (without tokens on loopback, any page could otherwise
//! post a multipart form to `/api/v1/jobs`):
//!
//! * **Cross-site request forgery**: a page of another origin sends a request to the farm.
//! * **DNS rebinding**: a page at `http://evil.example:7878/` makes its name resolve to
//!   127.0.0.1 and then talks to the loopback coordinator as if it were its own origin. Its
//!   `Origin` and `Host` headers then agree, so comparing them cannot tell it apart.
//!
//! The rule in force:
//!
//! * **Only browsers are checked.** A request is a browser's when it carries `Origin`, any
//!   `Sec-Fetch-*` header, or a `User-Agent` starting with `Mozilla/`. Browsers add `Origin` to
//!   every request but GET and HEAD and no page can remove it; `Sec-Fetch-*` to every request,
//!   but only to HTTPS and `localhost` URLs, so over plain HTTP a page's GET carries neither and
//!   the user agent, which every browser's starts with and Chromium's and Safari's pages cannot
//!   change, is what is left (checked with a headless Chromium: a rebound plain-HTTP page was
//!   otherwise served). The `tessera` command, workers, curl, Python clients, Prometheus and
//!   probes send none of the three and pass unchecked, whatever host name they use; they
//!   cannot be rebound, since nothing steers them to a name. A non-browser client that calls
//!   itself `Mozilla/` (PowerShell's `Invoke-WebRequest`) must use an allowed name or an IP.
//! * **A browser must reach the server under an allowed host name**, on every method: the
//!   `Host` header (HTTP/2's `:authority`), port and IPv6 brackets removed, compared without
//!   case. Allowed are `localhost` and `*.localhost` (browsers resolve them to loopback
//!   themselves), the names given with `--allowed-host` (repeatable; `TESSERA_ALLOWED_HOSTS`,
//!   comma-separated; `allowed-host` in the `--config` file; `*.example.com` allows its
//!   subdomains, `*` every name, for a coordinator behind a proxy of one's own) and **any IP
//!   literal**, which covers the listen address and the loopback addresses. An IP literal
//!   cannot be rebound: DNS is not asked about it, and a browser sends `Host: 10.0.0.5` only to
//!   the server at 10.0.0.5, for a page loaded from that address. Anything else, such as a
//!   rebound name, gets 403: plain text naming the host and the flag that allows it for a page,
//!   JSON `permission_denied` for the API, gRPC `PERMISSION_DENIED` on gRPC paths.
//! * **A browser's state-changing request** (any method but GET, HEAD, OPTIONS and TRACE) is
//!   refused when `Sec-Fetch-Site` says `cross-site` or `same-site`, whatever `Origin` and `Host`
//!   say, and when its `Origin` is not the server's own origin (the scheme it serves plus the
//!   `Host` it was reached at). The dashboard calls the API from its own origin and passes.
//!   gRPC paths are guarded too, since a form can post to any path.
//!
//! What remains: a Firefox page may replace the user agent of its own plain-HTTP fetches, and
//! a browser too old to send `Sec-Fetch-*` (before Chrome 76, Firefox 90, Safari 16.4) may
//! send no signal on GET, so a rebound page in them could read job lists and images of a farm
//! without tokens; neither can change anything, since `Origin` is checked on every other
//! method.

use crate::serve::error::{ApiError, ErrorCode};
use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use http::{HeaderMap, Method};
use std::net::IpAddr;
use std::sync::Arc;

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

/// The host names browsers may reach the server under, besides IP literals and `localhost`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct AllowedHosts {
    /// `*` was given: every name.
    any: bool,
    /// Exact names, normalised by [`parse_allowed_host`].
    names: Vec<String>,
    /// Suffixes with their leading dot, from `*.example.com` entries.
    suffixes: Vec<String>,
}

impl AllowedHosts {
    /// The defaults plus `entries`, each already normalised by [`parse_allowed_host`] (empty
    /// entries, as an empty `TESSERA_ALLOWED_HOSTS` gives, are ignored).
    pub fn new(entries: &[String]) -> Self {
        let mut hosts = AllowedHosts::default();
        for entry in entries.iter().filter(|e| !e.is_empty()) {
            match entry.strip_prefix('*') {
                Some("") => hosts.any = true,
                Some(suffix) => hosts.suffixes.push(suffix.to_string()),
                None => hosts.names.push(entry.clone()),
            }
        }
        hosts
    }

    /// Whether a browser may reach the server as `host` (bare, as [`host_name`] gives it).
    pub fn allows(&self, host: &str) -> bool {
        self.any
            || host.parse::<IpAddr>().is_ok()
            || host == "localhost"
            || host.ends_with(".localhost")
            || self.names.iter().any(|n| n == host)
            || self.suffixes.iter().any(|s| host.ends_with(s.as_str()))
    }

    /// The names allowed besides the defaults, for the start-up log.
    pub fn extra(&self) -> Vec<String> {
        let any = self.any.then(|| "*".to_string());
        let wildcards = self.suffixes.iter().map(|s| format!("*{s}"));
        any.into_iter().chain(self.names.iter().cloned()).chain(wildcards).collect()
    }
}

/// The clap value parser of `--allowed-host`: a host name (`farm1`, `farm.example.com`), a
/// wildcard (`*.example.com`, `*`), an IP literal (`[::1]` or `::1`) or nothing; lowercase,
/// without a trailing dot. A port or scheme is refused, naming what to write instead.
pub fn parse_allowed_host(text: &str) -> Result<String, String> {
    let name = text.trim().to_ascii_lowercase();
    let name = name.strip_suffix('.').unwrap_or(&name);
    if name.is_empty() || name == "*" {
        return Ok(name.to_string());
    }
    let unbracketed = name.strip_prefix('[').and_then(|n| n.strip_suffix(']')).unwrap_or(name);
    if let Ok(ip) = unbracketed.parse::<IpAddr>() {
        return Ok(ip.to_string());
    }
    // `http://farm1:7878/` or `farm1:7878`: say what to write instead
    let authority = name.split_once("://").map_or(name, |(_, rest)| rest.trim_end_matches('/'));
    if let Some(bare) = host_name(authority).filter(|bare| bare != name) {
        return Err(format!("{text:?} is not a host name: give it without scheme or port, e.g. {bare}"));
    }
    let labels = name.strip_prefix("*.").unwrap_or(name);
    if !labels.split('.').all(is_label) {
        return Err(format!("{text:?} is not a host name (e.g. farm1, farm.example.com or *.example.com)"));
    }
    Ok(name.to_string())
}

/// A DNS label as browsers send it: letters, digits, `-` and `_`, not empty.
fn is_label(label: &str) -> bool {
    !label.is_empty() && label.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

/// The host of an authority such as a `Host` header: lowercase, without port, IPv6 brackets
/// and trailing dot. `None` when it is no authority a browser would send (userinfo, a bare
/// IPv6 address, a bad port, other characters).
pub fn host_name(authority: &str) -> Option<String> {
    let authority = authority.trim();
    let (host, port) = match authority.strip_prefix('[') {
        Some(rest) => {
            let (inside, after) = rest.split_once(']')?;
            inside.parse::<std::net::Ipv6Addr>().ok()?;
            let port = match after {
                "" => None,
                after => Some(after.strip_prefix(':')?),
            };
            (inside, port)
        }
        None => match authority.split_once(':') {
            Some((host, port)) => (host, Some(port)),
            None => (authority, None),
        },
    };
    if port.is_some_and(|p| p.is_empty() || !p.bytes().all(|b| b.is_ascii_digit())) {
        return None;
    }
    let host = host.to_ascii_lowercase();
    let host = host.strip_suffix('.').unwrap_or(&host);
    let ipv6 = authority.starts_with('[');
    (ipv6 || host.split('.').all(is_label)).then(|| host.to_string())
}

/// What the guard needs to know: the server's scheme and the host names it may be reached as.
#[derive(Clone, Debug)]
pub struct Guard {
    /// The scheme the server serves, part of its origin.
    pub scheme: Scheme,
    /// The host names browsers may use.
    pub hosts: AllowedHosts,
}

/// Why a browser's request was refused.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// It reached the server under a host name that is not allowed (or none).
    Host(String),
    /// `Sec-Fetch-Site` said the page is of another site (`cross-site` or `same-site`).
    Site(String),
    /// Its `Origin` is another than the server's own.
    Origin(String),
}

impl Refusal {
    /// What the client is told.
    pub fn message(&self) -> String {
        match self {
            Refusal::Host(host) if host.is_empty() => {
                "a browser's request without a Host header is refused".to_string()
            }
            Refusal::Host(host) => format!(
                "this coordinator does not answer browsers that reach it as {host:?}: a web page could have \
                 pointed that name at it (DNS rebinding). If {host:?} is this coordinator's name, start it with \
                 --allowed-host {host} (or add it to TESSERA_ALLOWED_HOSTS)"
            ),
            Refusal::Site(site) => {
                format!(
                    "requests from a {site} page may not change jobs: use the dashboard at this server's own address"
                )
            }
            Refusal::Origin(origin) => {
                format!("requests from {origin} may not change jobs: use the dashboard at this server's own address")
            }
        }
    }
}

/// Whether a browser sent the request (see the module doc).
fn from_browser(headers: &HeaderMap) -> bool {
    let mozilla = headers.get(http::header::USER_AGENT).is_some_and(|ua| ua.as_bytes().starts_with(b"Mozilla/"));
    mozilla
        || headers.contains_key(http::header::ORIGIN)
        || headers.keys().any(|k| k.as_str().starts_with("sec-fetch-"))
}

/// Whether a request may proceed. `host` is where the client reached the server (the `Host`
/// header, or the `:authority` of HTTP/2).
pub fn check(guard: &Guard, method: &Method, host: Option<&str>, headers: &HeaderMap) -> Result<(), Refusal> {
    if !from_browser(headers) {
        return Ok(());
    }
    match host.map(|h| (h, host_name(h))) {
        Some((_, Some(name))) if guard.hosts.allows(&name) => {}
        Some((_, Some(name))) => return Err(Refusal::Host(name)),
        Some((raw, None)) => return Err(Refusal::Host(raw.chars().take(100).collect())),
        None => return Err(Refusal::Host(String::new())),
    }
    if matches!(*method, Method::GET | Method::HEAD | Method::OPTIONS | Method::TRACE) {
        return Ok(());
    }
    if let Some(site @ ("cross-site" | "same-site")) = headers.get("sec-fetch-site").and_then(|v| v.to_str().ok()) {
        return Err(Refusal::Site(site.to_string()));
    }
    let Some(origin) = headers.get(http::header::ORIGIN) else { return Ok(()) };
    let origin = origin.to_str().unwrap_or("(unreadable)");
    let own = host.map(|h| normalize(guard.scheme, &format!("{}://{h}", guard.scheme.as_str())));
    match own {
        Some(own) if own == normalize(guard.scheme, origin) => Ok(()),
        _ => Err(Refusal::Origin(origin.to_string())),
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

/// The axum middleware.
pub async fn refuse_foreign_browsers(State(guard): State<Arc<Guard>>, req: Request, next: Next) -> Response {
    let host = req
        .headers()
        .get(http::header::HOST)
        .and_then(|v| v.to_str().ok())
        .or_else(|| req.uri().authority().map(|a| a.as_str()));
    let Err(refusal) = check(&guard, req.method(), host, req.headers()) else {
        return next.run(req).await;
    };
    let path = req.uri().path();
    tracing::warn!(refusal = ?refusal, method = %req.method(), path, "browser request refused");
    let message = refusal.message();
    if path.starts_with("/tessera.v1.") {
        return tonic::Status::permission_denied(message).into_http::<axum::body::Body>().into_response();
    }
    // a page opened in the browser: text it shows as it is
    if matches!(path, "/" | "/dashboard") {
        let text = [(http::header::CONTENT_TYPE, "text/plain; charset=utf-8")];
        return (http::StatusCode::FORBIDDEN, text, message).into_response();
    }
    ApiError::new(ErrorCode::PermissionDenied, message).into_response()
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::routing::{get, post};
    use tower::ServiceExt;

    fn headers(pairs: &[(&'static str, &str)]) -> HeaderMap {
        pairs.iter().map(|(k, v)| (http::HeaderName::from_static(k), v.parse().unwrap())).collect()
    }

    fn guard(scheme: Scheme, extra: &[&str]) -> Guard {
        let entries: Vec<String> = extra.iter().map(|e| parse_allowed_host(e).unwrap()).collect();
        Guard { scheme, hosts: AllowedHosts::new(&entries) }
    }

    #[test]
    fn host_name_strips_port_brackets_case_and_trailing_dot() {
        let name = |a: &str| host_name(a);
        assert_eq!(name("Farm.Example:7878").as_deref(), Some("farm.example"));
        assert_eq!(name("localhost.").as_deref(), Some("localhost"));
        assert_eq!(name("127.0.0.1:7878").as_deref(), Some("127.0.0.1"));
        assert_eq!(name("[::1]:7878").as_deref(), Some("::1"));
        assert_eq!(name("[::FFFF:127.0.0.1]").as_deref(), Some("::ffff:127.0.0.1"));
        for bad in ["::1", "[::1", "[::1]x", "[nope]:80", "a:b:c", "h:", "h:x", "user@h", "a b", "", "a..b"] {
            assert_eq!(name(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn defaults_allow_loopback_names_and_ip_literals_only() {
        let hosts = AllowedHosts::new(&[]);
        for ok in ["localhost", "dash.localhost", "127.0.0.1", "127.0.0.2", "::1", "10.0.0.5", "0.0.0.0"] {
            assert!(hosts.allows(ok), "{ok}");
        }
        // rebindable names, including ones that look like loopback
        for refused in ["evil.example", "localhost.evil.example", "127.0.0.1.nip.io", "xlocalhost", "farm1"] {
            assert!(!hosts.allows(refused), "{refused}");
        }
    }

    #[test]
    fn allowed_hosts_add_names_wildcards_and_everything() {
        let entries: Vec<String> = ["Farm1", "*.render.example", ""].map(|e| parse_allowed_host(e).unwrap()).into();
        let hosts = AllowedHosts::new(&entries);
        assert!(hosts.allows("farm1") && hosts.allows("a.render.example") && hosts.allows("a.b.render.example"));
        assert!(!hosts.allows("render.example") && !hosts.allows("evilrender.example") && !hosts.allows("farm2"));
        assert_eq!(hosts.extra(), ["farm1", "*.render.example"]);
        assert!(AllowedHosts::new(&["*".to_string()]).allows("anything.example"));
    }

    #[test]
    fn parse_allowed_host_normalises_and_names_what_to_write() {
        assert_eq!(parse_allowed_host(" Farm.Example. ").as_deref(), Ok("farm.example"));
        assert_eq!(parse_allowed_host("[::1]").as_deref(), Ok("::1"));
        assert_eq!(parse_allowed_host("*").as_deref(), Ok("*"));
        assert_eq!(parse_allowed_host("").as_deref(), Ok(""));
        let e = parse_allowed_host("farm1:7878").unwrap_err();
        assert!(e.contains("without scheme or port, e.g. farm1"), "{e}");
        let e = parse_allowed_host("https://farm1:7878/").unwrap_err();
        assert!(e.contains("e.g. farm1"), "{e}");
        for bad in ["farm 1", "*farm", "a..b", "a/b"] {
            assert!(parse_allowed_host(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn clients_without_browser_headers_pass_under_any_host() {
        let g = guard(Scheme::Http, &[]);
        let none = HeaderMap::new();
        for method in [Method::GET, Method::POST, Method::DELETE] {
            assert_eq!(check(&g, &method, Some("evil.example:7878"), &none), Ok(()));
            assert_eq!(check(&g, &method, None, &none), Ok(()));
        }
    }

    #[test]
    fn browsers_are_refused_under_names_that_are_not_allowed() {
        let g = guard(Scheme::Http, &["farm1"]);
        // a rebound page: Origin and Host agree, on reads as on writes
        let rebound = headers(&[("origin", "http://evil.example:7878"), ("sec-fetch-site", "same-origin")]);
        for method in [Method::GET, Method::POST] {
            let e = check(&g, &method, Some("evil.example:7878"), &rebound).unwrap_err();
            assert_eq!(e, Refusal::Host("evil.example".into()));
        }
        // a navigation sends Sec-Fetch-* but no Origin; over plain HTTP only the user agent
        let navigation = headers(&[("sec-fetch-mode", "navigate"), ("sec-fetch-dest", "document")]);
        assert!(check(&g, &Method::GET, Some("Evil.Example"), &navigation).is_err());
        let plain_http = headers(&[("user-agent", "Mozilla/5.0 (X11; Linux x86_64) HeadlessChrome/156.0")]);
        assert!(check(&g, &Method::GET, Some("evil.example:7878"), &plain_http).is_err());
        let curl = headers(&[("user-agent", "curl/8.5.0")]);
        assert_eq!(check(&g, &Method::GET, Some("evil.example:7878"), &curl), Ok(()));
        assert_eq!(check(&g, &Method::GET, None, &navigation), Err(Refusal::Host(String::new())));
        for ok in ["127.0.0.1:7878", "localhost:7878", "[::1]:7878", "FARM1:7878", "192.168.1.20"] {
            assert_eq!(check(&g, &Method::GET, Some(ok), &navigation), Ok(()), "{ok}");
        }
        let message = Refusal::Host("evil.example".into()).message();
        assert!(message.contains("\"evil.example\"") && message.contains("--allowed-host evil.example"), "{message}");
    }

    #[test]
    fn cross_site_writes_are_refused_whatever_origin_and_host_say() {
        let g = guard(Scheme::Http, &["*"]);
        for site in ["cross-site", "same-site"] {
            let h = headers(&[("sec-fetch-site", site), ("origin", "http://127.0.0.1:7878")]);
            assert_eq!(check(&g, &Method::POST, Some("127.0.0.1:7878"), &h), Err(Refusal::Site(site.into())));
            assert_eq!(check(&g, &Method::GET, Some("127.0.0.1:7878"), &h), Ok(()), "reads are the browser's to guard");
        }
        let own = headers(&[("sec-fetch-site", "same-origin"), ("origin", "http://127.0.0.1:7878")]);
        assert_eq!(check(&g, &Method::DELETE, Some("127.0.0.1:7878"), &own), Ok(()));
        let typed = headers(&[("sec-fetch-site", "none")]);
        assert_eq!(check(&g, &Method::POST, Some("127.0.0.1:7878"), &typed), Ok(()));
    }

    #[test]
    fn check_compares_origin_with_scheme_and_host() {
        let origin = |o: &str| headers(&[("origin", o)]);
        let host = Some("farm.example:7878");
        let g = |scheme| guard(scheme, &["farm.example"]);
        let ok = |scheme, o: &str| check(&g(scheme), &Method::POST, host, &origin(o)).is_ok();
        assert!(ok(Scheme::Https, "https://farm.example:7878"));
        assert!(ok(Scheme::Https, "HTTPS://Farm.Example:7878"));
        assert!(!ok(Scheme::Http, "https://farm.example:7878"), "another scheme is another origin");
        assert!(!ok(Scheme::Https, "https://farm.example:7879"));
        assert!(!ok(Scheme::Https, "https://farm.example"));
        assert!(!ok(Scheme::Https, "https://evil.example:7878"));
        assert!(!ok(Scheme::Https, "null"), "sandboxed pages and files");
        // default ports: browsers leave them out, a Host header may not
        let https = g(Scheme::Https);
        assert!(check(&https, &Method::PUT, Some("farm.example:443"), &origin("https://farm.example")).is_ok());
        let http = g(Scheme::Http);
        assert!(check(&http, &Method::PATCH, Some("farm.example"), &origin("http://farm.example:80")).is_ok());
        let e = check(&http, &Method::POST, Some("127.0.0.1:7878"), &origin("http://evil.example")).unwrap_err();
        assert_eq!(e, Refusal::Origin("http://evil.example".into()));
    }

    async fn call(app: axum::Router, method: Method, path: &str, pairs: &[(&'static str, &str)]) -> (u16, String) {
        let mut req = Request::builder().method(method).uri(path);
        for (k, v) in pairs {
            req = req.header(*k, *v);
        }
        let res = app.oneshot(req.body(axum::body::Body::empty()).unwrap()).await.unwrap();
        let status = res.status().as_u16();
        let grpc = res.headers().get("grpc-status").map(|v| v.to_str().unwrap().to_string());
        let kind = res.headers().get("content-type").map(|v| v.to_str().unwrap().to_string()).unwrap_or_default();
        let body = axum::body::to_bytes(res.into_body(), 1 << 20).await.unwrap();
        let text = String::from_utf8_lossy(&body);
        (status, format!("{kind} grpc-status={} {text}", grpc.unwrap_or_default()))
    }

    #[tokio::test]
    async fn middleware_answers_403_as_text_json_or_grpc() {
        let app = axum::Router::new()
            .route("/", get(|| async { "dashboard" }))
            .route("/api/v1/jobs", post(|| async { "submitted" }))
            .route("/tessera.v1.JobService/CancelJob", post(|| async { "cancelled" }))
            .layer(axum::middleware::from_fn_with_state(Arc::new(guard(Scheme::Http, &[])), refuse_foreign_browsers));
        let rebound = [("host", "evil.example:7878"), ("sec-fetch-dest", "document")];
        let (status, page) = call(app.clone(), Method::GET, "/", &rebound).await;
        assert_eq!(status, 403);
        assert!(page.starts_with("text/plain") && page.contains("--allowed-host evil.example"), "{page}");
        let rebound_post = [("host", "evil.example:7878"), ("origin", "http://evil.example:7878")];
        let (status, body) = call(app.clone(), Method::POST, "/api/v1/jobs", &rebound_post).await;
        assert_eq!(status, 403);
        assert!(body.contains("permission_denied") && body.contains("--allowed-host evil.example"), "{body}");
        let (status, body) = call(app.clone(), Method::POST, "/tessera.v1.JobService/CancelJob", &rebound_post).await;
        assert_eq!(status, 200);
        assert!(body.contains("grpc-status=7"), "gRPC PERMISSION_DENIED: {body}");
        let foreign = [("host", "127.0.0.1:7878"), ("origin", "https://evil.example")];
        let (status, body) = call(app.clone(), Method::POST, "/api/v1/jobs", &foreign).await;
        assert!(status == 403 && body.contains("https://evil.example"), "{body}");
        // the dashboard and its calls, and clients without browser headers under any name
        let (status, _) =
            call(app.clone(), Method::GET, "/", &[("host", "localhost:7878"), ("sec-fetch-dest", "document")]).await;
        assert_eq!(status, 200);
        let own = [("host", "127.0.0.1:7878"), ("origin", "http://127.0.0.1:7878"), ("sec-fetch-site", "same-origin")];
        assert_eq!(call(app.clone(), Method::POST, "/api/v1/jobs", &own).await.0, 200);
        assert_eq!(call(app, Method::POST, "/api/v1/jobs", &[("host", "evil.example")]).await.0, 200);
    }
}
