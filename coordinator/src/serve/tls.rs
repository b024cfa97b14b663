//! TLS for `tessera serve --tls-cert PEM --tls-key PEM`: the rustls server configuration (ring
//! provider; ALPN offers `h2` for gRPC and `http/1.1` for browsers and REST clients) and
//! [`TlsListener`], an axum listener that hands `axum::serve` finished TLS streams. gRPC, REST
//! and the dashboard keep sharing one port, and graceful shutdown works as without TLS.
//!
//! Handshakes cannot be held hostage: each has [`HANDSHAKE_TIMEOUT`], and at most
//! [`MAX_PENDING_HANDSHAKES`] run at once; a connection arriving when all are taken is still
//! accepted, and a pending handshake is dropped for it: the oldest of those still waiting for
//! their ClientHello, or the oldest of all if every one has sent it. Refusing instead (leaving
//! the newcomer in the kernel's backlog) let a few hundred sockets that never send a
//! ClientHello stop every client, `/healthz` included, for the length of the timeout, again
//! and again; dropping the oldest regardless let a fast enough flood of them drop real
//! clients mid-handshake. A real client sends its ClientHello as it connects, so a silent
//! flood only replaces itself. Under the coordinator, the listener beneath
//! (`conn::LimitedListener`) also counts handshaking sockets against the connection limits.
//!
//! ```no_run
//! # async fn f(router: axum::Router) -> Result<(), Box<dyn std::error::Error>> {
//! use tessera_coordinator::serve::tls::{TlsListener, server_config};
//! let config = server_config("cert.pem".as_ref(), "key.pem".as_ref())?;
//! let tcp = tokio::net::TcpListener::bind("127.0.0.1:7878").await?;
//! axum::serve(TlsListener::new(tcp, config), router).await?;
//! # Ok(()) }
//! ```

use axum::serve::Listener;
use rustls::ServerConfig;
use rustls_pki_types::pem::PemObject;
use rustls_pki_types::{CertificateDer, PrivateKeyDer};
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use tokio::task::{AbortHandle, JoinSet};
use tokio_rustls::LazyConfigAcceptor;
use tokio_rustls::server::TlsStream;

/// A client that has not finished its handshake by then is dropped.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);
/// Handshakes in progress at once; beyond this one is dropped for the newcomer (a silent one
/// first), so that clients that never finish cannot hold unbounded memory nor keep others out.
pub const MAX_PENDING_HANDSHAKES: usize = 256;

/// Why the certificate or key cannot be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TlsError {
    /// The file is missing, unreadable or not PEM.
    #[error("cannot read {what} {}", path.display())]
    Read {
        /// `certificate` or `private key`.
        what: &'static str,
        /// The file.
        path: PathBuf,
        /// The reading or parsing failure.
        source: rustls_pki_types::pem::Error,
    },
    /// The certificate file holds no `CERTIFICATE` section.
    #[error("certificate file {} holds no PEM certificate", path.display())]
    NoCertificate {
        /// The file.
        path: PathBuf,
    },
    /// The key file holds no PKCS#8, PKCS#1 or SEC1 private key.
    #[error("key file {} holds no PEM private key", path.display())]
    NoKey {
        /// The file.
        path: PathBuf,
    },
    /// rustls refused the pair (a key that does not match the certificate, an unsupported
    /// algorithm, an invalid certificate).
    #[error("cannot use certificate {} with key {}", cert.display(), key.display())]
    Config {
        /// The certificate file.
        cert: PathBuf,
        /// The key file.
        key: PathBuf,
        /// rustls' reason.
        source: rustls::Error,
    },
}

