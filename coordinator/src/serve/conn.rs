//! Bounds on connections, so that sockets nobody uses cannot stop the coordinator: a listener
//! wrapper ([`LimitedListener`]) that counts every accepted TCP connection and closes the least
//! useful one when a limit is reached, the request tracking that tells it which connections
//! are in use ([`track_requests`]), and the start-up step that raises the descriptor limit
//! ([`raise_fd_limit`]).
//!
//! The rule in force:
//!
//! * **Descriptors.** At start the soft `RLIMIT_NOFILE` is raised to the hard limit and logged.
//!   Connections may use that limit minus a reserve of max(64, ⅛ of it) for SQLite, blobs and
//!   uploads, and at most [`DEFAULT_MAX_CONNECTIONS`] (`--max-connections` lowers or raises the
//!   cap, never above the descriptors), so `accept` never fails for want of a descriptor.
//! * **Per peer.** One IPv4 address (or IPv6 /64) may hold a quarter of the connections
//!   (`--max-connections-per-ip`), so one host cannot push out the others.
//! * **Full means evict, not refuse.** A newcomer beyond either limit is accepted and the
//!   least useful connection closed: of the newcomer's peer at the per-peer limit, of the
//!   peers holding the most at the global cap. Least useful is: no request in flight before one
//!   with a request in flight (a long poll, a watch stream, an upload), then one that never
//!   sent a byte before one that has (a TLS handshake under way, a client between requests;
//!   bytes waiting in the socket count, since the task that reads a real client's first bytes
//!   may run late on a loaded machine), then the least recently active (accepted, a request
//!   started or ended, bytes received).
//!   A flood of idle sockets, even from the address real clients use (all of loopback is one
//!   peer), thus only evicts itself: `/healthz` and real clients are served on fresh
//!   connections and kept while they work. A TLS client is not yet in a request during its
//!   handshake; ranked by accept time alone, a flood from its address closed it within a few
//!   dozen arrivals.
//!   Refusing would leave the newcomer in the kernel's backlog behind the flood. Sockets
//!   being closed may outnumber the cap by 17 until their tasks drop them; beyond that the
//!   next accept waits for them (the reserve covers it).
//! * **Idle connections end.** A connection that has not started a request within
//!   [`FIRST_REQUEST_TIMEOUT`] (10 s) of its accept (a TLS handshake included), or has had none
//!   in flight for [`IDLE_TIMEOUT`] (2 min), is closed, checked every second. This plays the part of hyper's HTTP/1 header-read
//!   timeout and of HTTP/2 keep-alive, which `axum::serve` does not expose, the same way for
//!   both protocols and for TLS; a peer dropping out of the network mid-request is found by
//!   TCP keep-alive probes (set in `app.rs`).
//!
//! Closing works from outside the connection's task: the socket wrapper ([`Tracked`]) fails
//! its next read or write and wakes the task, hyper drops the connection, and the descriptor is
//! freed when the wrapper is dropped.

mod sys;

use sys::bytes_waiting;
pub use sys::{FdLimit, raise_fd_limit};

use atomic_waker::AtomicWaker;
use axum::extract::{ConnectInfo, Request};
use axum::middleware::Next;
use axum::response::Response;
use axum::serve::{IncomingStream, Listener};
use std::collections::HashMap;
use std::io;
use std::net::{IpAddr, SocketAddr};
use std::os::fd::AsRawFd;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

/// The most connections by default, whatever the descriptor limit: an idle TLS connection
/// costs tens of KiB, so this bounds them to a few hundred MiB.
pub const DEFAULT_MAX_CONNECTIONS: usize = 8192;
/// A connection must start its first request this soon after its accept.
pub const FIRST_REQUEST_TIMEOUT: Duration = Duration::from_secs(10);
/// A connection without a request in flight for this long is closed.
pub const IDLE_TIMEOUT: Duration = Duration::from_secs(120);
/// How often connections are checked against the timeouts.
const SWEEP_PERIOD: Duration = Duration::from_secs(1);
/// Descriptors kept for anything but connections: at least this many, or an eighth.
const FD_RESERVE_MIN: u64 = 64;
/// Sockets being closed that may still be open when the next connection is accepted (taken
/// from the reserve): a connection whose task does not notice its close at once (an upload
/// whose handler is not reading just then) must not stop the accept loop.
const CLOSING_SLACK: usize = 16;

