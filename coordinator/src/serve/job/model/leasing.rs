//! Leasing in the pure job model: which job's tiles a worker gets, heartbeats, and the two
//! ends of a lease that is not answered: its deadline (no heartbeat within the lease timeout)
//! and its lifetime (heartbeats that go on without a result, bounded by what the job's tiles
//! measurably take), plus the postponement of every lease when the coordinator stalled.

use super::{
    BLOCKLIST_AFTER_FAILURES, Changes, Job, JobState, JobsModel, LeaseRef, PassKind, TileState, fail_tile, host_of,
    join, touch,
};

/// How long a lease may be held, heartbeats or not: `factor` times what the tile should take at
/// the slowest rate measured for its job, never less than `floor_ms`, doubled at each earlier
/// failure of the tile (so a tile that is merely slow everywhere gets there, and a tile that
/// never returns fails its job after [`super::MAX_TILE_FAILURES`] bounded attempts).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeaseLifetime {
    /// The least lifetime, also the lifetime before anything was measured.
    pub floor_ms: u64,
    /// Multiple of the expected render time.
    pub factor: f64,
}

impl LeaseLifetime {
    /// The lifetime of tile `i` of `job`.
    pub fn of(&self, job: &Job, i: usize) -> u64 {
        let tile = &job.tiles[i];
        let expected = job.slowest_ms_per_sample.map_or(0.0, |r| r * tile.spec.pixel_samples() as f64);
        let base = (self.factor * expected).min(u64::MAX as f64 / 64.0) as u64;
        base.max(self.floor_ms).saturating_mul(1 << tile.failures.min(20))
    }
}

impl JobsModel {
    /// Leases up to `max_tiles` queued tiles of the most urgent job `worker` may render
    /// (highest priority, then oldest). Full-frame jobs hand out one tile at a time.
    pub(super) fn lease(
        &mut self,
        worker: &str,
        max_tiles: usize,
        now_ms: u64,
        ttl_ms: u64,
    ) -> (Vec<LeaseRef>, Changes) {
        let mut changes = Changes::new();
        let host = host_of(&self.hosts, worker);
        let candidate = self
            .jobs
            .values()
            .filter(|j| {
                matches!(j.state, JobState::Queued | JobState::Pilot | JobState::Final) && j.paused_ms.is_none()
            })
            .filter(|j| self.upstream_done(j) && self.serves(worker, j))
            .filter(|j| !j.is_blocklisted_on(worker, host))
            .filter(|j| j.index.queued.range(j.leasable()).next().is_some())
            // a sequence's frames share its seq: the earliest frame first
            .max_by_key(|j| {
                let frame = j.spec.frame.as_ref().map_or(0, |f| f.index);
                (j.spec.priority, std::cmp::Reverse(j.seq), std::cmp::Reverse(frame))
            })
            .map(|j| j.id.clone());
        let Some(id) = candidate else { return (Vec::new(), changes) };
        let job = self.jobs.get_mut(&id).expect("invariant: candidate job exists");
        let max = if job.spec.full_frame { 1 } else { max_tiles.max(1) };
        let mut leases = Vec::new();
        let ready: Vec<usize> = job.index.queued.range(job.leasable()).take(max).copied().collect();
        for i in ready {
            let state =
                TileState::Leased { worker: worker.to_string(), deadline_ms: now_ms + ttl_ms, since_ms: now_ms };
            job.set_tile_state(i, state);
            leases.push(LeaseRef { job: id.clone(), tile: i, epoch: job.tiles[i].epoch });
            touch(&mut changes, &id, Some(i));
        }
        if job.state == JobState::Queued {
            job.state = match job.passes().last().map(|p| p.kind) {
                Some(PassKind::Pilot) => JobState::Pilot,
                _ => JobState::Final,
            };
            job.driver.start(now_ms as f64);
            touch(&mut changes, &id, None);
        }
        (leases, changes)
    }

    /// Extends `worker`'s current leases among `leases` to `now_ms + ttl_ms`; returns those
    /// that are not current any more. Deadlines are not persisted (see `service.rs`), so this
    /// reports no changes.
    pub(super) fn heartbeat(&mut self, worker: &str, leases: &[LeaseRef], now_ms: u64, ttl_ms: u64) -> Vec<LeaseRef> {
        let mut lost = Vec::new();
        for lease in leases {
            match self.current_tile(worker, lease) {
                Some((job, i)) => {
                    if let TileState::Leased { deadline_ms, .. } = &mut job.tiles[i].state {
                        *deadline_ms = (*deadline_ms).max(now_ms + ttl_ms);
                    }
                }
                None => lost.push(lease.clone()),
            }
        }
        lost
    }

