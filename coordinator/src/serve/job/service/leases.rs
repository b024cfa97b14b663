//! The calls workers make: registration, leasing, heartbeats, failure reports and result
//! uploads (validated, stored, accepted once for the current epoch, merged in tile order), and
//! the timer's lease expiry.

use super::runtime::JobRuntime;
use super::{Inner, JobService, LeaseGrant, ServiceError};
use crate::serve::job::emis::MergeSpec;
use crate::serve::job::model::{Effects, Event, LeaseRef, ResultOutcome, TileSpec, TileState};
use crate::serve::job::spec::check_tags;
use crate::serve::job::validate::ResultClaim;
use crate::serve::storage::{Extra, WorkerMode, WorkerRow};
use std::collections::HashMap;
use tessera_common::film::Rect;

impl JobService {
    /// Registers a worker; returns its id. A worker that keeps its identity (`identity`: id
    /// and secret) gets the same id back after a restart, with its failures and blocklists;
    /// the leases its earlier process held are lost with it and go back to the queue now,
    /// each counted as a failure, as their expiry would have. An id registered with another
    /// secret is refused.
    pub fn register(
        &self,
        name: &str,
        threads: u32,
        tags: &[String],
        identity: Option<(&str, &str)>,
        peer: Option<std::net::IpAddr>,
        now_ms: u64,
    ) -> Result<String, ServiceError> {
        check_registration(name, threads)?;
        check_tags("tags", tags).map_err(ServiceError::InvalidArgument)?;
        let mut inner = self.lock();
        let (id, secret_sha256) = match identity {
            None => (uuid::Uuid::new_v4().to_string(), None),
            Some((id, secret)) => {
                check_identity(id, secret)?;
                let hash = hex::encode(<sha2::Sha256 as sha2::Digest>::digest(secret.as_bytes()));
                if let Some(known) = inner.workers.get(id)
                    && known.secret_sha256.as_deref() != Some(hash.as_str())
                {
                    return Err(ServiceError::FailedPrecondition(format!(
                        "worker id {id} is registered with another secret: give each worker its own --cache-dir"
                    )));
                }
                (id.to_string(), Some(hash))
            }
        };
        if !inner.workers.contains_key(&id) && inner.workers.len() >= self.cfg.max_workers {
            return Err(ServiceError::ResourceExhausted(format!(
                "this coordinator knows {} workers, its limit (tessera serve --max-workers); silent ones are forgotten after {} s",
                inner.workers.len(),
                self.cfg.forget_workers_ms / 1000
            )));
        }
        // an operator's disable or drain outlives the worker's restarts
        let (registered_ms, mode) =
            inner.workers.get(&id).map_or((now_ms, WorkerMode::Enabled), |w| (w.registered_ms, w.mode));
        let host = peer.map(host_of_address);
        let (name, tags) = (name.to_string(), tags.to_vec());
        let row = WorkerRow { id, name, threads, registered_ms, last_seen_ms: now_ms, secret_sha256, host, tags, mode };
        self.commits.store().save_worker(&row)?;
        let orphaned = inner.model.leases_of(&row.id).len();
        let event = Event::Register { worker: &row.id, host: row.host.clone(), tags: row.tags.clone() };
        let effects = inner.model.apply(event, now_ms)?;
        if !effects.changes.is_empty() {
            tracing::warn!(worker_id = %row.id, tiles = orphaned, "worker restarted: its leases are re-queued");
            self.persist(&mut inner, &effects.changes, &[])?;
            self.sync(&inner)?;
            self.ended(&mut inner, &effects);
            self.work.notify_waiters();
        }
        tracing::info!(worker_id = %row.id, name = %row.name, threads, host = row.host.as_deref().unwrap_or("-"), "worker registered");
        inner.workers.insert(row.id.clone(), row.clone());
        Ok(row.id)
    }

    /// Forgets the workers silent for [`super::ServiceConfig::forget_workers_ms`] that hold no
    /// lease (`held`: leases per worker), so that the workers known stay bounded; one that
    /// comes back registers again.
    fn forget_workers(
        &self,
        inner: &mut Inner,
        held: &HashMap<String, usize>,
        now_ms: u64,
    ) -> Result<(), ServiceError> {
        let silent: Vec<String> = inner
            .workers
            .values()
            .filter(|w| now_ms.saturating_sub(w.last_seen_ms) > self.cfg.forget_workers_ms && !held.contains_key(&w.id))
            .map(|w| w.id.clone())
            .collect();
        for id in silent {
            self.commits.store().delete_worker(&id)?;
            inner.workers.remove(&id);
            inner.model.apply(Event::Forget { worker: &id }, now_ms)?;
            tracing::info!(worker_id = %id, "worker forgotten: silent too long");
        }
        Ok(())
    }

