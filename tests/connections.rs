//! Network-level hostile input with real processes (issue 67): floods of idle connections
//! against a coordinator limited to 256 file descriptors, over plain TCP and TLS, must leave
//! `/healthz` answering and a job completing bit for bit; and browsers must reach the
//! coordinator under an allowed host name (DNS rebinding), while clients without browser
//! headers may use any.

use super::*;
use std::io::{Read, Write};
use std::net::{Ipv4Addr, SocketAddr, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;
use tessera_tests::rest::Extra;

/// The descriptors the flooded coordinator may open (soft = hard, so it cannot raise them).
const FDS: u64 = 256;
/// Idle sockets each flood keeps open, several times the coordinator's descriptors.
const FLOOD: usize = 300;
/// How long `/healthz` may take during a flood. It answers in milliseconds; the bound leaves
/// room for a debug build on a loaded 2-core machine. Without the limits it never answers.
const HEALTHZ_WITHIN: Duration = Duration::from_secs(2);

/// Gives this test process the descriptors its floods need (soft limit to the hard one).
fn raise_own_fd_limit() {
    let mut limit = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
    // SAFETY: get/setrlimit read and write the struct they are given
    unsafe {
        libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit);
        limit.rlim_cur = limit.rlim_max.min(1 << 16);
        libc::setrlimit(libc::RLIMIT_NOFILE, &limit);
    }
    assert!(limit.rlim_cur >= 4 * FLOOD as u64, "the floods need {} descriptors", 4 * FLOOD);
}

/// A coordinator limited to [`FDS`] descriptors.
fn start_limited(dir: &Path, extra: &[&str]) -> Coordinator {
    use std::os::unix::process::CommandExt;
    Coordinator::start_with(&dir.join("data"), "127.0.0.1:0", extra, |command| {
        // SAFETY: only an async-signal-safe call between fork and exec
        unsafe {
            command.pre_exec(|| {
                let limit = libc::rlimit { rlim_cur: FDS, rlim_max: FDS };
                libc::setrlimit(libc::RLIMIT_NOFILE, &limit);
                Ok(())
            });
        }
    })
}

/// What a flood's sockets do once connected.
#[derive(Clone, Copy)]
enum Kind {
    /// Send nothing (over TLS: never a ClientHello).
    Silent,
    /// One `GET /healthz` on a kept-alive connection, then nothing.
    ServedThenIdle,
}

/// `sockets` connections from `source` to `addr`, each opened again a second after the server
/// closes it, so that the flood lasts as long as the value lives.
struct Flood {
    stop: Option<tokio::sync::watch::Sender<bool>>,
    thread: Option<std::thread::JoinHandle<()>>,
    closed: Arc<AtomicU64>,
}

impl Flood {
    fn start(addr: SocketAddr, source: Ipv4Addr, sockets: usize, kind: Kind) -> Flood {
        let (stop, stopped) = tokio::sync::watch::channel(false);
        let closed = Arc::new(AtomicU64::new(0));
        let counter = closed.clone();
        let (ready_tx, ready) = std::sync::mpsc::channel();
        let thread = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
            rt.block_on(async move {
                let (first_tx, mut first) = tokio::sync::mpsc::unbounded_channel();
                let tasks: Vec<_> = (0..sockets)
                    .map(|_| {
                        let socket = (addr, source, kind);
                        tokio::spawn(hold(socket, stopped.clone(), counter.clone(), first_tx.clone()))
                    })
                    .collect();
                // started once every socket has been opened once
                for _ in 0..sockets {
                    first.recv().await;
                }
                let _ = ready_tx.send(());
                for t in tasks {
                    let _ = t.await;
                }
            });
        });
        ready.recv_timeout(Duration::from_secs(60)).expect("the flood's sockets did not open");
        Flood { stop: Some(stop), thread: Some(thread), closed }
    }

    /// Waits up to 10 s for the server to close one of the flood's sockets; whether it did.
    fn closed_one(&self) -> bool {
        let start = Instant::now();
        while self.closed.load(Ordering::Relaxed) == 0 && start.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(50));
        }
        self.closed.load(Ordering::Relaxed) > 0
    }
}

