//! Runs the real `tessera-worker` binary: argument errors, and draining on SIGTERM while the
//! coordinator is unreachable (it keeps retrying with backoff until told to stop).

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn worker() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tessera-worker"))
}

#[test]
fn zero_threads_is_refused_with_one_line() {
    let out = worker().args(["--coordinator", "http://127.0.0.1:9", "--threads", "0"]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--threads must be at least 1"), "{err}");
}

#[test]
fn a_bad_ca_certificate_is_refused_at_once_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing-ca.pem");
    let out = worker()
        .args(["--coordinator", "https://127.0.0.1:9", "--threads", "1", "--ca-cert"])
        .arg(&missing)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("cannot read CA certificate") && err.contains("missing-ca.pem"), "{err}");
    // a CA for a plain-text URL would silently do nothing
    let out = worker().args(["--coordinator", "http://127.0.0.1:9", "--ca-cert"]).arg(&missing).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("needs an https:// coordinator URL"), "{err}");
}

#[test]
fn sigterm_stops_a_worker_that_is_retrying_a_dead_coordinator() {
    // a port nobody listens on
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let cache = tempfile::tempdir().unwrap();
    let mut child = worker()
        .args(["--coordinator", &format!("http://127.0.0.1:{port}"), "--threads", "1", "--cache-dir"])
        .arg(cache.path())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(700));
    assert!(child.try_wait().unwrap().is_none(), "the worker gave up instead of retrying");
    // SAFETY: sending a signal to our own child process
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            assert!(status.success(), "{status:?}");
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(10), "the worker did not drain");
        std::thread::sleep(Duration::from_millis(50));
    }
}
