//! Tests of the connection limits: the choice of whom to close on the table alone, then a
//! [`LimitedListener`] under `axum::serve` on loopback sockets.

use super::*;
use std::net::Ipv4Addr;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};

fn limits(max_connections: usize, max_per_peer: usize) -> Limits {
    Limits { max_connections, max_per_peer, first_request_timeout: FIRST_REQUEST_TIMEOUT, idle_timeout: IDLE_TIMEOUT }
}

fn peer(last: u8) -> PeerKey {
    PeerKey::of(IpAddr::V4(Ipv4Addr::new(127, 0, 0, last)))
}

fn closing(c: &Conn) -> bool {
    c.closing.load(Ordering::Relaxed)
}

#[test]
fn limits_follow_the_descriptor_limit() {
    let (l, lowered) = Limits::for_fds(256, None, None);
    assert_eq!((l.max_connections, l.max_per_peer, lowered), (192, 48, false));
    let (l, _) = Limits::for_fds(1024, None, None);
    assert_eq!((l.max_connections, l.max_per_peer), (896, 224), "an eighth kept for files");
    let (l, _) = Limits::for_fds(1 << 20, None, None);
    assert_eq!(l.max_connections, DEFAULT_MAX_CONNECTIONS, "memory bounds them beyond the descriptors");
    let (l, lowered) = Limits::for_fds(1024, Some(5000), Some(5000));
    assert_eq!((l.max_connections, l.max_per_peer, lowered), (896, 896, true));
    let (l, lowered) = Limits::for_fds(100, Some(10), None);
    assert_eq!((l.max_connections, l.max_per_peer, lowered), (10, 2, false));
}

#[test]
fn peer_keys_group_ipv6_by_64_and_unmap_ipv4() {
    let v6 = |s: &str| PeerKey::of(s.parse().unwrap());
    assert_eq!(v6("2001:db8:1:2:aaaa::1"), v6("2001:db8:1:2:bbbb::2"));
    assert_ne!(v6("2001:db8:1:2::1"), v6("2001:db8:1:3::1"));
    assert_eq!(v6("::ffff:127.0.0.1"), peer(1));
}

#[test]
fn a_peer_at_its_limit_loses_its_least_recently_active_idle_connection() {
    let (l, epoch) = (limits(100, 3), Instant::now());
    let mut table = Table::default();
    let a = table.admit(&l, peer(1), epoch, 0);
    let b = table.admit(&l, peer(1), epoch, 1);
    let c = table.admit(&l, peer(1), epoch, 2);
    let other = table.admit(&l, peer(2), epoch, 0);
    a.in_flight.store(1, Ordering::Relaxed);
    let d = table.admit(&l, peer(1), epoch, 3);
    assert!(closing(&b), "the oldest idle one");
    assert!(!closing(&a) && !closing(&c) && !closing(&d) && !closing(&other));
    // with every other connection busy, the least recently active busy one goes
    c.in_flight.store(1, Ordering::Relaxed);
    d.in_flight.store(1, Ordering::Relaxed);
    table.admit(&l, peer(1), epoch, 4);
    assert!(closing(&a) && !closing(&c) && !closing(&d));
    assert_eq!((table.conns.len(), table.closing, table.live[&peer(1)]), (6, 2, 3));
}

#[test]
fn a_connection_that_has_sent_bytes_outlasts_newer_silent_ones() {
    let (l, epoch) = (limits(100, 3), Instant::now());
    let mut table = Table::default();
    // a TLS client mid-handshake: accepted first, has sent its hello, no request yet
    let client = table.admit(&l, peer(1), epoch, 0);
    client.heard_ms.store(1, Ordering::Relaxed);
    let silent: Vec<_> = (1..=2).map(|t| table.admit(&l, peer(1), epoch, t)).collect();
    let newcomer = table.admit(&l, peer(1), epoch, 3);
    assert!(closing(&silent[0]) && !closing(&client) && !closing(&silent[1]) && !closing(&newcomer));
    let _ = table.admit(&l, peer(1), epoch, 4);
    assert!(closing(&silent[1]) && !closing(&client), "silent ones go first, however new");
    // among connections that have spoken, bytes received count as activity
    let (a, b) = (table.admit(&l, peer(2), epoch, 10), table.admit(&l, peer(2), epoch, 11));
    let c = table.admit(&l, peer(2), epoch, 12);
    for (conn, at) in [(&a, 13), (&b, 13), (&c, 14)] {
        conn.heard_ms.store(at, Ordering::Relaxed);
    }
    a.heard_ms.store(21, Ordering::Relaxed);
    let _ = table.admit(&l, peer(2), epoch, 22);
    assert!(closing(&b) && !closing(&a) && !closing(&c), "{:?} {:?}", a.rank(), b.rank());
}

