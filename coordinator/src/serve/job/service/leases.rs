//! The calls workers make: registration, leasing, heartbeats, failure reports and result
//! uploads (validated, stored, accepted once for the current epoch, merged in tile order), and
//! the timer's lease expiry.

use super::runtime::JobRuntime;
use super::{Inner, JobService, LeaseGrant, ServiceError};
use crate::serve::job::emis::MergeSpec;
use crate::serve::job::model::{BLOCKLIST_AFTER_FAILURES, LeaseRef, ResultOutcome, TileSpec, TileState};
use crate::serve::job::validate::ResultClaim;
use crate::serve::storage::{Extra, WorkerRow};
use tessera_common::film::Rect;

impl JobService {
    /// Registers a worker; returns its id.
    pub fn register(&self, name: &str, threads: u32, now_ms: u64) -> Result<String, ServiceError> {
        let row = WorkerRow {
            id: uuid::Uuid::new_v4().to_string(),
            name: name.to_string(),
            threads,
            registered_ms: now_ms,
            last_seen_ms: now_ms,
        };
        let mut inner = self.lock();
        self.commits.store().save_worker(&row)?;
        tracing::info!(worker = %row.id, name = %row.name, threads, "worker registered");
        inner.workers.insert(row.id.clone(), row.clone());
        Ok(row.id)
    }

    fn seen(&self, inner: &mut Inner, worker: &str, now_ms: u64) -> Result<(), ServiceError> {
        let w = inner
            .workers
            .get_mut(worker)
            .ok_or_else(|| ServiceError::NotFound(format!("worker {worker} is not registered")))?;
        w.last_seen_ms = now_ms;
        Ok(())
    }

    /// Leases up to `max_tiles` tiles to `worker` (nothing when no work is queued).
    pub fn lease(&self, worker: &str, max_tiles: usize, now_ms: u64) -> Result<Vec<LeaseGrant>, ServiceError> {
        let mut inner = self.lock();
        self.seen(&mut inner, worker, now_ms)?;
        let (leases, changes) = inner.model.lease(worker, max_tiles, now_ms, self.cfg.lease_timeout_ms);
        self.persist(&mut inner, &changes, &[])?;
        let state = &mut *inner;
        let grants = leases
            .into_iter()
            .map(|l| {
                let job = &state.model.jobs[&l.job];
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
        let bytes = tessera_proto::payload::payload_bytes(&job.spec.layout(tile.spec.rect))?;
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
        Ok(inner.model.heartbeat(worker, leases, now_ms, self.cfg.lease_timeout_ms))
    }

    /// Re-queues expired leases, and fails the jobs no live worker may serve any more.
    pub fn expire(&self, now_ms: u64) -> Result<(), ServiceError> {
        let mut inner = self.lock();
        let mut changes = inner.model.expire(now_ms);
        if !changes.is_empty() {
            inner.counters.leases_expired += changes.values().map(|t| t.len() as u64).sum::<u64>();
            tracing::warn!(tiles = changes.values().map(|t| t.len()).sum::<usize>(), "leases expired");
        }
        let stranded = self.stranded_jobs(&inner, now_ms);
        for (job, error) in &stranded {
            tracing::error!(job_id = %job, %error, "job failed");
            for (j, tiles) in inner.model.fail(job, error.clone(), now_ms) {
                changes.entry(j).or_default().extend(tiles);
            }
        }
        if !changes.is_empty() {
            self.persist(&mut inner, &changes, &[])?;
            self.sync(&inner)?;
            for (job, _) in &stranded {
                inner.job(job).end();
            }
            self.work.notify_waiters();
        }
        Ok(())
    }

    /// Jobs with work left whose every live worker (seen within a lease timeout) is blocklisted
    /// for them: nobody will ever render them, so they fail with that reason.
    fn stranded_jobs(&self, inner: &Inner, now_ms: u64) -> Vec<(String, String)> {
        let live: Vec<&str> = inner
            .workers
            .values()
            .filter(|w| now_ms.saturating_sub(w.last_seen_ms) <= self.cfg.lease_timeout_ms)
            .map(|w| w.id.as_str())
            .collect();
        if live.is_empty() {
            return Vec::new();
        }
        inner
            .model
            .jobs
            .values()
            .filter(|j| !j.state.is_terminal() && j.tiles.iter().any(|t| t.state == TileState::Queued))
            .filter(|j| live.iter().all(|w| j.is_blocklisted(w)))
            .map(|j| {
                let error = format!(
                    "no eligible worker is left: each of the {} live workers failed {BLOCKLIST_AFTER_FAILURES} of its tiles",
                    live.len()
                );
                (j.id.clone(), error)
            })
            .collect()
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
        let changes = inner.model.report_failure(worker, lease, message, now_ms);
        tracing::warn!(job_id = %lease.job, tile = lease.tile, worker, message, "worker reported a failure");
        self.persist(&mut inner, &changes, &[])?;
        self.sync(&inner)?;
        self.work.notify_waiters();
        Ok(())
    }

    /// An uploaded result: validated, stored, accepted once for the current epoch, merged in
    /// tile order. A refused result re-queues its tile and returns [`ServiceError::InvalidResult`].
    #[tracing::instrument(skip_all, fields(job_id = %lease.job, tile = lease.tile, epoch = lease.epoch, worker))]
    pub fn upload(
        &self,
        worker: &str,
        lease: &LeaseRef,
        claim: &ResultClaim,
        payload: &[u8],
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
            // not current: let the model say whether it is a duplicate or stale
            let mut inner = self.lock();
            let (outcome, _) = inner.model.result(worker, lease, Ok(()), now_ms);
            inner.counters.results_ignored += 1;
            return Ok(outcome);
        };
        let verdict = self.validate(&lease.job, &tile, collect, claim, payload);
        let stored = verdict.as_ref().ok().map(|(accum, _)| Extra::Result {
            job: lease.job.clone(),
            tile: lease.tile,
            epoch: lease.epoch,
            non_finite: accum.non_finite,
            payload: payload.to_vec(),
        });
        let mut inner = self.lock();
        let (outcome, changes) =
            inner.model.result(worker, lease, verdict.as_ref().map(|_| ()).map_err(Clone::clone), now_ms);
        match (&outcome, verdict) {
            (ResultOutcome::Accepted, Ok(result)) => {
                inner.counters.results_accepted += 1;
                inner.job(&lease.job).held.insert(lease.tile, result);
                // the result and its acceptance are committed in the merge's transaction: one
                // commit (one fsync) per result, still before anyone is answered
                let finishing = self.merge_ready(&mut inner, &lease.job, now_ms, changes, stored.into_iter().collect());
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
                self.persist(&mut inner, &changes, &[])?;
                self.sync(&inner)?;
                inner.counters.results_refused += 1;
                tracing::warn!(job_id = %lease.job, tile = lease.tile, worker, reason = %reason, "tile result refused");
                self.work.notify_waiters();
                Err(ServiceError::InvalidResult(reason.clone()))
            }
            _ => {
                self.persist(&mut inner, &changes, &[])?;
                self.sync(&inner)?;
                inner.counters.results_ignored += 1;
                Ok(outcome)
            }
        }
    }
}
