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
        Coordinator::start_bin(&self.tessera, &dir.join("data"), "127.0.0.1:0", extra, |cmd| {
            bound_address_space(cmd);
            configure(cmd)
        })
    }

    /// Whether `tessera serve` of these binaries has `flag` (an older build may not).
    pub fn serve_has_flag(&self, flag: &str) -> bool {
        Command::new(&self.tessera)
            .args(["serve", "--help"])
            .output()
            .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains(flag))
    }

    /// A one-thread worker of `c`, its cache under `dir`.
    pub fn worker(&self, c: &Coordinator, dir: &Path) -> Worker {
        let child = Command::new(&self.worker)
            .args(["--coordinator", &c.url, "--threads", "1", "--cache-dir"])
            .arg(dir.join("cache"))
            .stdout(std::process::Stdio::null())
            .stderr(
                std::fs::File::create(dir.join("worker.log")).map_or_else(|_| std::process::Stdio::null(), Into::into),
            )
            .spawn_bounded()
            .expect("start tessera-worker");
        Worker { child }
    }
}

/// The address space a process of the suite may take: an older build's runaway allocation
/// (tens of GB) must abort that process, not push the machine into swapping or the OOM killer.
const ADDRESS_SPACE: u64 = 8 << 30;

fn bound_address_space(cmd: &mut Command) {
    use std::os::unix::process::CommandExt;
    // SAFETY: setrlimit is async-signal-safe, as pre_exec requires
    unsafe {
        cmd.pre_exec(|| {
            let limit = libc::rlimit { rlim_cur: ADDRESS_SPACE, rlim_max: ADDRESS_SPACE };
            if libc::setrlimit(libc::RLIMIT_AS, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

trait SpawnBounded {
    fn spawn_bounded(&mut self) -> std::io::Result<Child>;
}

impl SpawnBounded for Command {
    fn spawn_bounded(&mut self) -> std::io::Result<Child> {
        bound_address_space(self);
        self.spawn()
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