#[test]
fn a_full_server_closes_a_connection_of_the_heaviest_peer() {
    let (l, epoch) = (limits(4, 4), Instant::now());
    let mut table = Table::default();
    let lone = table.admit(&l, peer(2), epoch, 0);
    let heavy: Vec<_> = (1..=3).map(|t| table.admit(&l, peer(1), epoch, t)).collect();
    let newcomer = table.admit(&l, peer(3), epoch, 10);
    assert!(closing(&heavy[0]), "the heaviest peer's least recently active");
    assert!(!closing(&lone) && !closing(&newcomer), "not the lone peer's older connection");
    assert!(!closing(&heavy[1]) && !closing(&heavy[2]));
    // one connection per peer, the newcomer's peer as heavy as any: the least recent of all
    let mut table = Table::default();
    let first = table.admit(&l, peer(1), epoch, 0);
    let others: Vec<_> = (2..=4).map(|p| table.admit(&l, peer(p), epoch, u64::from(p))).collect();
    let newcomer = table.admit(&l, peer(5), epoch, 10);
    assert!(closing(&first) && !closing(&newcomer) && others.iter().all(|c| !closing(c)));
}

#[test]
fn removing_a_connection_keeps_the_counts() {
    let (l, epoch) = (limits(100, 1), Instant::now());
    let mut table = Table::default();
    let a = table.admit(&l, peer(1), epoch, 0);
    let b = table.admit(&l, peer(1), epoch, 1);
    assert!(closing(&a));
    table.remove(a.id);
    assert_eq!((table.conns.len(), table.closing, table.live[&peer(1)]), (1, 0, 1));
    table.remove(b.id);
    assert!(table.conns.is_empty() && table.live.is_empty() && table.closing == 0);
}

#[test]
fn sweeping_closes_silent_and_idle_connections_but_not_busy_ones() {
    let (l, epoch) = (limits(100, 100), Instant::now());
    let mut table = Table::default();
    let silent = table.admit(&l, peer(1), epoch, 0);
    let idle = table.admit(&l, peer(1), epoch, 0);
    idle.served.store(true, Ordering::Relaxed);
    let busy = table.admit(&l, peer(1), epoch, 0);
    busy.served.store(true, Ordering::Relaxed);
    busy.in_flight.store(1, Ordering::Relaxed);
    let first = FIRST_REQUEST_TIMEOUT.as_millis() as u64;
    table.sweep(&l, first - 1);
    assert!(!closing(&silent));
    table.sweep(&l, first);
    assert!(closing(&silent) && !closing(&idle));
    table.sweep(&l, IDLE_TIMEOUT.as_millis() as u64);
    assert!(closing(&idle) && !closing(&busy));
    table.sweep(&l, 100 * IDLE_TIMEOUT.as_millis() as u64);
    assert!(!closing(&busy), "a request in flight is not idle");
}

// ---------------------------------------------------------------------------------------------
// a LimitedListener under axum::serve

/// A server with `/healthz` and `/hold` (answers when `release` is notified), whose limits are
/// `limits`; returns its address, the registry and the release.
async fn serve(limits: Limits) -> (SocketAddr, Arc<Registry>, Arc<tokio::sync::Notify>) {
    let tcp = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = tcp.local_addr().unwrap();
    let listener = LimitedListener::new(tcp, limits);
    let registry = listener.registry.clone();
    let release = Arc::new(tokio::sync::Notify::new());
    let held = release.clone();
    let app = axum::Router::new()
        .route("/healthz", axum::routing::get(|| async { "ok" }))
        .route(
            "/hold",
            axum::routing::get(move || async move {
                held.notified().await;
                "released"
            }),
        )
        .layer(axum::middleware::from_fn(track_requests));
    tokio::spawn(axum::serve(listener, app.into_make_service_with_connect_info::<Peer>()).into_future());
    (addr, registry, release)
}