    /// Returns to the queue, with epoch + 1 and a failure counted against its worker, every
    /// lease whose deadline has passed, and every lease held past its lifetime (see
    /// [`LeaseLifetime`]) however often it was extended: its worker is told so at its next
    /// heartbeat and abandons the tile.
    pub(super) fn expire(&mut self, now_ms: u64, lifetime: &LeaseLifetime) -> Changes {
        let mut changes = Changes::new();
        let hosts = &self.hosts;
        for job in self.jobs.values_mut().filter(|j| !j.state.is_terminal()) {
            for i in job.index.leased.clone() {
                let TileState::Leased { worker, deadline_ms, since_ms } = &job.tiles[i].state else { continue };
                let limit = lifetime.of(job, i);
                let reason = if *deadline_ms <= now_ms {
                    "lease expired (no heartbeat)".to_string()
                } else if now_ms.saturating_sub(*since_ms) >= limit {
                    format!("lease held past its lifetime of {:.1} s", limit as f64 / 1000.0)
                } else {
                    continue;
                };
                let worker = worker.clone();
                fail_tile(job, i, (&worker, host_of(hosts, &worker)), &reason, now_ms);
                touch(&mut changes, &job.id, Some(i));
            }
        }
        changes
    }

    /// Fails the jobs with work left whose every live worker (`live`) with the tags they
    /// require is blocklisted for them: nobody would ever render them. A job no live worker has
    /// the tags for waits for one. Returns the failed jobs.
    pub(super) fn fail_stranded(&mut self, live: &[&str], now_ms: u64) -> (Vec<String>, Changes) {
        let mut changes = Changes::new();
        let stranded: Vec<String> = self
            .jobs
            .values()
            .filter(|j| !j.state.is_terminal() && j.paused_ms.is_none() && !live.is_empty())
            .filter(|j| self.upstream_done(j))
            .filter(|j| !j.index.queued.is_empty())
            // by the workers' own failures: a host blocklisted for workers that registered
            // afresh before each failure (one token holder lying) leaves the job waiting for
            // a worker elsewhere
            .filter(|j| {
                let mut able = live.iter().filter(|w| self.serves(w, j)).peekable();
                able.peek().is_some() && able.all(|w| j.is_blocklisted(w))
            })
            .map(|j| j.id.clone())
            .collect();
        for id in &stranded {
            let able = live.iter().filter(|w| self.serves(w, &self.jobs[id])).count();
            let mut error = format!(
                "no eligible worker is left: each of the {able} live workers failed {BLOCKLIST_AFTER_FAILURES} of its tiles"
            );
            if let Some(last) = &self.jobs[id].last_failure {
                error += &format!("; the last failure: {last}");
            }
            join(&mut changes, self.fail(id, error, now_ms));
        }
        (stranded, changes)
    }

    /// The coordinator itself stalled for `by_ms` (its timer ran that late): nobody could
    /// heartbeat or upload meanwhile, so every lease's clock moves on by as much.
    pub(super) fn postpone_leases(&mut self, by_ms: u64) {
        for job in self.jobs.values_mut().filter(|j| !j.state.is_terminal()) {
            for &i in &job.index.leased {
                if let TileState::Leased { deadline_ms, since_ms, .. } = &mut job.tiles[i].state {
                    *deadline_ms += by_ms;
                    *since_ms += by_ms;
                }
            }
        }
    }

    /// Current leases of `worker` (in jobs that have not ended).
    pub fn leases_of(&self, worker: &str) -> Vec<LeaseRef> {
        let mut out = Vec::new();
        for job in self.jobs.values().filter(|j| !j.state.is_terminal()) {
            for &i in &job.index.leased {
                if matches!(&job.tiles[i].state, TileState::Leased { worker: w, .. } if w == worker) {
                    out.push(LeaseRef { job: job.id.clone(), tile: i, epoch: job.tiles[i].epoch });
                }
            }
        }
        out
    }

    /// How many tiles each worker holds, by worker id (in jobs that have not ended).
    pub fn lease_counts(&self) -> std::collections::HashMap<&str, usize> {
        let mut counts = std::collections::HashMap::new();
        for job in self.jobs.values().filter(|j| !j.state.is_terminal()) {
            for &i in &job.index.leased {
                if let TileState::Leased { worker, .. } = &job.tiles[i].state {
                    *counts.entry(worker.as_str()).or_default() += 1;
                }
            }
        }
        counts
    }
}
