//! The coordinator process's own figures for `/metrics`, read from `/proc/self` at each scrape
//! (Linux; elsewhere none are reported): CPU seconds, resident memory, open descriptors and
//! start time, under the names Prometheus clients use (`process_*`).

/// What the process costs right now.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Process {
    /// User plus system CPU time, seconds.
    pub cpu_seconds: f64,
    /// Resident set size, bytes.
    pub resident_bytes: u64,
    /// Open file descriptors.
    pub open_fds: u64,
    /// Start time, seconds since the Unix epoch.
    pub start_time_seconds: f64,
}

/// The figures of this process, `None` where `/proc` cannot be read.
pub fn read() -> Option<Process> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let boot = std::fs::read_to_string("/proc/stat").ok()?;
    // SAFETY: sysconf only reads a configuration value
    let (ticks, page) = unsafe { (libc::sysconf(libc::_SC_CLK_TCK), libc::sysconf(libc::_SC_PAGESIZE)) };
    let open_fds = std::fs::read_dir("/proc/self/fd").ok()?.count() as u64;
    parse(&stat, &boot, ticks as f64, page as u64, open_fds)
}

/// The figures from the texts of `/proc/self/stat` and `/proc/stat`.
fn parse(stat: &str, boot: &str, ticks_per_s: f64, page_bytes: u64, open_fds: u64) -> Option<Process> {
    // the command name (field 2) is in parentheses and may hold spaces: fields count after it
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let field = |n: usize| fields.get(n - 3)?.parse::<u64>().ok();
    let (utime, stime, start, rss) = (field(14)?, field(15)?, field(22)?, field(24)?);
    let boot_time: u64 = boot.lines().find_map(|l| l.strip_prefix("btime "))?.trim().parse().ok()?;
    if ticks_per_s <= 0.0 {
        return None;
    }
    Some(Process {
        cpu_seconds: (utime + stime) as f64 / ticks_per_s,
        resident_bytes: rss * page_bytes,
        open_fds,
        start_time_seconds: boot_time as f64 + start as f64 / ticks_per_s,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stat_fields_count_after_the_command_name() {
        let stat = "4242 (tessera serve) S 1 4242 4242 0 -1 4194560 500 0 0 0 250 50 0 0 20 0 9 0 \
                    1000 123456789 2048 18446744073709551615 1 1 0 0 0 0 0 0 0 0 0 0 17 1 0 0 0 0 0";
        let p = parse(stat, "cpu  1 2 3\nbtime 1700000000\n", 100.0, 4096, 7).unwrap();
        assert_eq!(
            p,
            Process { cpu_seconds: 3.0, resident_bytes: 2048 * 4096, open_fds: 7, start_time_seconds: 1_700_000_010.0 }
        );
        assert!(parse("garbage", "", 100.0, 4096, 0).is_none());
    }

    #[test]
    fn this_process_has_figures() {
        let p = read().expect("/proc is readable on Linux");
        assert!(p.resident_bytes > 0 && p.open_fds > 0 && p.start_time_seconds > 1.6e9, "{p:?}");
    }
}
