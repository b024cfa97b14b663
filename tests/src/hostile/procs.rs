//! The processes a case runs: a coordinator and an optional worker from given binaries, their
//! peak memory and whether they still run.

use super::Peak;
use crate::{Coordinator, Worker};
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::Duration;

/// The binaries under test.
#[derive(Clone, Debug)]
pub struct Bins {
    /// `tessera`.
    pub tessera: PathBuf,
    /// `tessera-worker`.
    pub worker: PathBuf,
}

impl Bins {
    /// This build's binaries, from the test's target folder.
    pub fn this_build() -> Bins {
        Bins { tessera: crate::bin("tessera"), worker: crate::bin("tessera-worker") }
    }

    /// A coordinator on loopback with `extra` flags, its data under `dir`.
    pub fn coordinator(&self, dir: &Path, extra: &[&str]) -> Coordinator {
        self.coordinator_with(dir, extra, |_| {})
    }

    /// [`Bins::coordinator`] with the command adjusted first (limits, environment).
    pub fn coordinator_with(&self, dir: &Path, extra: &[&str], configure: impl FnOnce(&mut Command)) -> Coordinator {
        Coordinator::start_bin(&self.tessera, &dir.join("data"), "127.0.0.1:0", extra, configure)
    }

    /// A one-thread worker of `c`, its cache under `dir`.
    pub fn worker(&self, c: &Coordinator, dir: &Path) -> Worker {
        Worker::start_bin(&self.worker, &c.url, &dir.join("cache"), &[])
    }
}

/// The peak memory of `child` and whether it runs.
pub fn peak(child: &mut Child) -> Peak {
    let kib = std::fs::read_to_string(format!("/proc/{}/status", child.id()))
        .ok()
        .and_then(|s| {
            let line = s.lines().find(|l| l.starts_with("VmHWM:"))?.to_string();
            line.split_whitespace().nth(1)?.parse().ok()
        })
        .unwrap_or(0);
    let alive = matches!(child.try_wait(), Ok(None));
    // a zombie still shows its status: only a running process counts
    Peak { kib: if alive { kib } else { 0 }, alive }
}

/// Waits up to `limit` for `child` to exit (a crash in progress), then reports it.
pub fn settle(child: &mut Child, limit: Duration) -> Peak {
    let end = std::time::Instant::now() + limit;
    while std::time::Instant::now() < end {
        if !matches!(child.try_wait(), Ok(None)) {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    peak(child)
}