/// The limits a [`LimitedListener`] enforces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Connections at once.
    pub max_connections: usize,
    /// Connections at once from one peer (IPv4 address or IPv6 /64).
    pub max_per_peer: usize,
    /// See [`FIRST_REQUEST_TIMEOUT`].
    pub first_request_timeout: Duration,
    /// See [`IDLE_TIMEOUT`].
    pub idle_timeout: Duration,
}

impl Limits {
    /// The limits for a process that may open `fds` descriptors, with `--max-connections` and
    /// `--max-connections-per-ip` when given. A cap above what the descriptors allow is
    /// lowered to it (the second value says so).
    pub fn for_fds(fds: u64, max_connections: Option<usize>, max_per_peer: Option<usize>) -> (Limits, bool) {
        let reserve = FD_RESERVE_MIN.max(fds / 8).min(fds / 2);
        let fd_cap = usize::try_from(fds - reserve).unwrap_or(usize::MAX).max(2);
        let lowered = max_connections.is_some_and(|wanted| wanted > fd_cap);
        let max_connections = max_connections.unwrap_or(DEFAULT_MAX_CONNECTIONS).clamp(2, fd_cap);
        let max_per_peer = max_per_peer.unwrap_or(max_connections / 4).clamp(1, max_connections);
        let limits = Limits {
            max_connections,
            max_per_peer,
            first_request_timeout: FIRST_REQUEST_TIMEOUT,
            idle_timeout: IDLE_TIMEOUT,
        };
        (limits, lowered)
    }
}

/// Whom a limit is counted for: an IPv4 address, or the /64 of an IPv6 one (a host usually
/// has a whole /64).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PeerKey(IpAddr);

impl PeerKey {
    /// The key of a peer at `ip` (IPv4-mapped IPv6 addresses count as IPv4).
    pub fn of(ip: IpAddr) -> PeerKey {
        match ip.to_canonical() {
            IpAddr::V6(v6) => PeerKey(IpAddr::V6((u128::from(v6) & !((1u128 << 64) - 1)).into())),
            v4 => PeerKey(v4),
        }
    }
}

/// One accepted connection, shared by its socket wrapper, its requests and the registry.
#[derive(Debug)]
struct Conn {
    id: u64,
    peer: PeerKey,
    epoch: Instant,
    accepted_ms: u64,
    /// Accept, or the last request start or end.
    last_event_ms: AtomicU64,
    in_flight: AtomicU32,
    /// One more than the time of the last read that brought bytes; 0 if none has.
    heard_ms: AtomicU64,
    /// The socket's descriptor (-1 until known), to see bytes that arrived before any read.
    fd: AtomicI32,
    served: AtomicBool,
    /// Set (under the registry's lock) when the connection is to be closed.
    closing: AtomicBool,
    /// The task that last read or wrote the socket, woken to notice `closing`.
    waker: AtomicWaker,
}

impl Conn {
    fn touch(&self) {
        self.last_event_ms.store(self.epoch.elapsed().as_millis() as u64, Ordering::Relaxed);
    }

    /// Notes that bytes arrived.
    fn heard(&self) {
        self.heard_ms.store(self.epoch.elapsed().as_millis() as u64 + 1, Ordering::Relaxed);
    }

    /// Lower goes first: idle before busy, silent before heard, then least recently active.
    fn rank(&self) -> (bool, bool, u64) {
        let heard = self.heard_ms.load(Ordering::Relaxed);
        let active = self.last_event_ms.load(Ordering::Relaxed).max(heard.saturating_sub(1));
        (self.in_flight.load(Ordering::Relaxed) > 0, heard > 0, active)
    }

    /// Whether a silent connection's bytes wait unread (its reading task runs late on a
    /// loaded machine), noting it as heard if so.
    fn spoke_unread(&self) -> bool {
        let spoke = self.heard_ms.load(Ordering::Relaxed) == 0 && bytes_waiting(self.fd.load(Ordering::Relaxed));
        spoke.then(|| self.heard()).is_some()
    }
}