/// A connection to `addr` from `source` (127.0.0.x: loopback routes all of 127/8).
async fn connect_from(source: Ipv4Addr, addr: SocketAddr) -> TcpStream {
    let socket = TcpSocket::new_v4().unwrap();
    socket.bind(SocketAddr::new(source.into(), 0)).unwrap();
    socket.connect(addr).await.unwrap()
}

/// GET `path` on a kept-alive HTTP/1.1 connection; the body.
async fn get(stream: &mut TcpStream, path: &str) -> String {
    stream.write_all(format!("GET {path} HTTP/1.1\r\nhost: localhost\r\n\r\n").as_bytes()).await.unwrap();
    let mut answer = Vec::new();
    let mut buf = [0u8; 1024];
    loop {
        let n = stream.read(&mut buf).await.unwrap();
        assert!(n > 0, "closed mid-answer: {}", String::from_utf8_lossy(&answer));
        answer.extend_from_slice(&buf[..n]);
        let text = String::from_utf8_lossy(&answer).into_owned();
        let Some((head, body)) = text.split_once("\r\n\r\n") else { continue };
        let length = head.lines().find_map(|l| l.strip_prefix("content-length: ")).and_then(|l| l.parse().ok());
        if length.is_some_and(|l: usize| body.len() >= l) {
            assert!(head.starts_with("HTTP/1.1 200"), "{head}");
            return body.to_string();
        }
    }
}

/// Whether the server has closed `stream` (reads end, or fail), waiting up to `within`.
async fn closed_by_server(stream: &mut TcpStream, within: Duration) -> bool {
    let mut buf = [0u8; 64];
    matches!(tokio::time::timeout(within, stream.read(&mut buf)).await, Ok(Ok(0) | Err(_)))
}

// A bound on a loopback request that a loaded 2-core test machine meets with a wide margin
// (they take milliseconds); without the limits these requests never get an answer at all.
const ANSWER_WITHIN: Duration = Duration::from_secs(2);

#[tokio::test]
async fn an_idle_flood_from_the_clients_own_address_evicts_only_itself() {
    let (addr, registry, release) = serve(limits(32, 8)).await;
    let local = Ipv4Addr::LOCALHOST;
    // a request in flight (a long poll), then a flood of sockets that never send a byte
    let mut busy = connect_from(local, addr).await;
    busy.write_all(b"GET /hold HTTP/1.1\r\nhost: localhost\r\n\r\n").await.unwrap();
    wait_until(|| registry.table().conns.values().any(|c| c.in_flight.load(Ordering::Relaxed) > 0)).await;
    let mut flood = Vec::new();
    for _ in 0..100 {
        flood.push(connect_from(local, addr).await);
    }
    let mut probe = connect_from(local, addr).await;
    let answer = tokio::time::timeout(ANSWER_WITHIN, get(&mut probe, "/healthz")).await;
    assert_eq!(answer.expect("/healthz during the flood").as_str(), "ok");
    {
        let table = registry.table();
        assert!(table.conns.len() <= 32 + CLOSING_SLACK + 1, "{} sockets for a cap of 32", table.conns.len());
        assert!(table.conns.len() - table.closing <= 32);
        assert!(table.live[&PeerKey::of(local.into())] <= 8);
    }
    // the request in flight was kept and completes
    release.notify_one();
    let mut buf = vec![0u8; 1024];
    let n = tokio::time::timeout(ANSWER_WITHIN, busy.read(&mut buf)).await.expect("held answer").unwrap();
    assert!(String::from_utf8_lossy(&buf[..n]).ends_with("released"));
    // and the flood's oldest sockets were the ones closed
    assert!(closed_by_server(&mut flood[0], ANSWER_WITHIN).await);
}

