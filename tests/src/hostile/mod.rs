//! The adversarial suite of issue 67: one case per class of hostile input a client, a worker or
//! a file can send, each against fresh `tessera serve` and `tessera-worker` processes, so that
//! each case's peak memory is its own. A case reports the answer, the time to answer, both
//! processes' peak RSS (`VmHWM`) and whether they survived, and says whether the outcome is
//! the one wanted (refused with a reason, or served within bounded memory). A canary job on a
//! coordinator that took the cheap cases in turn must then equal `tessera render` bit for bit.
//!
//! The binaries are parameters, so the same cases run against an older build for a table side
//! by side (`hostile-suite` binary); the farm test `hostile::adversarial_suite` runs them
//! against this build. Every process runs under an 8 GiB address-space limit, so that an older
//! build's runaway allocation aborts it instead of pushing the machine into the OOM killer.

mod canary;
mod cases;
mod earlier;
mod inputs;
mod net;
mod procs;
mod worker_cases;

pub use procs::Bins;

use std::path::Path;
use std::time::{Duration, Instant};

/// What one case observed.
#[derive(Clone, Debug)]
pub struct Report {
    /// The case.
    pub case: &'static str,
    /// The class of issue 67 it belongs to.
    pub class: &'static str,
    /// What the farm answered (status and the start of its message, or what happened).
    pub answer: String,
    /// Seconds from the first byte sent to the answer.
    pub seconds: f64,
    /// Peak RSS of the coordinator in KiB, and whether it still runs.
    pub coordinator: Peak,
    /// Peak RSS of the worker in KiB, and whether it still runs (`None`: no worker).
    pub worker: Option<Peak>,
    /// The outcome is the wanted one.
    pub passed: bool,
}

/// A process's peak memory and fate.
#[derive(Clone, Copy, Debug)]
pub struct Peak {
    /// `VmHWM` in KiB (0 if it could not be read: the process is gone).
    pub kib: u64,
    /// It was still running when the case ended.
    pub alive: bool,
}

/// Nothing sent may push a process past this.
pub const MAX_RSS_KIB: u64 = 1 << 20;

impl Report {
    /// Both processes survived within [`MAX_RSS_KIB`].
    pub fn survived(&self) -> bool {
        let ok = |p: &Peak| p.alive && p.kib <= MAX_RSS_KIB;
        ok(&self.coordinator) && self.worker.as_ref().is_none_or(ok)
    }

    /// A Markdown table row.
    pub fn row(&self) -> String {
        let peak = |p: &Peak| match (p.alive, p.kib) {
            (true, k) => format!("{:.0} MB", k as f64 / 1024.0),
            (false, 0) => "died".to_string(),
            (false, k) => format!("died ({:.0} MB)", k as f64 / 1024.0),
        };
        let answer = self.answer.replace('|', "/").replace('\n', " ");
        format!(
            "| {} | {} | {} | {:.2} s | {} | {} |",
            self.class,
            self.case,
            answer,
            self.seconds,
            peak(&self.coordinator),
            self.worker.as_ref().map_or("–".to_string(), peak)
        )
    }
}

/// A case: its name, class, and what it does with fresh processes under a scratch folder.
pub struct Case {
    /// Short name (`--case` filter).
    pub name: &'static str,
    /// Issue 67's class.
    pub class: &'static str,
    run: fn(&Bins, &Path) -> Report,
}

/// Every case, in the order.
pub fn cases() -> Vec<Case> {
    let mut all = earlier::all();
    all.extend(cases::all());
    all.extend(net::all());
    all.extend(worker_cases::all());
    all.extend(canary::all());
    all
}

/// Runs the cases whose names contain one of `filter` (all when empty) with `bins`, each in
/// a folder of its own under `scratch`.
pub fn run(bins: &Bins, scratch: &Path, filter: &[String]) -> Vec<Report> {
    raise_fd_limit();
    cases()
        .into_iter()
        .filter(|c| filter.is_empty() || filter.iter().any(|f| c.name.contains(f.as_str())))
        .map(|c| {
            let dir = scratch.join(c.name);
            std::fs::create_dir_all(&dir).expect("scratch folder");
            let report = (c.run)(bins, &dir);
            // TESSERA_SUITE_KEEP keeps the processes' logs and data for a look afterwards
            if std::env::var_os("TESSERA_SUITE_KEEP").is_none() {
                let _ = std::fs::remove_dir_all(&dir);
            }
            report
        })
        .collect()
}

/// The table header for [`Report::row`].
pub const TABLE_HEADER: &str =
    "| class | case | answer | time | coordinator peak | worker peak |\n|---|---|---|---|---|---|";

/// Times `f`.
fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let start = Instant::now();
    let t = f();
    (t, start.elapsed().as_secs_f64())
}

/// A short form of an HTTP answer: the status and the start of its message.
fn answer(status: u16, body: &serde_json::Value) -> String {
    let message = body["error"].as_str().or(body["state"].as_str()).unwrap_or("");
    let short: String = message.chars().take(110).collect();
    format!("{status} {short}")
}

/// How long a case waits for something that should come soon.
const PATIENCE: Duration = Duration::from_secs(60);

/// Raises this process's soft descriptor limit to its hard one: the connection floods open
/// over a thousand sockets.
fn raise_fd_limit() {
    let mut limit = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
    // SAFETY: getrlimit and setrlimit read and write the struct given
    unsafe {
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit) == 0 && limit.rlim_cur < limit.rlim_max {
            limit.rlim_cur = limit.rlim_max;
            libc::setrlimit(libc::RLIMIT_NOFILE, &limit);
        }
    }
}
