//! The cases of the network and the disk: a page whose DNS name rebinds to loopback, floods of
//! idle connections (plain and TLS), too few file descriptors, and a full disk.

use super::inputs;
use super::procs::{Bins, settle};
use super::{Case, Report, answer, timed};
use crate::rest;
use serde_json::json;
use std::net::TcpStream;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

pub(super) fn all() -> Vec<Case> {
    vec![
        Case { name: "dns-rebinding", class: "the origin guard trusts Host", run: rebinding },
        Case { name: "tls-handshake-flood", class: "connections", run: tls_flood },
        Case { name: "fd-exhaustion-1024", class: "connections", run: fd_flood },
        Case { name: "full-disk", class: "a full disk stops the service", run: full_disk },
    ]
}

/// A page at `http://evil.example:PORT` whose name resolves to 127.0.0.1 posts a job: its
/// `Origin` and `Host` agree, and name no host the coordinator serves.
fn rebinding(bins: &Bins, dir: &Path) -> Report {
    let mut c = bins.coordinator(dir, &[]);
    let host = format!("evil.example:{}", c.port());
    let origin = format!("http://{host}");
    let headers = [("host", host.as_str()), ("origin", origin.as_str()), ("sec-fetch-site", "same-origin")];
    let extra = rest::Extra { headers: &headers, ca_pem: None };
    let ((status, body), seconds) =
        timed(|| rest::try_submit_with(&c.url, extra, ("scene.xml", inputs::scene("")), vec![], json!({"spp": 1})));
    Report {
        case: "dns-rebinding",
        class: "the origin guard trusts Host",
        answer: answer(status, &body),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(100)),
        worker: None,
        passed: status == 403,
    }
}

/// `GET /healthz` with curl (`-k`: the suite's own certificate), its status and seconds.
fn healthz(url: &str) -> (u16, f64) {
    let ((ok, out), seconds) = timed(|| {
        let out = Command::new("curl")
            .args(["-sk", "-o", "/dev/null", "-w", "%{http_code}", "--max-time", "10"])
            .arg(format!("{url}/healthz"))
            .output();
        out.map_or((false, String::new()), |o| (o.status.success(), String::from_utf8_lossy(&o.stdout).into_owned()))
    });
    (if ok { out.trim().parse().unwrap_or(0) } else { 0 }, seconds)
}

/// Opens `n` TCP connections to `port` that send nothing, from eight threads so that the
/// flood is in place within a second or two; returns those that opened.
fn idle_connections(port: u16, n: usize) -> Vec<TcpStream> {
    let threads: Vec<_> = (0..8)
        .map(|_| {
            std::thread::spawn(move || {
                let addr = ([127, 0, 0, 1], port).into();
                let open = |_| TcpStream::connect_timeout(&addr, Duration::from_millis(500)).ok();
                (0..n / 8).filter_map(open).collect::<Vec<_>>()
            })
        })
        .collect();
    threads.into_iter().flat_map(|t| t.join().unwrap_or_default()).collect()
}

