//! Runs the real `tessera-worker` binary: argument errors, settings from flags, variables and
//! a file, and draining on SIGTERM while the coordinator is unreachable (it keeps retrying
//! with backoff until told to stop).

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
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // two failed attempts logged: it retried instead of giving up
    let (tx, attempts) = std::sync::mpsc::channel();
    let stderr = std::io::BufReader::new(child.stderr.take().unwrap());
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in stderr.lines().map_while(Result::ok) {
            if line.contains("coordinator unavailable") {
                let _ = tx.send(());
            }
        }
    });
    for _ in 0..2 {
        attempts.recv_timeout(Duration::from_secs(20)).expect("the worker logged no attempt to reach the coordinator");
    }
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

/// Flag > `TESSERA_*` variable > `--config` file > default, shown by `--print-config` with
/// the token redacted. The variables are set on the child only, so no test races another.
#[test]
fn settings_come_from_flags_then_variables_then_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("worker.toml");
    std::fs::write(
        &file,
        "coordinator = \"http://file:7878\"\nthreads = 4\nname = \"from-file\"\ncache-limit = 100\ntoken = \"file-secret\"\n",
    )
    .unwrap();
    let out = worker()
        .args(["--print-config", "--threads", "2"])
        .env("TESSERA_CONFIG", &file)
        .env("TESSERA_THREADS", "3")
        .env("TESSERA_NAME", "from-env")
        .env("TESSERA_WORKER_TOKEN", "env-secret")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for line in [
        "coordinator = \"http://file:7878\"  # file, line 1",
        "threads = 2  # flag",
        "name = \"from-env\"  # env TESSERA_NAME",
        "cache-limit = 100  # file, line 4",
        "token = \"<redacted>\"  # env TESSERA_WORKER_TOKEN",
        "max-tiles", // unset: a comment
    ] {
        assert!(text.lines().any(|l| l == line || l == format!("# {line} is not set")), "no {line:?} in\n{text}");
    }
    assert!(!text.contains("secret"), "a token is shown:\n{text}");
    // an unknown key stops the worker, naming the key and the file
    std::fs::write(&file, "coordinator = \"http://c\"\nthread = 4\n").unwrap();
    let out = worker().arg("--config").arg(&file).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("worker.toml, line 2: unknown key `thread`"), "{err}");
}
