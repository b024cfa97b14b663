//! How a client (the `tessera` command, a worker) reaches a coordinator: a [`Target`] for an
//! `http://` or `https://` URL. Over `https://` the coordinator's certificate must chain to one
//! of the system's trusted roots or to a certificate of the PEM file given as the CA
//! (`--ca-cert`, for a farm's own or a self-signed certificate), or be one of that file's
//! certificates exactly ([`crate::pinned`]).
//!
//! ```no_run
//! # async fn f() -> Result<(), Box<dyn std::error::Error>> {
//! let ca = std::path::Path::new("farm-ca.pem");
//! let channel = tessera_link::connect::endpoint("https://farm:7878", Some(ca))?.connect().await?;
//! # Ok(()) }
//! ```

use rustls::RootCertStore;
use rustls_pki_types::pem::PemObject;
use rustls_pki_types::{CertificateDer, ServerName};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use tonic::transport::{Channel, Endpoint};

/// Why no endpoint could be made.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConnectError {
    /// The URL does not parse.
    #[error("invalid coordinator URL {url}: {reason}")]
    Url {
        /// The URL.
        url: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The CA file is missing, unreadable or not PEM.
    #[error("cannot read CA certificate {}", path.display())]
    ReadCa {
        /// The file.
        path: PathBuf,
        /// The reading or parsing failure.
        source: rustls_pki_types::pem::Error,
    },
    /// The CA file holds no `CERTIFICATE` section.
    #[error("CA certificate file {} holds no PEM certificate", path.display())]
    NoCertificate {
        /// The file.
        path: PathBuf,
    },
    /// A certificate of the CA file is no usable trust anchor.
    #[error("CA certificate file {}: certificate {index} is not usable: {reason}", path.display())]
    BadCertificate {
        /// The file.
        path: PathBuf,
        /// Its position in the file, from 1.
        index: usize,
        /// Why.
        reason: String,
    },
    /// A CA file was given for a plain-text URL, where it would silently do nothing.
    #[error("a CA certificate ({}) needs an https:// coordinator URL, not {url}", path.display())]
    CaWithoutTls {
        /// The file.
        path: PathBuf,
        /// The URL.
        url: String,
    },
    /// Neither the system nor the caller has a trusted root.
    #[error("no trusted root certificates for {url}: the system has none, give the coordinator's CA (--ca-cert)")]
    NoRoots {
        /// The URL.
        url: String,
    },
    /// The TLS settings could not be made.
    #[error("cannot set up TLS for {url}: {reason}")]
    Tls {
        /// The URL.
        url: String,
        /// Why.
        reason: String,
    },
}

/// Where a coordinator is and how to reach it; [`Target::connect`] connects.
#[derive(Clone, Debug)]
pub struct Target {
    endpoint: Endpoint,
    /// For `https://`: the TLS settings the connector uses.
    tls: Option<Arc<rustls::ClientConfig>>,
    connect_timeout: Duration,
}

impl Target {
    /// The longest a connection (TCP and TLS handshake) may take (10 s unless set).
    pub fn connect_timeout(mut self, timeout: Duration) -> Self {
        self.endpoint = self.endpoint.connect_timeout(timeout);
        self.connect_timeout = timeout;
        self
    }

    /// A channel to the coordinator, with `TCP_NODELAY` (small gRPC messages go out at once).
    pub async fn connect(&self) -> Result<Channel, tonic::transport::Error> {
        let endpoint = self.endpoint.clone().tcp_nodelay(true);
        let Some(config) = self.tls.clone() else { return endpoint.connect().await };
        let timeout = self.connect_timeout;
        let connector = tower::service_fn(move |uri: http::Uri| tls_connect(uri, config.clone(), timeout));
        endpoint.connect_with_connector(connector).await
    }
}