/// Runs a coordinator with `n` file descriptors (soft and hard), a common `ulimit -n`.
fn with_descriptors(n: u64) -> impl FnOnce(&mut Command) {
    move |cmd| {
        use std::os::unix::process::CommandExt;
        // SAFETY: setrlimit is async-signal-safe, as pre_exec requires
        unsafe {
            cmd.pre_exec(move || {
                let limit = libc::rlimit { rlim_cur: n, rlim_max: n };
                if libc::setrlimit(libc::RLIMIT_NOFILE, &limit) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
}

/// 2000 connections that never send a ClientHello to a TLS coordinator with 1024 file
/// descriptors (eight times its handshake slots), then `/healthz`.
fn tls_flood(bins: &Bins, dir: &Path) -> Report {
    let made = rcgen::generate_simple_self_signed(vec!["localhost".to_string()]).expect("certificate");
    let (cert, key) = (dir.join("cert.pem"), dir.join("key.pem"));
    std::fs::write(&cert, made.cert.pem()).expect("write");
    std::fs::write(&key, made.signing_key.serialize_pem()).expect("write");
    let flags = ["--tls-cert", cert.to_str().expect("utf-8"), "--tls-key", key.to_str().expect("utf-8")];
    let mut c = bins.coordinator_with(dir, &flags, with_descriptors(1024));
    let idle = idle_connections(c.port(), 2000);
    let ((status, _), seconds) = timed(|| healthz(&c.url));
    let opened = idle.len();
    drop(idle);
    Report {
        case: "tls-handshake-flood",
        class: "connections",
        answer: format!("healthz {status} with {opened} silent TLS connections opened"),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(100)),
        worker: None,
        passed: status == 200 && seconds < 2.0,
    }
}

/// A coordinator with 1024 file descriptors (soft and hard) and 1100 idle connections.
fn fd_flood(bins: &Bins, dir: &Path) -> Report {
    let mut c = bins.coordinator_with(dir, &[], with_descriptors(1024));
    let idle = idle_connections(c.port(), 1100);
    let ((status, _), seconds) = timed(|| healthz(&c.url));
    let opened = idle.len();
    drop(idle);
    Report {
        case: "fd-exhaustion-1024",
        class: "connections",
        answer: format!("healthz {status} with {opened} idle connections opened"),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(100)),
        worker: None,
        passed: status == 200 && seconds < 2.0,
    }
}

/// A data folder on a 96 MiB file system that something else fills: a submission must be
/// refused (507) and a delete must work, without the coordinator stopping. Needs root to
/// mount the file system; otherwise the case says so and does not pass.
fn full_disk(bins: &Bins, dir: &Path) -> Report {
    let disk = dir.join("disk");
    std::fs::create_dir_all(&disk).expect("mkdir");
    let mounted = Command::new("mount").args(["-t", "tmpfs", "-o", "size=96m", "tmpfs"]).arg(&disk).status();
    if !mounted.is_ok_and(|s| s.success()) {
        let peak = super::Peak { kib: 0, alive: true };
        let answer = "skipped: cannot mount a 96 MiB tmpfs (needs root)".to_string();
        return Report {
            case: "full-disk",
            class: "a full disk stops the service",
            answer,
            seconds: 0.0,
            coordinator: peak,
            worker: None,
            passed: false,
        };
    }
    // unmounted however the case ends
    let report = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| full_disk_on(bins, dir, &disk)));
    let _ = Command::new("umount").arg("-l").arg(&disk).status();
    report.unwrap_or_else(|e| std::panic::resume_unwind(e))
}

fn full_disk_on(bins: &Bins, dir: &Path, disk: &Path) -> Report {
    // an older build has no reserve to set
    let reserve: &[&str] = if bins.serve_has_flag("--min-free-space") { &["--min-free-space", "32"] } else { &[] };
    let mut c = bins.coordinator(disk, reserve);
    let mut w = bins.worker(&c, dir);
    let (_, first) = rest::try_submit(&c.url, ("scene.xml", inputs::scene("")), vec![], json!({"spp": 1}));
    let id = first["id"].as_str().unwrap_or("").to_string();
    crate::wait_for(Duration::from_secs(60), "the first job", || {
        let (_, job) = rest::try_get_json(&format!("{}/api/v1/jobs/{id}", c.url));
        matches!(job["state"].as_str(), Some("done" | "failed")).then_some(())
    });
    fill(&disk.join("filler"));
    let ((submitted, body), seconds) =
        timed(|| rest::try_submit(&c.url, ("scene.xml", inputs::scene("")), vec![], json!({"spp": 1})));
    let (_, server) = rest::try_get_json(&format!("{}/api/v1/server", c.url));
    let (deleted, _) = rest::try_delete(&format!("{}/api/v1/jobs/{id}", c.url));
    let alive = settle(&mut c.child, Duration::from_millis(300));
    let reported = server["disk"]["low"].as_bool() == Some(true);
    Report {
        case: "full-disk",
        class: "a full disk stops the service",
        answer: format!("submit {}; disk low shown: {reported}; delete {deleted}", answer(submitted, &body)),
        seconds,
        coordinator: alive,
        worker: Some(super::procs::peak(&mut w.child)),
        passed: submitted == 507 && reported && deleted == 204 && alive.alive,
    }
}

/// Writes zeros to `path` until the file system is full.
fn fill(path: &Path) {
    use std::io::Write;
    let Ok(mut f) = std::fs::File::create(path) else { return };
    let block = vec![0u8; 1 << 20];
    while f.write_all(&block).is_ok() {}
    let _ = f.sync_all();
}