#[tokio::test]
async fn a_flood_from_one_peer_leaves_the_connections_of_others_alone() {
    let (addr, _registry, _release) = serve(limits(64, 8)).await;
    // an idle kept-alive connection from 127.0.0.3, older than the whole flood
    let mut kept = connect_from(Ipv4Addr::new(127, 0, 0, 3), addr).await;
    assert_eq!(get(&mut kept, "/healthz").await, "ok");
    let mut flood = Vec::new();
    for _ in 0..100 {
        flood.push(connect_from(Ipv4Addr::new(127, 0, 0, 2), addr).await);
    }
    let mut probe = connect_from(Ipv4Addr::new(127, 0, 0, 2), addr).await;
    assert_eq!(tokio::time::timeout(ANSWER_WITHIN, get(&mut probe, "/healthz")).await.unwrap(), "ok");
    let second = tokio::time::timeout(ANSWER_WITHIN, get(&mut kept, "/healthz")).await;
    assert_eq!(second.expect("the other peer's connection was closed"), "ok");
}

#[tokio::test]
async fn a_full_server_stays_under_its_cap_and_serves_the_newcomer() {
    let (addr, registry, _release) = serve(limits(16, 16)).await;
    let mut flood = Vec::new();
    for _ in 0..60 {
        flood.push(connect_from(Ipv4Addr::new(127, 0, 0, 2), addr).await);
    }
    let mut probe = connect_from(Ipv4Addr::new(127, 0, 0, 3), addr).await;
    assert_eq!(tokio::time::timeout(ANSWER_WITHIN, get(&mut probe, "/healthz")).await.unwrap(), "ok");
    let table = registry.table();
    assert!(table.conns.len() <= 16 + CLOSING_SLACK + 1, "{} sockets for a cap of 16", table.conns.len());
    assert!(table.conns.len() - table.closing <= 16);
}

#[tokio::test]
async fn silent_and_idle_connections_are_closed_after_their_timeouts() {
    let short = Limits {
        first_request_timeout: Duration::from_millis(300),
        idle_timeout: Duration::from_millis(1500),
        ..limits(32, 32)
    };
    let (addr, registry, _release) = serve(short).await;
    let mut silent = connect_from(Ipv4Addr::LOCALHOST, addr).await;
    let mut served = connect_from(Ipv4Addr::LOCALHOST, addr).await;
    assert_eq!(get(&mut served, "/healthz").await, "ok");
    // the sweep runs every second: each is closed within a few periods of its timeout
    assert!(closed_by_server(&mut silent, Duration::from_secs(10)).await, "a silent socket stays open");
    assert!(closed_by_server(&mut served, Duration::from_secs(10)).await, "an idle socket stays open");
    wait_until(|| registry.table().conns.is_empty()).await;
}

/// Waits (up to 10 s) until `done` holds, polling every 10 ms: the registry has no event to
/// wait on from outside.
async fn wait_until(mut done: impl FnMut() -> bool) {
    let start = Instant::now();
    while !done() {
        assert!(start.elapsed() < Duration::from_secs(10), "timed out");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// A client whose first bytes wait unread in its socket (its task has not run yet) counts as
/// heard: newer silent sockets of its peer go first.
#[test]
fn bytes_waiting_unread_count_as_heard() {
    use std::io::Write;
    use std::os::fd::AsRawFd;
    let server = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let mut client = std::net::TcpStream::connect(server.local_addr().unwrap()).unwrap();
    let (accepted, _) = server.accept().unwrap();
    client.write_all(b"\x16\x03\x01").unwrap();
    let (l, epoch) = (limits(100, 2), Instant::now());
    let mut table = Table::default();
    let real = table.admit(&l, peer(1), epoch, 0);
    real.fd.store(accepted.as_raw_fd(), Ordering::Relaxed);
    let start = Instant::now();
    while !bytes_waiting(accepted.as_raw_fd()) && start.elapsed() < std::time::Duration::from_secs(5) {
        std::thread::yield_now();
    }
    let silent = table.admit(&l, peer(1), epoch, 1);
    let _newcomer = table.admit(&l, peer(1), epoch, 2);
    assert!(closing(&silent) && !closing(&real), "the client with bytes waiting was closed first");
    assert!(real.heard_ms.load(Ordering::Relaxed) > 0, "noted as heard once asked");
}