/// Why a connection was closed, for the log.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reason {
    PeerLimit,
    GlobalLimit,
    NoFirstRequest,
    Idle,
}

/// Every open connection.
#[derive(Debug, Default)]
struct Table {
    conns: HashMap<u64, Arc<Conn>>,
    /// Connections per peer that are not closing.
    live: HashMap<PeerKey, usize>,
    /// Connections marked closing whose socket is still open.
    closing: usize,
    next_id: u64,
    /// When the last warning about a full server was logged.
    warned_ms: Option<u64>,
}

impl Table {
    /// Registers a connection from `peer` accepted at `now_ms`, closing others as the limits
    /// require.
    fn admit(&mut self, limits: &Limits, peer: PeerKey, epoch: Instant, now_ms: u64) -> Arc<Conn> {
        let id = self.next_id;
        self.next_id += 1;
        let conn = Arc::new(Conn {
            id,
            peer,
            epoch,
            accepted_ms: now_ms,
            last_event_ms: AtomicU64::new(now_ms),
            in_flight: AtomicU32::new(0),
            heard_ms: AtomicU64::new(0),
            fd: AtomicI32::new(-1),
            served: AtomicBool::new(false),
            closing: AtomicBool::new(false),
            waker: AtomicWaker::new(),
        });
        self.conns.insert(id, conn.clone());
        let live = self.live.entry(peer).or_default();
        *live += 1;
        if *live > limits.max_per_peer
            && let Some(victim) = self.victim(|c| c.peer == peer, id)
        {
            self.close(&victim, Reason::PeerLimit);
            self.warn_full(limits, Reason::PeerLimit, now_ms);
        }
        if self.conns.len() - self.closing > limits.max_connections {
            // of the peers holding the most (the newcomer alone may be one of them: then any)
            let most = self.live.values().copied().max().unwrap_or(0);
            let heaviest = |c: &Conn| self.live.get(&c.peer) == Some(&most);
            if let Some(victim) = self.victim(heaviest, id).or_else(|| self.victim(|_| true, id)) {
                self.close(&victim, Reason::GlobalLimit);
            }
            self.warn_full(limits, Reason::GlobalLimit, now_ms);
        }
        conn
    }

    /// Of the connections `among` picks, the one to close first, never `except`.
    /// Only the chosen one's socket is asked whether bytes wait (a system call per choice,
    /// not per connection); one that has spoken is noted as heard and the choice made again.
    fn victim(&self, among: impl Fn(&Conn) -> bool, except: u64) -> Option<Arc<Conn>> {
        loop {
            let candidates = self.conns.values().filter(|c| c.id != except && among(c));
            let victim = candidates.filter(|c| !c.closing.load(Ordering::Relaxed)).min_by_key(|c| c.rank())?;
            if !victim.spoke_unread() {
                return Some(victim.clone());
            }
        }
    }

    fn close(&mut self, conn: &Conn, reason: Reason) {
        if conn.closing.swap(true, Ordering::Relaxed) {
            return;
        }
        tracing::debug!(peer = ?conn.peer.0, reason = ?reason, "closing connection");
        self.closing += 1;
        self.forget_live(conn.peer);
        conn.waker.wake();
    }

    fn forget_live(&mut self, peer: PeerKey) {
        if let Some(n) = self.live.get_mut(&peer) {
            *n -= 1;
            if *n == 0 {
                self.live.remove(&peer);
            }
        }
    }

    /// Forgets a connection whose socket is being dropped.
    fn remove(&mut self, id: u64) {
        let Some(conn) = self.conns.remove(&id) else { return };
        if conn.closing.load(Ordering::Relaxed) {
            self.closing -= 1;
        } else {
            self.forget_live(conn.peer);
        }
    }

    /// Closes the connections past their timeouts at `now_ms`.
    fn sweep(&mut self, limits: &Limits, now_ms: u64) {
        let first = limits.first_request_timeout.as_millis() as u64;
        let idle = limits.idle_timeout.as_millis() as u64;
        let expired: Vec<(Arc<Conn>, Reason)> = self
            .conns
            .values()
            .filter(|c| !c.closing.load(Ordering::Relaxed) && c.in_flight.load(Ordering::Relaxed) == 0)
            .filter_map(|c| {
                if !c.served.load(Ordering::Relaxed) && now_ms.saturating_sub(c.accepted_ms) >= first {
                    Some((c.clone(), Reason::NoFirstRequest))
                } else if now_ms.saturating_sub(c.last_event_ms.load(Ordering::Relaxed)) >= idle {
                    Some((c.clone(), Reason::Idle))
                } else {
                    None
                }
            })
            .collect();
        for (conn, reason) in expired {
            self.close(&conn, reason);
        }
    }

