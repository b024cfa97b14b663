//! A real `tessera serve` child process for the farm benchmarks: loopback, ephemeral port,
//! a fresh temporary data directory (removed on drop), optionally pinned to one CPU; its CPU
//! time is read from `/proc/PID/stat`.

use anyhow::{Context, bail};
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};

/// A running coordinator, killed (and its data directory removed) on drop.
pub struct ServeProcess {
    child: Child,
    /// `http://127.0.0.1:PORT`.
    pub url: String,
    /// Its data directory (its log beside it, as `log`).
    folder: tempfile::TempDir,
}

/// A fresh, empty folder under the system temp directory, removed when dropped.
pub fn temp_dir(prefix: &str) -> anyhow::Result<tempfile::TempDir> {
    tempfile::Builder::new().prefix(prefix).tempdir().context("cannot create a temporary folder")
}

/// Restricts the calling thread (and the threads and processes it starts later) to `cpus`.
pub fn pin_current_thread(cpus: &[usize]) -> anyhow::Result<()> {
    // SAFETY: cpu_set_t is plain data; sched_setaffinity only reads it
    let rc = unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        for &c in cpus {
            libc::CPU_SET(c, &mut set);
        }
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
    };
    if rc != 0 {
        bail!("sched_setaffinity failed: {}", std::io::Error::last_os_error());
    }
    Ok(())
}

/// Every CPU of the machine.
pub fn all_cpus() -> Vec<usize> {
    (0..std::thread::available_parallelism().map_or(1, |n| n.get())).collect()
}

impl ServeProcess {
    /// Starts the `tessera` binary that runs this benchmark as `serve`, pinned to `cpu` if given.
    pub fn start(cpu: Option<usize>) -> anyhow::Result<ServeProcess> {
        let exe = std::env::current_exe().context("cannot find the tessera executable")?;
        let folder = temp_dir("tessera-bench-farm")?;
        let log = folder.path().join("log");
        let mut cmd = Command::new(exe);
        cmd.args(["serve", "--listen", "127.0.0.1:0", "--data-dir"])
            .arg(folder.path().join("data"))
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(&log)?);
        if let Some(cpu) = cpu {
            use std::os::unix::process::CommandExt;
            // SAFETY: the closure only makes the async-signal-safe sched_setaffinity system call
            unsafe {
                cmd.pre_exec(move || {
                    let mut set: libc::cpu_set_t = std::mem::zeroed();
                    libc::CPU_SET(cpu, &mut set);
                    if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) != 0 {
                        return Err(std::io::Error::last_os_error());
                    }
                    Ok(())
                });
            }
        }
        let mut child = cmd.spawn().context("cannot start tessera serve")?;
        let mut line = String::new();
        BufReader::new(child.stdout.take().context("invariant: stdout is piped")?).read_line(&mut line)?;
        let Some(url) = line.trim().rsplit(' ').next().filter(|u| u.starts_with("http://")) else {
            let _ = child.kill();
            let log = std::fs::read_to_string(&log).unwrap_or_default();
            bail!("tessera serve did not start: {log}");
        };
        Ok(ServeProcess { url: url.to_string(), child, folder })
    }

    /// Its data directory.
    pub fn data_dir(&self) -> PathBuf {
        self.folder.path().join("data")
    }

    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// User + system CPU seconds the coordinator has used so far.
    pub fn cpu_seconds(&self) -> anyhow::Result<f64> {
        proc_cpu_seconds(self.pid())
    }
}

impl Drop for ServeProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// User + system CPU seconds of process `pid` (fields 14 and 15 of `/proc/PID/stat`).
pub fn proc_cpu_seconds(pid: u32) -> anyhow::Result<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).with_context(|| format!("no process {pid}"))?;
    // the command name (field 2) may hold spaces: count fields after its closing parenthesis
    let rest = stat.rsplit_once(')').map(|(_, r)| r).context("malformed /proc/PID/stat")?;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i).and_then(|v| v.parse::<f64>().ok()).context("malformed /proc/PID/stat");
    // SAFETY: sysconf has no preconditions
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as f64;
    Ok((ticks(11)? + ticks(12)?) / hz)
}