    fn seen(&self, inner: &mut Inner, worker: &str, now_ms: u64) -> Result<(), ServiceError> {
        let w = inner
            .workers
            .get_mut(worker)
            .ok_or_else(|| ServiceError::NotFound(format!("worker {worker} is not registered")))?;
        let silent_ms = now_ms.saturating_sub(w.last_seen_ms);
        if silent_ms > self.cfg.lease_timeout_ms {
            // logged as lost by the expiry timer (or silent since before a restart)
            tracing::info!(worker_id = %worker, silent_ms, "worker back");
        }
        w.last_seen_ms = now_ms;
        Ok(())
    }

    /// Leases up to `max_tiles` tiles to `worker` (nothing when no work is queued).
    pub fn lease(&self, worker: &str, max_tiles: usize, now_ms: u64) -> Result<Vec<LeaseGrant>, ServiceError> {
        let mut inner = self.lock();
        self.seen(&mut inner, worker, now_ms)?;
        if inner.workers.get(worker).is_some_and(|w| w.mode != WorkerMode::Enabled) {
            // disabled or draining by an operator: what it holds it finishes
            return Ok(Vec::new());
        }
        if self.disk.refusal().is_some() {
            // no new work below the reserve: what is leased already may still come back
            return Ok(Vec::new());
        }
        let ttl_ms = self.cfg.lease_timeout_ms;
        let effects = inner.model.apply(Event::Lease { worker, max_tiles, ttl_ms }, now_ms)?;
        if let Some(l) = effects.leases().next() {
            // an EMIS job's state is made at its first lease (all leases are of one job)
            let job = l.job.clone();
            inner.emis(&job, &self.blobs);
        }
        self.persist(&mut inner, &effects.changes, &[])?;
        let state = &mut *inner;
        let grants = effects
            .leases()
            .cloned()
            .map(|l| {
                let job = state.model.jobs.get(&l.job).expect("invariant: a job just leased from exists");
                let runtime = state.jobs.get_mut(&l.job);
                let strategy = match runtime {
                    Some(JobRuntime { emis: Some(e), masks, .. }) => {
                        let s = e.strategy(&self.blobs, job.collects(l.tile))?;
                        if let MergeSpec::Mask(digest) = &s.merge {
                            masks.insert(digest.clone());
                        }
                        Some(s)
                    }
                    _ => None,
                };
                Ok(LeaseGrant { tile: job.tiles[l.tile].spec.clone(), job: job.spec.clone(), lease: l, strategy })
            })
            .collect::<Result<Vec<_>, ServiceError>>()?;
        let ticket = inner.ticket;
        drop(inner);
        self.commits.wait(ticket)?;
        Ok(grants)
    }

    /// What an upload for `lease` by `worker` may carry, checked before a byte of it is
    /// buffered: the leased tile's rectangle and the size of its image sums (the rectangle, the
    /// filter's border and channels). `None` when the lease is unknown, of another epoch, or
    /// held by another worker: such an upload is stale whatever it holds.
    pub fn upload_limit(&self, worker: &str, lease: &LeaseRef) -> Option<(Rect, usize)> {
        let inner = self.lock();
        let job = inner.model.jobs.get(&lease.job)?;
        let tile = job.tiles.get(lease.tile).filter(|t| t.epoch == lease.epoch)?;
        if matches!(&tile.state, TileState::Leased { worker: holder, .. } if holder != worker) {
            return None;
        }
        let bytes = tessera_link::payload::payload_bytes(&job.spec.layout(tile.spec.rect))?;
        Some((tile.spec.rect, bytes))
    }

    /// The tile a lease refers to.
    pub fn lease_spec(&self, lease: &LeaseRef) -> Option<TileSpec> {
        let inner = self.lock();
        inner.model.jobs.get(&lease.job).and_then(|j| j.tiles.get(lease.tile)).map(|t| t.spec.clone())
    }

    /// Extends `worker`'s leases; returns those that are no longer current.
    pub fn heartbeat(&self, worker: &str, leases: &[LeaseRef], now_ms: u64) -> Result<Vec<LeaseRef>, ServiceError> {
        let mut inner = self.lock();
        self.seen(&mut inner, worker, now_ms)?;
        let ttl_ms = self.cfg.lease_timeout_ms;
        Ok(inner.model.apply(Event::Heartbeat { worker, leases, ttl_ms }, now_ms)?.leases().cloned().collect())
    }

