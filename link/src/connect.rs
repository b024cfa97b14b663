//! How a client (the `tessera` command, a worker) reaches a coordinator: a tonic [`Endpoint`]
//! for an `http://` or `https://` URL. Over `https://` the coordinator's certificate must chain
//! to one of the system's trusted roots or to a certificate of the PEM file given as the CA
//! (`--ca-cert`, for a farm's own or a self-signed certificate).
//!
//! ```no_run
//! # async fn f() -> Result<(), Box<dyn std::error::Error>> {
//! let ca = std::path::Path::new("farm-ca.pem");
//! let channel = tessera_link::connect::endpoint("https://farm:7878", Some(ca))?.connect().await?;
//! # Ok(()) }
//! ```

use rustls::RootCertStore;
use rustls_pki_types::CertificateDer;
use rustls_pki_types::pem::PemObject;
use std::path::{Path, PathBuf};
use tonic::transport::{ClientTlsConfig, Endpoint};

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
    /// tonic refused the TLS settings.
    #[error("cannot set up TLS for {url}")]
    Tls {
        /// The URL.
        url: String,
        /// tonic's error.
        source: tonic::transport::Error,
    },
}

/// An endpoint for `url`; over `https://` it trusts the system's roots plus the certificates in
/// the PEM file `ca_cert`. It does not connect yet, so a bad URL or CA file is reported at once
/// while a coordinator that is down can be retried.
pub fn endpoint(url: &str, ca_cert: Option<&Path>) -> Result<Endpoint, ConnectError> {
    let bad_url = |reason: String| ConnectError::Url { url: url.to_string(), reason };
    let endpoint = Endpoint::from_shared(url.to_string()).map_err(|e| bad_url(e.to_string()))?;
    match endpoint.uri().scheme_str() {
        Some("https") => {}
        Some("http") => {
            return match ca_cert {
                Some(path) => Err(ConnectError::CaWithoutTls { path: path.to_path_buf(), url: url.to_string() }),
                None => Ok(endpoint),
            };
        }
        _ => return Err(bad_url("the scheme must be http:// or https://".into())),
    }
    let mut roots = RootCertStore::empty();
    // a system without a CA bundle is fine when the caller names the CA
    roots.add_parsable_certificates(rustls_native_certs::load_native_certs().certs);
    if let Some(path) = ca_cert {
        for (i, cert) in read_certificates(path)?.into_iter().enumerate() {
            roots.add(cert).map_err(|e| ConnectError::BadCertificate {
                path: path.to_path_buf(),
                index: i + 1,
                reason: e.to_string(),
            })?;
        }
    }
    if roots.is_empty() {
        return Err(ConnectError::NoRoots { url: url.to_string() });
    }
    endpoint
        .tls_config(ClientTlsConfig::new().trust_anchors(roots.roots))
        .map_err(|source| ConnectError::Tls { url: url.to_string(), source })
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