/// TCP to `uri`'s host and port, then the TLS handshake with its host name.
async fn tls_connect(
    uri: http::Uri,
    config: Arc<rustls::ClientConfig>,
    timeout: Duration,
) -> std::io::Result<hyper_util::rt::TokioIo<tokio_rustls::client::TlsStream<tokio::net::TcpStream>>> {
    use std::io::{Error, ErrorKind};
    let host = uri.host().ok_or_else(|| Error::new(ErrorKind::InvalidInput, "the URL has no host"))?;
    let host = host.trim_start_matches('[').trim_end_matches(']').to_string();
    let port = uri.port_u16().unwrap_or(443);
    let connecting = tokio::net::TcpStream::connect((host.as_str(), port));
    let tcp = tokio::time::timeout(timeout, connecting)
        .await
        .map_err(|_| Error::new(ErrorKind::TimedOut, format!("no connection to {host}:{port} within {timeout:?}")))??;
    tcp.set_nodelay(true)?;
    let name = ServerName::try_from(host).map_err(|e| Error::new(ErrorKind::InvalidInput, e))?;
    let tls = tokio_rustls::TlsConnector::from(config).connect(name, tcp).await?;
    Ok(hyper_util::rt::TokioIo::new(tls))
}

/// How long a connection may take unless [`Target::connect_timeout`] says otherwise.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

/// The target `url`; over `https://` it trusts the system's roots plus the certificates in the
/// PEM file `ca_cert`. It does not connect yet, so a bad URL or CA file is reported at once
/// while a coordinator that is down can be retried.
pub fn endpoint(url: &str, ca_cert: Option<&Path>) -> Result<Target, ConnectError> {
    let bad_url = |reason: String| ConnectError::Url { url: url.to_string(), reason };
    let endpoint = Endpoint::from_shared(url.to_string()).map_err(|e| bad_url(e.to_string()))?;
    let plain = |endpoint: Endpoint| Target { endpoint, tls: None, connect_timeout: CONNECT_TIMEOUT };
    match endpoint.uri().scheme_str() {
        Some("https") => {}
        Some("http") => {
            return match ca_cert {
                Some(path) => Err(ConnectError::CaWithoutTls { path: path.to_path_buf(), url: url.to_string() }),
                None => Ok(plain(endpoint)),
            };
        }
        _ => return Err(bad_url("the scheme must be http:// or https://".into())),
    }
    let mut roots = RootCertStore::empty();
    // a system without a CA bundle is fine when the caller names the CA
    roots.add_parsable_certificates(rustls_native_certs::load_native_certs().certs);
    let pinned = match ca_cert {
        Some(path) => read_certificates(path)?,
        None => Vec::new(),
    };
    for (i, cert) in pinned.iter().enumerate() {
        let bad = |reason: String| ConnectError::BadCertificate {
            path: ca_cert.unwrap_or(Path::new("")).to_path_buf(),
            index: i + 1,
            reason,
        };
        roots.add(cert.clone()).map_err(|e| bad(e.to_string()))?;
    }
    if roots.is_empty() {
        return Err(ConnectError::NoRoots { url: url.to_string() });
    }
    let tls_error = |reason: String| ConnectError::Tls { url: url.to_string(), reason };
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let verifier =
        crate::pinned::PinnedOrChained::new(roots, pinned, provider.clone()).map_err(|e| tls_error(e.to_string()))?;
    let mut config = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| tls_error(e.to_string()))?
        .dangerous()
        .with_custom_certificate_verifier(Arc::new(verifier))
        .with_no_client_auth();
    config.alpn_protocols = vec![b"h2".to_vec()];
    // tonic would refuse an https:// URI without its own TLS: the connector does the TLS, the
    // requests still name the https:// origin
    let origin = endpoint.uri().clone();
    let mut parts = origin.clone().into_parts();
    parts.scheme = Some(http::uri::Scheme::HTTP);
    let connect_uri = http::Uri::from_parts(parts).map_err(|e| bad_url(e.to_string()))?;
    let endpoint = Endpoint::from(connect_uri).origin(origin);
    Ok(Target { endpoint, tls: Some(Arc::new(config)), connect_timeout: CONNECT_TIMEOUT })
}