    /// Re-queues expired leases, and fails the jobs no live worker may serve any more. The
    /// timer calls this every [`JobService::expiry_period_ms`]; when it ran much later than
    /// that, the coordinator itself stalled (suspended, starved, a long lock), and the stall
    /// is not held against the workers: every lease's clock moves on by it first.
    pub fn expire(&self, now_ms: u64) -> Result<(), ServiceError> {
        let mut inner = self.lock();
        let period = self.expiry_period_ms();
        let previous_ms = inner.last_expiry_ms;
        let late = now_ms.saturating_sub(previous_ms.unwrap_or(now_ms)).saturating_sub(period);
        inner.last_expiry_ms = Some(now_ms);
        let stalled_ms = if late > period.max(self.cfg.lease_timeout_ms / 4) { late } else { 0 };
        if stalled_ms > 0 {
            tracing::warn!(stalled_ms, "the coordinator stalled: leases postponed");
            inner.counters.stalls += 1;
        }
        let held: HashMap<String, usize> =
            inner.model.lease_counts().into_iter().map(|(w, n)| (w.to_string(), n)).collect();
        let mut effects = inner.model.apply(Event::Expire { lifetime: self.cfg.lease_lifetime, stalled_ms }, now_ms)?;
        if !effects.changes.is_empty() {
            inner.counters.leases_expired += effects.changes.values().map(|t| t.len() as u64).sum::<u64>();
            super::events::leases_expired(&held, &inner.model.lease_counts());
        }
        if let Some(previous_ms) = previous_ms {
            super::events::workers_lost(inner.workers.values(), &held, previous_ms, now_ms, self.cfg.lease_timeout_ms);
        }
        self.forget_workers(&mut inner, &held, now_ms)?;
        let live: Vec<String> = inner
            .workers
            .values()
            .filter(|w| now_ms.saturating_sub(w.last_seen_ms) <= self.cfg.lease_timeout_ms)
            .map(|w| w.id.clone())
            .collect();
        if !live.is_empty() {
            let live: Vec<&str> = live.iter().map(String::as_str).collect();
            effects.extend(inner.model.apply(Event::Strand { live: &live }, now_ms)?);
        }
        if !effects.changes.is_empty() {
            self.persist(&mut inner, &effects.changes, &[])?;
            self.sync(&inner)?;
            self.ended(&mut inner, &effects);
            self.work.notify_waiters();
        }
        Ok(())
    }

    /// How often the timer should call [`JobService::expire`].
    pub fn expiry_period_ms(&self) -> u64 {
        (self.cfg.lease_timeout_ms / 4).clamp(50, 1000)
    }

    /// A worker's failure to render a lease.
    pub fn report_failure(
        &self,
        worker: &str,
        lease: &LeaseRef,
        message: &str,
        now_ms: u64,
    ) -> Result<(), ServiceError> {
        let mut inner = self.lock();
        let effects = inner.model.apply(Event::Failure { worker, lease, message }, now_ms)?;
        inner.counters.tile_failures += 1;
        tracing::warn!(job_id = %lease.job, tile = lease.tile, worker_id = worker, message, "worker reported a failure");
        self.persist(&mut inner, &effects.changes, &[])?;
        self.sync(&inner)?;
        self.ended(&mut inner, &effects);
        self.work.notify_waiters();
        Ok(())
    }