impl Drop for Flood {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// One socket of a flood: open, act, wait for the server to close it, a second's pause, again.
async fn hold(
    (addr, source, kind): (SocketAddr, Ipv4Addr, Kind),
    mut stop: tokio::sync::watch::Receiver<bool>,
    closed: Arc<AtomicU64>,
    first: tokio::sync::mpsc::UnboundedSender<()>,
) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut first = Some(first);
    loop {
        let socket = tokio::net::TcpSocket::new_v4().unwrap();
        socket.bind(SocketAddr::new(source.into(), 0)).unwrap();
        let connected = tokio::select! {
            c = tokio::time::timeout(Duration::from_secs(2), socket.connect(addr)) => c,
            _ = stop.changed() => return,
        };
        if let Some(first) = first.take() {
            let _ = first.send(());
        }
        if let Ok(Ok(mut stream)) = connected {
            if let Kind::ServedThenIdle = kind {
                let _ = stream.write_all(b"GET /healthz HTTP/1.1\r\nhost: localhost\r\n\r\n").await;
            }
            // reads end when the server closes the socket (after the answer, if any)
            let mut buf = [0u8; 256];
            loop {
                tokio::select! {
                    r = stream.read(&mut buf) => if !matches!(r, Ok(n) if n > 0) {
                        closed.fetch_add(1, Ordering::Relaxed);
                        break;
                    },
                    _ = stop.changed() => return,
                }
            }
        }
        tokio::select! {
            _ = tokio::time::sleep(Duration::from_secs(1)) => {}
            _ = stop.changed() => return,
        }
    }
}

/// `GET /healthz` over a new HTTP/1.1 connection; how long the answer took.
fn healthz_http1(addr: SocketAddr) -> Duration {
    let start = Instant::now();
    let mut s = TcpStream::connect_timeout(&addr, Duration::from_secs(10)).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(b"GET /healthz HTTP/1.1\r\nhost: 127.0.0.1\r\nconnection: close\r\n\r\n").unwrap();
    let mut answer = String::new();
    let _ = s.read_to_string(&mut answer);
    assert!(answer.starts_with("HTTP/1.1 200") && answer.ends_with("ok"), "/healthz answered {answer:?}");
    start.elapsed()
}

/// `tessera healthcheck` (HTTP/2 through the client's own connection code); how long it took.
fn healthz_http2(url: &str, ca: Option<&Path>) -> Duration {
    let start = Instant::now();
    let mut args = vec!["healthcheck", url, "--timeout", "10", "--quiet"];
    if let Some(ca) = ca {
        args.extend(["--ca-cert", ca.to_str().unwrap()]);
    }
    let (ok, _, err) = tessera(&args);
    assert!(ok, "tessera healthcheck failed: {err}");
    start.elapsed()
}

fn addr_of(c: &Coordinator) -> SocketAddr {
    SocketAddr::from((Ipv4Addr::LOCALHOST, c.port()))
}

/// Checks the coordinator survived with no descriptor shortage in its log.
fn assert_no_fd_shortage(c: &mut Coordinator) {
    assert!(c.child.try_wait().unwrap().is_none(), "the coordinator died, log: {}", c.log.display());
    let log = std::fs::read_to_string(&c.log).unwrap();
    assert!(!log.contains("Too many open files") && !log.contains("accept error"), "log: {}", c.log.display());
    assert!(log.contains("connection limit reached"), "the floods never reached a limit: {}", c.log.display());
}

#[test]
fn idle_floods_leave_healthz_and_jobs_working_with_256_descriptors() {
    raise_own_fd_limit();
    let dir = tempfile::tempdir().unwrap();
    let mut c = start_limited(dir.path(), &[]);
    let _worker = Worker::start(&c.url, &dir.path().join("cache"), &[]);
    let addr = addr_of(&c);
    // silent sockets from the address every real client here uses, and kept-alive idle ones
    // from another; together several times the coordinator's descriptors
    let silent = Flood::start(addr, Ipv4Addr::LOCALHOST, FLOOD, Kind::Silent);
    let idle = Flood::start(addr, Ipv4Addr::new(127, 0, 0, 2), FLOOD, Kind::ServedThenIdle);
    for _ in 0..5 {
        let took = healthz_http1(addr);
        assert!(took < HEALTHZ_WITHIN, "HTTP/1.1 /healthz took {took:?} during the flood");
        let took = healthz_http2(&c.url, None);
        assert!(took < HEALTHZ_WITHIN, "HTTP/2 /healthz took {took:?} during the flood");
    }
    let out = dir.path().join("farm.exr");
    let box_scene = scene("cornell-box");
    let (ok, _, err) = submit_and_wait(&c.url, &box_scene, ("pt", 2, 7), &out, &[]);
    assert!(ok, "the job failed during the flood: {err}\nlog: {}", c.log.display());
    assert_same_image(&out, &local_render(dir.path(), &box_scene, "pt", 2, 7));
    assert!(silent.closed_one() && idle.closed_one(), "the server closed no flood socket");
    drop((silent, idle));
    assert_no_fd_shortage(&mut c);
}