/// Whether the server at the `http://` URL `url` speaks TLS: a connection that failed there
/// may be one to an `https://` coordinator (a TLS handshake with it completes within `timeout`;
/// nothing else is sent).
pub async fn speaks_tls(url: &str, timeout: Duration) -> bool {
    let Ok(uri) = url.parse::<http::Uri>() else { return false };
    if uri.scheme_str() != Some("http") {
        return false;
    }
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let any = crate::pinned::AnyCertificate(provider.signature_verification_algorithms);
    let Ok(builder) = rustls::ClientConfig::builder_with_provider(provider).with_safe_default_protocol_versions()
    else {
        return false;
    };
    let config = builder.dangerous().with_custom_certificate_verifier(Arc::new(any)).with_no_client_auth();
    let port = uri.port_u16().unwrap_or(80);
    let Some(host) = uri.host() else { return false };
    let probe = format!("http://{host}:{port}").parse::<http::Uri>();
    let Ok(probe) = probe else { return false };
    tokio::time::timeout(timeout, tls_connect(probe, Arc::new(config), timeout)).await.is_ok_and(|r| r.is_ok())
}

/// What to tell a user whose `http://` URL reached a server that speaks TLS.
pub fn use_https(url: &str) -> String {
    let https = url.replacen("http://", "https://", 1);
    format!("the server at {url} speaks TLS: use {https} (with --ca-cert if its certificate is your own)")
}

/// Every certificate of a PEM file (at least one).
fn read_certificates(path: &Path) -> Result<Vec<CertificateDer<'static>>, ConnectError> {
    let read_error = |source| ConnectError::ReadCa { path: path.to_path_buf(), source };
    let certs =
        CertificateDer::pem_file_iter(path).map_err(read_error)?.collect::<Result<Vec<_>, _>>().map_err(read_error)?;
    if certs.is_empty() {
        return Err(ConnectError::NoCertificate { path: path.to_path_buf() });
    }
    Ok(certs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoint_accepts_plain_urls_and_refuses_a_ca_for_them() {
        assert!(endpoint("http://127.0.0.1:7878", None).is_ok());
        let e = endpoint("http://127.0.0.1:7878", Some(Path::new("ca.pem"))).unwrap_err();
        assert!(matches!(e, ConnectError::CaWithoutTls { .. }), "{e}");
        assert!(matches!(endpoint("ftp://host:1", None), Err(ConnectError::Url { .. })));
        assert!(matches!(endpoint("not a url", None), Err(ConnectError::Url { .. })));
    }

    #[test]
    fn endpoint_names_a_missing_or_invalid_ca_file() {
        let dir = std::env::temp_dir().join(format!("tessera-connect-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let missing = dir.join("missing.pem");
        let e = endpoint("https://127.0.0.1:7878", Some(&missing)).unwrap_err().to_string();
        assert!(e.contains("missing.pem") && e.starts_with("cannot read CA certificate"), "{e}");
        let empty = dir.join("empty.pem");
        std::fs::write(&empty, "not a certificate\n").unwrap();
        let e = endpoint("https://127.0.0.1:7878", Some(&empty)).unwrap_err().to_string();
        assert!(e.contains("empty.pem") && e.contains("no PEM certificate"), "{e}");
        let truncated = dir.join("truncated.pem");
        std::fs::write(&truncated, "-----BEGIN CERTIFICATE-----\nMIIB\n").unwrap();
        let e = endpoint("https://127.0.0.1:7878", Some(&truncated)).unwrap_err().to_string();
        assert!(e.contains("truncated.pem"), "{e}");
        let garbage = dir.join("garbage.pem");
        std::fs::write(&garbage, "-----BEGIN CERTIFICATE-----\nAAAA\n-----END CERTIFICATE-----\n").unwrap();
        let e = endpoint("https://127.0.0.1:7878", Some(&garbage)).unwrap_err().to_string();
        assert!(e.contains("garbage.pem") && e.contains("certificate 1"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn endpoint_trusts_the_certificates_of_a_ca_file() {
        let cert = rcgen::generate_simple_self_signed(vec!["localhost".to_string()]).unwrap();
        let path = std::env::temp_dir().join(format!("tessera-connect-ca-{}.pem", std::process::id()));
        std::fs::write(&path, cert.cert.pem()).unwrap();
        let endpoint = endpoint("https://localhost:7878", Some(&path));
        std::fs::remove_file(&path).unwrap();
        assert!(endpoint.is_ok(), "{:?}", endpoint.err());
    }
}