/// The server configuration for the certificate chain in `cert` (the server's certificate
/// first) and the private key in `key`, both PEM.
pub fn server_config(cert: &Path, key: &Path) -> Result<Arc<ServerConfig>, TlsError> {
    let read_cert = |source| TlsError::Read { what: "certificate", path: cert.to_path_buf(), source };
    let chain =
        CertificateDer::pem_file_iter(cert).map_err(read_cert)?.collect::<Result<Vec<_>, _>>().map_err(read_cert)?;
    if chain.is_empty() {
        return Err(TlsError::NoCertificate { path: cert.to_path_buf() });
    }
    let private_key = PrivateKeyDer::from_pem_file(key).map_err(|e| match e {
        rustls_pki_types::pem::Error::NoItemsFound => TlsError::NoKey { path: key.to_path_buf() },
        source => TlsError::Read { what: "private key", path: key.to_path_buf(), source },
    })?;
    let config_error = |source| TlsError::Config { cert: cert.to_path_buf(), key: key.to_path_buf(), source };
    let mut config = ServerConfig::builder_with_provider(Arc::new(rustls::crypto::ring::default_provider()))
        .with_safe_default_protocol_versions()
        .map_err(config_error)?
        .with_no_client_auth()
        .with_single_cert(chain, private_key)
        .map_err(config_error)?;
    // tonic's client insists on h2 by ALPN; browsers and REST clients may speak either
    config.alpn_protocols = vec![b"h2".to_vec(), b"http/1.1".to_vec()];
    Ok(Arc::new(config))
}

/// A finished handshake: the TLS stream and the peer's address, or `None` if it failed.
type Handshake<L> = Option<(TlsStream<<L as Listener>::Io>, <L as Listener>::Addr)>;

/// Accepts connections from `L` and returns them once their TLS handshake is done. Handshakes
/// run concurrently, so one slow client does not hold up the others.
pub struct TlsListener<L: Listener> {
    inner: L,
    config: Arc<ServerConfig>,
    handshakes: JoinSet<Handshake<L>>,
    /// The handshakes in `handshakes`, oldest first.
    pending: VecDeque<Pending>,
}

/// A handshake in progress.
struct Pending {
    task: AbortHandle,
    /// Whether the client's ClientHello has arrived.
    hello: Arc<AtomicBool>,
}

impl<L: Listener> TlsListener<L> {
    /// Wraps `inner`, serving with `config`.
    pub fn new(inner: L, config: Arc<ServerConfig>) -> Self {
        TlsListener { inner, config, handshakes: JoinSet::new(), pending: VecDeque::new() }
    }
}

impl<L> TlsListener<L>
where
    L: Listener,
    L::Addr: std::fmt::Debug + 'static,
{
    /// Starts the handshake of a new connection, dropping a pending one if all slots are taken:
    /// the oldest still waiting for its ClientHello, else the oldest.
    fn start(&mut self, io: L::Io, addr: L::Addr) {
        if self.pending.len() >= MAX_PENDING_HANDSHAKES {
            let silent = self.pending.iter().position(|p| !p.hello.load(Ordering::Relaxed));
            if let Some(victim) = self.pending.remove(silent.unwrap_or(0)) {
                tracing::debug!(silent = silent.is_some(), "tls handshake slots full: dropping a pending handshake");
                victim.task.abort();
            }
        }
        let config = self.config.clone();
        let hello = Arc::new(AtomicBool::new(false));
        let said = hello.clone();
        let handshake = async move {
            let start = LazyConfigAcceptor::new(rustls::server::Acceptor::default(), io).await?;
            said.store(true, Ordering::Relaxed);
            start.into_stream(config).await
        };
        let task = self.handshakes.spawn(async move {
            match tokio::time::timeout(HANDSHAKE_TIMEOUT, handshake).await {
                Ok(Ok(stream)) => Some((stream, addr)),
                Ok(Err(e)) => {
                    tracing::debug!(error = %e, peer = ?addr, "tls handshake failed");
                    None
                }
                Err(_) => {
                    tracing::debug!(peer = ?addr, "tls handshake timed out");
                    None
                }
            }
        });
        self.pending.push_back(Pending { task, hello });
    }
}