#[test]
fn sockets_that_never_say_hello_leave_tls_working_with_256_descriptors() {
    raise_own_fd_limit();
    let dir = tempfile::tempdir().unwrap();
    let made = rcgen::generate_simple_self_signed(vec!["127.0.0.1".to_string(), "localhost".to_string()]).unwrap();
    let (cert, key) = (dir.path().join("cert.pem"), dir.path().join("key.pem"));
    std::fs::write(&cert, made.cert.pem()).unwrap();
    std::fs::write(&key, made.signing_key.serialize_pem()).unwrap();
    let (cert_arg, key_arg) = (cert.to_str().unwrap(), key.to_str().unwrap());
    let mut c = start_limited(dir.path(), &["--tls-cert", cert_arg, "--tls-key", key_arg]);
    let _worker = Worker::start(&c.url, &dir.path().join("cache"), &["--ca-cert", cert_arg]);
    let addr = addr_of(&c);
    // more silent sockets than the TLS handshake slots (256), from two addresses
    let first = Flood::start(addr, Ipv4Addr::LOCALHOST, FLOOD, Kind::Silent);
    let second = Flood::start(addr, Ipv4Addr::new(127, 0, 0, 2), FLOOD, Kind::Silent);
    let pem = made.cert.pem().into_bytes();
    for _ in 0..5 {
        let start = Instant::now();
        let ca = Extra { headers: &[], ca_pem: Some(&pem) };
        let (status, body) = rest::send(None, ca, |http| http.get(format!("{}/healthz", c.url)));
        let took = start.elapsed();
        assert_eq!((status, body.as_slice()), (200, &b"ok"[..]));
        assert!(took < HEALTHZ_WITHIN, "HTTPS/1.1 /healthz took {took:?} during the flood");
        let took = healthz_http2(&c.url, Some(&cert));
        assert!(took < HEALTHZ_WITHIN, "HTTPS/2 /healthz took {took:?} during the flood");
    }
    let out = dir.path().join("farm.exr");
    let box_scene = scene("cornell-box");
    let (ok, _, err) = submit_and_wait(&c.url, &box_scene, ("pt", 2, 8), &out, &["--ca-cert", cert_arg]);
    assert!(ok, "the job failed during the flood: {err}\nlog: {}", c.log.display());
    assert_same_image(&out, &local_render(dir.path(), &box_scene, "pt", 2, 8));
    assert!(first.closed_one() && second.closed_one(), "the server closed no flood socket");
    drop((first, second));
    assert_no_fd_shortage(&mut c);
}

/// A hand-written HTTP/1.1 request (`Host` and the browser's headers set at will) to `addr`:
/// (status, head, body).
fn raw(addr: SocketAddr, method: &str, path: &str, headers: &[(&str, &str)]) -> (u16, String, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let mut request = format!("{method} {path} HTTP/1.1\r\nconnection: close\r\ncontent-length: 0\r\n");
    for (name, value) in headers {
        request.push_str(&format!("{name}: {value}\r\n"));
    }
    s.write_all(format!("{request}\r\n").as_bytes()).unwrap();
    let mut answer = String::new();
    s.read_to_string(&mut answer).unwrap();
    let (head, body) = answer.split_once("\r\n\r\n").unwrap_or((&answer, ""));
    let status = head.split(' ').nth(1).and_then(|s| s.parse().ok()).unwrap_or(0);
    (status, head.to_ascii_lowercase(), body.to_string())
}