    /// An uploaded result: validated, stored, accepted once for the current epoch, merged in
    /// tile order. A refused result re-queues its tile and returns [`ServiceError::InvalidResult`].
    #[tracing::instrument(skip_all, fields(job_id = %lease.job, tile = lease.tile, epoch = lease.epoch, worker_id = worker))]
    pub fn upload(
        &self,
        worker: &str,
        lease: &LeaseRef,
        claim: &ResultClaim,
        payload: Vec<u8>,
        now_ms: u64,
    ) -> Result<ResultOutcome, ServiceError> {
        let tile = {
            let inner = self.lock();
            let job = inner.model.jobs.get(&lease.job);
            let current = job.and_then(|j| j.tiles.get(lease.tile)).filter(|t| {
                t.epoch == lease.epoch && matches!(&t.state, TileState::Leased { worker: w, .. } if w == worker)
            });
            current.map(|t| (t.spec.clone(), job.is_some_and(|j| j.collects(lease.tile))))
        };
        let Some((tile, collect)) = tile else {
            // not current: let the model say whether it is a duplicate or stale; a duplicate
            // is answered once the acceptance it repeats is saved (it may still be queued)
            let mut inner = self.lock();
            let outcome = result_outcome(&inner.model.apply(Event::Result { worker, lease, verdict: Ok(()) }, now_ms)?);
            inner.counters.results_ignored += 1;
            let ticket = inner.ticket;
            drop(inner);
            if outcome == ResultOutcome::Duplicate {
                self.commits.wait(ticket)?;
            }
            return Ok(outcome);
        };
        let verdict = self.validate(&lease.job, &tile, collect, claim, &payload);
        let mut stored = None;
        let mut in_file = false;
        if let Ok((accum, _)) = &verdict {
            if payload.len() >= self.cfg.result_file_bytes {
                // synced before the acceptance is committed, outside the lock
                self.blobs.put_result(&lease.job, lease.tile, lease.epoch, accum.non_finite, &payload)?;
                in_file = true;
            } else {
                // the payload moves into the row it is stored in, not copied
                stored = Some(Extra::Result {
                    job: lease.job.clone(),
                    tile: lease.tile,
                    epoch: lease.epoch,
                    non_finite: accum.non_finite,
                    payload,
                });
            }
        }
        let mut inner = self.lock();
        let event = Event::Result { worker, lease, verdict: verdict.as_ref().map(|_| ()).map_err(Clone::clone) };
        let effects = inner.model.apply(event, now_ms)?;
        let outcome = result_outcome(&effects);
        if in_file && outcome == ResultOutcome::Stale {
            // the tile moved on to another epoch meanwhile: nothing names this file (a
            // duplicate's file is the accepted one's, the same bytes under the same name)
            if let Err(e) = self.blobs.remove_result(&lease.job, lease.tile, lease.epoch) {
                tracing::warn!(job_id = %lease.job, tile = lease.tile, error = %e, "cannot remove an unused result file");
            }
        }
        match (&outcome, verdict) {
            (ResultOutcome::Accepted, Ok(result)) => {
                inner.counters.results_accepted += 1;
                let runtime = inner.job(&lease.job);
                runtime.held.insert(lease.tile, result);
                runtime.result_files |= in_file;
                // the result and its acceptance are committed in the merge's transaction: one
                // commit (one fsync) per result, still before anyone is answered
                let finishing = self.merge_ready(&mut inner, effects, stored.into_iter().collect(), now_ms);
                let ticket = inner.ticket;
                drop(inner);
                // outside the lock, so that concurrent uploads share a commit
                self.commits.wait(ticket)?;
                if let Some(f) = finishing? {
                    self.finish(f)?;
                }
                Ok(outcome)
            }
            (ResultOutcome::Refused(reason), _) => {
                self.persist(&mut inner, &effects.changes, &[])?;
                self.sync(&inner)?;
                inner.counters.results_refused += 1;
                tracing::warn!(job_id = %lease.job, tile = lease.tile, worker_id = worker, reason = %reason, "tile result refused");
                self.ended(&mut inner, &effects);
                self.work.notify_waiters();
                Err(ServiceError::InvalidResult(reason.clone()))
            }
            _ => {
                self.persist(&mut inner, &effects.changes, &[])?;
                self.sync(&inner)?;
                inner.counters.results_ignored += 1;
                Ok(outcome)
            }
        }
    }
}

/// What became of a result ([`Event::Result`] always says).
fn result_outcome(effects: &Effects) -> ResultOutcome {
    effects.outcome().cloned().expect("invariant: a result event has an outcome")
}

/// The host a peer address stands for: an IPv4 address, or an IPv6 /64 (one host's share of
/// addresses), as the connection limits count peers.
fn host_of_address(ip: std::net::IpAddr) -> String {
    match ip.to_canonical() {
        std::net::IpAddr::V4(v4) => v4.to_string(),
        std::net::IpAddr::V6(v6) => {
            let s = v6.segments();
            format!("{:x}:{:x}:{:x}:{:x}::/64", s[0], s[1], s[2], s[3])
        }
    }
}

/// A worker's name is shown on the dashboard and kept in memory: printable and short.
fn check_registration(name: &str, threads: u32) -> Result<(), ServiceError> {
    use super::{MAX_WORKER_NAME_BYTES, MAX_WORKER_THREADS};
    if name.len() > MAX_WORKER_NAME_BYTES || name.chars().any(char::is_control) {
        return Err(ServiceError::InvalidArgument(format!(
            "field \"name\" must be at most {MAX_WORKER_NAME_BYTES} bytes without control characters"
        )));
    }
    if threads > MAX_WORKER_THREADS {
        return Err(ServiceError::InvalidArgument(format!("field \"threads\" must be at most {MAX_WORKER_THREADS}")));
    }
    Ok(())
}

/// A kept identity is a short printable id and a secret long enough not to be guessed.
fn check_identity(id: &str, secret: &str) -> Result<(), ServiceError> {
    let printable = |s: &str| s.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
    if id.is_empty() || id.len() > 64 || !printable(id) {
        return Err(ServiceError::InvalidArgument("worker_id must be 1 to 64 letters, digits, '-' or '_'".to_string()));
    }
    if !(16..=256).contains(&secret.len()) {
        return Err(ServiceError::InvalidArgument("worker_secret must be 16 to 256 bytes".to_string()));
    }
    Ok(())
}