    /// Says once a minute that connections are being closed for want of room.
    fn warn_full(&mut self, limits: &Limits, reason: Reason, now_ms: u64) {
        if self.warned_ms.is_some_and(|t| now_ms.saturating_sub(t) < 60_000) {
            return;
        }
        self.warned_ms = Some(now_ms);
        let (limit, flag) = match reason {
            Reason::PeerLimit => (limits.max_per_peer, "--max-connections-per-ip"),
            _ => (limits.max_connections, "--max-connections"),
        };
        tracing::warn!(
            limit,
            flag,
            connections = self.conns.len(),
            "connection limit reached: closing the least recently active connections"
        );
    }
}

/// The shared state of a [`LimitedListener`] and its connections.
#[derive(Debug)]
struct Registry {
    limits: Limits,
    epoch: Instant,
    table: Mutex<Table>,
    /// Signalled when a socket is dropped.
    freed: tokio::sync::Notify,
}

impl Registry {
    fn table(&self) -> std::sync::MutexGuard<'_, Table> {
        // the table stays consistent between statements, so a panic elsewhere leaves it usable
        self.table.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn now_ms(&self) -> u64 {
        self.epoch.elapsed().as_millis() as u64
    }

    /// Waits until another socket fits: under the cap, counting the newcomer and up to
    /// [`CLOSING_SLACK`] sockets being closed.
    async fn room(&self) {
        loop {
            if self.table().conns.len() <= self.limits.max_connections + CLOSING_SLACK {
                return;
            }
            // notify_one keeps a permit, so a socket freed since the check is not missed
            self.freed.notified().await;
        }
    }
}

/// A listener that enforces [`Limits`] on the connections of `L` (see the module doc), and
/// gives each a [`Peer`] as its address.
pub struct LimitedListener<L> {
    inner: L,
    registry: Arc<Registry>,
}

impl<L> LimitedListener<L> {
    /// Wraps `inner`. Must be called within the tokio runtime: it starts the task that closes
    /// connections past their timeouts (it ends when the listener and its connections are gone).
    pub fn new(inner: L, limits: Limits) -> Self {
        let registry = Arc::new(Registry {
            limits,
            epoch: Instant::now(),
            table: Mutex::new(Table::default()),
            freed: tokio::sync::Notify::new(),
        });
        tokio::spawn(sweep(Arc::downgrade(&registry)));
        LimitedListener { inner, registry }
    }
}

async fn sweep(registry: Weak<Registry>) {
    let mut tick = tokio::time::interval(SWEEP_PERIOD);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tick.tick().await;
        let Some(registry) = registry.upgrade() else { return };
        let now = registry.now_ms();
        registry.table().sweep(&registry.limits, now);
    }
}

impl<L> Listener for LimitedListener<L>
where
    L: Listener<Addr = SocketAddr>,
    L::Io: Unpin + AsRawFd,
{
    type Io = Tracked<L::Io>;
    type Addr = Peer;

    // cancel-safe, as axum requires: nothing is accepted before the last await
    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        self.registry.room().await;
        let (io, addr) = self.inner.accept().await;
        let now = self.registry.now_ms();
        let conn = self.registry.table().admit(&self.registry.limits, PeerKey::of(addr.ip()), self.registry.epoch, now);
        conn.fd.store(io.as_raw_fd(), Ordering::Relaxed);
        let tracked = Tracked { inner: io, conn: conn.clone(), registry: self.registry.clone() };
        (tracked, Peer { addr, conn: Some(conn) })
    }

    fn local_addr(&self) -> io::Result<Peer> {
        Ok(Peer { addr: self.inner.local_addr()?, conn: None })
    }
}