impl<L> Listener for TlsListener<L>
where
    L: Listener,
    L::Addr: std::fmt::Debug + 'static,
{
    type Io = TlsStream<L::Io>;
    type Addr = L::Addr;

    // cancel-safe, as axum requires: a connection is either still in `inner`, in the join set
    // or returned
    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        loop {
            tokio::select! {
                (io, addr) = self.inner.accept() => self.start(io, addr),
                Some(done) = self.handshakes.join_next_with_id() => {
                    let id = match &done {
                        Ok((id, _)) => *id,
                        Err(e) => e.id(),
                    };
                    self.pending.retain(|p| p.task.id() != id);
                    if let Ok((_, Some(connection))) = done {
                        return connection;
                    }
                }
            }
        }
    }

    fn local_addr(&self) -> std::io::Result<Self::Addr> {
        self.inner.local_addr()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair(dir: &Path) -> (PathBuf, PathBuf) {
        let made = rcgen::generate_simple_self_signed(vec!["localhost".to_string()]).unwrap();
        let (cert, key) = (dir.join("cert.pem"), dir.join("key.pem"));
        std::fs::write(&cert, made.cert.pem()).unwrap();
        std::fs::write(&key, made.signing_key.serialize_pem()).unwrap();
        (cert, key)
    }

    #[test]
    fn server_config_loads_a_pair_and_offers_h2() {
        let dir = tempfile::tempdir().unwrap();
        let (cert, key) = pair(dir.path());
        let config = server_config(&cert, &key).unwrap();
        assert_eq!(config.alpn_protocols, [b"h2".to_vec(), b"http/1.1".to_vec()]);
    }

    /// A TLS client configuration trusting the certificate in `cert`, offering `alpn`.
    fn client_config(cert: &Path, alpn: &[&[u8]]) -> Arc<rustls::ClientConfig> {
        let mut roots = rustls::RootCertStore::empty();
        roots.add(CertificateDer::from_pem_file(cert).unwrap()).unwrap();
        let provider = Arc::new(rustls::crypto::ring::default_provider());
        let mut config = rustls::ClientConfig::builder_with_provider(provider)
            .with_safe_default_protocol_versions()
            .unwrap()
            .with_root_certificates(roots)
            .with_no_client_auth();
        config.alpn_protocols = alpn.iter().map(|p| p.to_vec()).collect();
        Arc::new(config)
    }

    /// A TLS client trusting the certificate in `cert`, offering `alpn`.
    async fn connect(
        addr: std::net::SocketAddr,
        cert: &Path,
        alpn: &[&[u8]],
    ) -> tokio_rustls::client::TlsStream<tokio::net::TcpStream> {
        let tcp = tokio::net::TcpStream::connect(addr).await.unwrap();
        let name = rustls_pki_types::ServerName::try_from("localhost").unwrap();
        tokio_rustls::TlsConnector::from(client_config(cert, alpn)).connect(name, tcp).await.unwrap()
    }

    /// A server answering "over tls" on `/` through a [`TlsListener`] with a new certificate;
    /// its address, the certificate and the task serving.
    async fn serve(dir: &Path) -> (std::net::SocketAddr, PathBuf, tokio::task::JoinHandle<std::io::Result<()>>) {
        let (cert, key) = pair(dir);
        let tcp = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = tcp.local_addr().unwrap();
        let app = axum::Router::new().route("/", axum::routing::get(|| async { "over tls" }));
        let server =
            tokio::spawn(axum::serve(TlsListener::new(tcp, server_config(&cert, &key).unwrap()), app).into_future());
        (addr, cert, server)
    }

    #[tokio::test]
    async fn tls_listener_serves_h2_and_http1_past_more_stalled_handshakes_than_slots() {
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        let dir = tempfile::tempdir().unwrap();
        let (addr, cert, server) = serve(dir.path()).await;
        // clients that connect and never say hello, more than there are handshake slots, must
        // not hold up the others (refusing to accept while the slots were full did, for the
        // length of the timeout)
        let mut stalled = Vec::new();
        for _ in 0..MAX_PENDING_HANDSHAKES + 16 {
            stalled.push(tokio::net::TcpStream::connect(addr).await.unwrap());
        }
        let h2 = tokio::time::timeout(HANDSHAKE_TIMEOUT / 2, connect(addr, &cert, &[b"h2", b"http/1.1"]))
            .await
            .expect("the stalled handshakes held up the next one");
        assert_eq!(h2.get_ref().1.alpn_protocol(), Some(&b"h2"[..]), "gRPC clients need h2");
        let mut http1 = connect(addr, &cert, &[b"http/1.1"]).await;
        http1.write_all(b"GET / HTTP/1.1\r\nhost: localhost\r\nconnection: close\r\n\r\n").await.unwrap();
        let mut answer = String::new();
        http1.read_to_string(&mut answer).await.unwrap();
        assert!(answer.starts_with("HTTP/1.1 200") && answer.ends_with("over tls"), "{answer}");
        server.abort();
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_client_that_said_hello_outlasts_a_flood_of_silent_sockets() {
        let dir = tempfile::tempdir().unwrap();
        let (addr, cert, server) = serve(dir.path()).await;
        // a client slow to finish: its ClientHello is answered, then more silent sockets than
        // slots arrive before its next flight (dropping the oldest pending dropped it)
        let finished = tokio::task::spawn_blocking(move || {
            let name = rustls_pki_types::ServerName::try_from("localhost").unwrap();
            let mut client = rustls::ClientConnection::new(client_config(&cert, &[]), name).unwrap();
            let mut socket = std::net::TcpStream::connect(addr).unwrap();
            socket.set_read_timeout(Some(HANDSHAKE_TIMEOUT / 2)).unwrap();
            client.write_tls(&mut socket).unwrap();
            assert!(client.read_tls(&mut socket).unwrap() > 0, "the server answered the hello");
            let stalled: Vec<_> =
                (0..MAX_PENDING_HANDSHAKES + 16).map(|_| std::net::TcpStream::connect(addr).unwrap()).collect();
            // 273 handshakes for 256 slots: 17 dropped, all of them silent ones
            let closed = |s: &std::net::TcpStream| {
                s.set_nonblocking(true).unwrap();
                !matches!(s.peek(&mut [0u8; 1]), Err(e) if e.kind() == std::io::ErrorKind::WouldBlock)
            };
            let start = std::time::Instant::now();
            while stalled.iter().filter(|s| closed(s)).count() < 17 {
                assert!(start.elapsed() < HANDSHAKE_TIMEOUT / 2, "fewer than 17 silent handshakes were dropped");
                std::thread::sleep(Duration::from_millis(10));
            }
            let mut tls = rustls::Stream::new(&mut client, &mut socket);
            let request = b"GET / HTTP/1.1\r\nhost: localhost\r\nconnection: close\r\n\r\n";
            std::io::Write::write_all(&mut tls, request).expect("the handshake was dropped");
            let mut answer = String::new();
            let _ = std::io::Read::read_to_string(&mut tls, &mut answer);
            assert!(answer.starts_with("HTTP/1.1 200") && answer.ends_with("over tls"), "{answer:?}");
            drop(stalled);
        });
        finished.await.unwrap();
        server.abort();
    }

    #[test]
    fn server_config_names_the_file_at_fault() {
        let dir = tempfile::tempdir().unwrap();
        let (cert, key) = pair(dir.path());
        let missing = dir.path().join("missing.pem");
        let e = server_config(&missing, &key).unwrap_err().to_string();
        assert!(e.starts_with("cannot read certificate") && e.contains("missing.pem"), "{e}");
        let e = server_config(&cert, &missing).unwrap_err().to_string();
        assert!(e.starts_with("cannot read private key") && e.contains("missing.pem"), "{e}");
        // swapped: the key file holds no certificate, the certificate file no key
        let e = server_config(&key, &key).unwrap_err().to_string();
        assert!(e.contains("holds no PEM certificate") && e.contains("key.pem"), "{e}");
        let e = server_config(&cert, &cert).unwrap_err().to_string();
        assert!(e.contains("holds no PEM private key") && e.contains("cert.pem"), "{e}");
        // a key that belongs to another certificate
        let other = tempfile::tempdir().unwrap();
        let (_, other_key) = pair(other.path());
        let e = server_config(&cert, &other_key).unwrap_err().to_string();
        assert!(e.starts_with("cannot use certificate") && e.contains("cert.pem"), "{e}");
    }
}
