//! What a failed lease counts against: the worker, the host it registered from and the tile,
//! with the blocklists and the job failure they lead to, so that no single worker, nor a host
//! registering workers afresh, can fail a job alone.

use super::{Job, JobState, MAX_TILE_FAILURES, TileState};
use std::collections::BTreeMap;

/// A worker that failed this many leases of one job gets no more of its tiles.
pub const BLOCKLIST_AFTER_FAILURES: u32 = 3;
/// A host's failed leases of one job that blocklist every worker on it for the job: twice a
/// worker's, so that one faulty worker does not cut off the others on its host.
pub const HOST_BLOCKLIST_AFTER_FAILURES: u32 = 2 * BLOCKLIST_AFTER_FAILURES;
/// What one host's failures count towards failing a job ([`fail_tile`]): half of what fails
/// it, so that no host alone can fail a job, not even by registering afresh before each lie.
pub const MAX_FAILURES_PER_HOST: u32 = MAX_TILE_FAILURES / 2;

impl Job {
    /// Whether `worker` may lease this job's tiles, its host aside.
    pub fn is_blocklisted(&self, worker: &str) -> bool {
        self.worker_failures.get(worker).is_some_and(|&n| n >= BLOCKLIST_AFTER_FAILURES)
    }

    /// Whether `worker` on `host` may lease this job's tiles: neither it nor its host failed
    /// them too often.
    pub fn is_blocklisted_on(&self, worker: &str, host: &str) -> bool {
        self.is_blocklisted(worker)
            || self.worker_failures.get(&host_key(host)).is_some_and(|&n| n >= HOST_BLOCKLIST_AFTER_FAILURES)
    }

    /// The job's failures that count towards failing it: each host's, at most
    /// [`MAX_FAILURES_PER_HOST`].
    fn failures_counted(&self) -> u32 {
        let hosts = self.worker_failures.iter().filter(|(k, _)| k.starts_with(HOST_PREFIX));
        hosts.map(|(_, &n)| n.min(MAX_FAILURES_PER_HOST)).sum()
    }
}

/// Keys of a job's `worker_failures` that count a host's failures (worker ids never hold it).
const HOST_PREFIX: &str = "@";

fn host_key(host: &str) -> String {
    format!("{HOST_PREFIX}{host}")
}

/// The host `worker` registered from, as the model knows it: a worker of unknown address
/// counts as a host of its own.
pub(super) fn host_of<'a>(hosts: &'a BTreeMap<String, String>, worker: &'a str) -> &'a str {
    hosts.get(worker).map_or(worker, String::as_str)
}

/// Sends tile `i` back to the queue with a new epoch and counts the failure against `worker`
/// and its `host` (blocklisting them for the job after [`BLOCKLIST_AFTER_FAILURES`] and
/// [`HOST_BLOCKLIST_AFTER_FAILURES`]); fails the job when the tile has failed
/// [`MAX_TILE_FAILURES`] times and the job's failures, at most [`MAX_FAILURES_PER_HOST`] a
/// host, add up to as many.
pub(super) fn fail_tile(job: &mut Job, i: usize, (worker, host): (&str, &str), reason: &str, now_ms: u64) {
    job.set_tile_state(i, TileState::Queued);
    let tile = &mut job.tiles[i];
    tile.epoch += 1;
    tile.failures += 1;
    let failures = tile.failures;
    *job.worker_failures.entry(worker.to_string()).or_default() += 1;
    *job.worker_failures.entry(host_key(host)).or_default() += 1;
    job.last_failure = Some(reason.to_string());
    if failures >= MAX_TILE_FAILURES && job.failures_counted() >= MAX_TILE_FAILURES {
        job.error = Some(format!("tile {i} failed {failures} times, last: {reason}"));
        job.finish(JobState::Failed, now_ms);
    }
}