#[test]
fn browsers_must_reach_the_coordinator_under_an_allowed_host_name() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &["--allowed-host", "farm.example"]);
    let (addr, port) = (addr_of(&c), c.port());
    let at = |name: &str| format!("{name}:{port}");
    let navigate = |host: &str| {
        raw(addr, "GET", "/", &[("host", host), ("sec-fetch-mode", "navigate"), ("sec-fetch-dest", "document")])
    };
    // the dashboard at the addresses a user opens, and at the name given with --allowed-host
    for host in ["127.0.0.1", "localhost", "farm.example", "[::1]"] {
        let (status, _, page) = navigate(&at(host));
        assert!(status == 200 && page.contains("/api/v1/jobs"), "{host}: {status}");
    }
    // a rebound name: the page and its API calls are refused, naming the flag
    let (status, head, text) = navigate(&at("evil.example"));
    assert_eq!(status, 403, "{text}");
    assert!(head.contains("content-type: text/plain"), "{head}");
    assert!(text.contains("\"evil.example\"") && text.contains("--allowed-host evil.example"), "{text}");
    let evil = at("evil.example");
    let evil_origin = format!("http://{evil}");
    let rebound = [("host", evil.as_str()), ("origin", evil_origin.as_str()), ("sec-fetch-site", "same-origin")];
    let (status, _, body) = raw(addr, "GET", "/api/v1/jobs", &rebound);
    assert!(status == 403 && body.contains("permission_denied"), "{status} {body}");
    // over plain HTTP a page's GET carries no Origin nor Sec-Fetch-*: its user agent tells
    let chrome = [("host", evil.as_str()), ("user-agent", "Mozilla/5.0 (X11; Linux x86_64) Chrome/156.0")];
    assert_eq!(raw(addr, "GET", "/api/v1/jobs", &chrome).0, 403);
    let curl = [("host", evil.as_str()), ("user-agent", "curl/8.5.0")];
    assert_eq!(raw(addr, "GET", "/api/v1/jobs", &curl).0, 200);

    // a job submitted by a client; the rebound page cannot cancel or delete it
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml), vec![], json!({"spp": 1}));
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_str().unwrap();
    let cancel = format!("/api/v1/jobs/{id}/cancel");
    assert_eq!(raw(addr, "POST", &cancel, &rebound).0, 403);
    let grpc = raw(addr, "POST", "/tessera.v1.JobService/CancelJob", &rebound);
    assert!(grpc.1.contains("grpc-status: 7"), "gRPC PERMISSION_DENIED: {}", grpc.1);
    // a cross-site page is refused at an allowed host with its own origin, too
    let own = at("127.0.0.1");
    let own_origin = format!("http://{own}");
    let cross = [("host", own.as_str()), ("origin", own_origin.as_str()), ("sec-fetch-site", "cross-site")];
    assert_eq!(raw(addr, "POST", &cancel, &cross).0, 403);
    assert_eq!(rest::get_json(&job_url(&c, id), None).1["state"], "queued", "a refused cancel did something");
    // the dashboard's own calls pass; clients without browser headers pass under any name
    let same = [("host", own.as_str()), ("origin", own_origin.as_str()), ("sec-fetch-site", "same-origin")];
    let (status, _, body) = raw(addr, "POST", &cancel, &same);
    assert!(status == 200 && body.contains("cancelled"), "{status} {body}");
    assert_eq!(raw(addr, "DELETE", &format!("/api/v1/jobs/{id}"), &rebound).0, 403);
    assert_eq!(raw(addr, "DELETE", &format!("/api/v1/jobs/{id}"), &[("host", evil.as_str())]).0, 204);
}

#[test]
fn allowed_hosts_come_from_the_environment_and_the_settings_file() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start_with(&dir.path().join("data"), "127.0.0.1:0", &[], |command| {
        command.env("TESSERA_ALLOWED_HOSTS", "farm.example,*.render.example");
    });
    let page = |host: &str| {
        let host = format!("{host}:{}", c.port());
        raw(addr_of(&c), "GET", "/", &[("host", host.as_str()), ("sec-fetch-dest", "document")]).0
    };
    assert_eq!([page("farm.example"), page("a.render.example"), page("render.example")], [200, 200, 403]);
    // the file's key is the flag's name; a port is refused naming what to write
    let file = dir.path().join("serve.toml");
    std::fs::write(&file, "allowed-host = [\"farm.example\", \"*.render.example\"]\n").unwrap();
    let (ok, out, err) = tessera(&["serve", "--config", file.to_str().unwrap(), "--print-config"]);
    assert!(ok, "{err}");
    assert!(out.contains("allowed-host = [\"farm.example\", \"*.render.example\"]  # file, line 1"), "{out}");
    std::fs::write(&file, "allowed-host = [\"farm.example:7878\"]\n").unwrap();
    let (ok, _, err) = tessera(&["serve", "--config", file.to_str().unwrap(), "--print-config"]);
    assert!(!ok && err.contains("line 1") && err.contains("e.g. farm.example"), "{err}");
}