/// A connection's address, and its handle for [`track_requests`] (axum's connect info).
#[derive(Clone, Debug)]
pub struct Peer {
    /// The remote address (the local one for [`Listener::local_addr`]).
    pub addr: SocketAddr,
    /// The connection; `None` for the listener's own address.
    conn: Option<Arc<Conn>>,
}

impl<L> axum::extract::connect_info::Connected<IncomingStream<'_, LimitedListener<L>>> for Peer
where
    LimitedListener<L>: Listener<Addr = Peer>,
{
    fn connect_info(stream: IncomingStream<'_, LimitedListener<L>>) -> Self {
        stream.remote_addr().clone()
    }
}

impl<L> axum::extract::connect_info::Connected<IncomingStream<'_, super::tls::TlsListener<L>>> for Peer
where
    L: Listener<Addr = Peer>,
    super::tls::TlsListener<L>: Listener<Addr = Peer>,
{
    fn connect_info(stream: IncomingStream<'_, super::tls::TlsListener<L>>) -> Self {
        stream.remote_addr().clone()
    }
}

/// A socket counted by a [`LimitedListener`]: fails once its connection is to be closed, and
/// leaves the count when dropped.
#[derive(Debug)]
pub struct Tracked<T> {
    inner: T,
    conn: Arc<Conn>,
    registry: Arc<Registry>,
}

impl<T> Tracked<T> {
    /// The error of a socket that is being closed (the waker is registered first, so that a
    /// close right after the check still wakes the task).
    fn closed(&self, cx: &Context<'_>) -> Option<io::Error> {
        self.conn.waker.register(cx.waker());
        let closing = self.conn.closing.load(Ordering::Relaxed);
        closing.then(|| io::Error::new(io::ErrorKind::ConnectionAborted, "connection closed to make room"))
    }
}

impl<T> Drop for Tracked<T> {
    fn drop(&mut self) {
        self.registry.table().remove(self.conn.id);
        self.registry.freed.notify_one();
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for Tracked<T> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        if let Some(e) = self.closed(cx) {
            return Poll::Ready(Err(e));
        }
        let before = buf.filled().len();
        let read = Pin::new(&mut self.inner).poll_read(cx, buf);
        if matches!(read, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            self.conn.heard();
        }
        read
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for Tracked<T> {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        if let Some(e) = self.closed(cx) {
            return Poll::Ready(Err(e));
        }
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        if let Some(e) = self.closed(cx) {
            return Poll::Ready(Err(e));
        }
        Pin::new(&mut self.inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        if let Some(e) = self.closed(cx) {
            return Poll::Ready(Err(e));
        }
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

/// A request in flight on a connection: counted from the request's start until its response
/// body has been sent or dropped.
struct InFlight(Arc<Conn>);

impl InFlight {
    fn start(conn: &Arc<Conn>) -> Self {
        conn.served.store(true, Ordering::Relaxed);
        conn.in_flight.fetch_add(1, Ordering::Relaxed);
        conn.touch();
        InFlight(conn.clone())
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        self.0.touch();
        self.0.in_flight.fetch_sub(1, Ordering::Relaxed);
    }
}

/// A response body that keeps its request counted as in flight until it ends (a watch stream
/// or a download is in use although its handler has returned).
struct Counted {
    body: axum::body::Body,
    _in_flight: InFlight,
}

impl http_body::Body for Counted {
    type Data = axum::body::Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<http_body::Frame<Self::Data>, Self::Error>>> {
        Pin::new(&mut self.body).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.body.is_end_stream()
    }

    fn size_hint(&self) -> http_body::SizeHint {
        self.body.size_hint()
    }
}

/// The axum middleware that tells the [`LimitedListener`] which connections have requests in
/// flight. Requests that did not come through one (router tests) pass untouched.
pub async fn track_requests(req: Request, next: Next) -> Response {
    let conn = req.extensions().get::<ConnectInfo<Peer>>().and_then(|ConnectInfo(peer)| peer.conn.as_ref());
    let in_flight = conn.map(InFlight::start);
    let response = next.run(req).await;
    match in_flight {
        Some(in_flight) => response.map(|body| axum::body::Body::new(Counted { body, _in_flight: in_flight })),
        None => response,
    }
}

#[cfg(test)]
mod tests;
