//! `JobService`: the coordinator's only domain API. Each call applies an event to the pure
//! [`JobsModel`], persists what changed (SQLite rows and results, film checkpoints), and only
//! then answers; merging of accepted results into the in-memory films happens here, strictly
//! in tile order. On start-up it rebuilds the model and films from storage and merges again
//! whatever was accepted after the last checkpoint, so a restart resumes every unfinished job.
//!
//! Lease deadlines and heartbeats are not persisted: after a restart every lease that was
//! outstanding gets a fresh deadline, which gives its worker time to upload or heartbeat.
//!
//! Methods are synchronous and may do file IO; async callers run the heavy ones (submit,
//! upload, results) on blocking threads.

use super::emis::{EmisJob, TileStrategy};
use super::model::{Changes, JobSpec, JobState, JobsModel, LeaseRef, ResultOutcome, TileSpec, TileState};
use super::validate::ResultClaim;
use crate::serve::storage::commit::{Committer, Ticket};
use crate::serve::storage::{BlobStore, Extra, JobFiles, Store, StoreError, WorkerRow, sqlite::Batch};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
pub use tessera_common::bundle::Bundle;
use tessera_common::emis::PilotData;
use tessera_common::film::{Film, TileAccum};
use tessera_common::scene::Scene;
use tessera_common::settings::RenderSettings;

pub use super::view::{JobView, StrategyView, WorkerView};
pub use merge::CHECKPOINT_SPACING;
use merge::CheckpointState;

mod merge;

/// Tunables of the service.
#[derive(Clone, Debug)]
pub struct ServiceConfig {
    /// A lease lives this long without a heartbeat.
    pub lease_timeout_ms: u64,
    /// Least time between film checkpoints of a job. The interval also grows with the
    /// checkpoint's cost (see [`CHECKPOINT_SPACING`]); a finished job's outputs replace its last
    /// checkpoint.
    pub checkpoint_interval_ms: u64,
}

/// Why a call failed; `code()` maps it onto the API error table.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ServiceError {
    /// Bad input from the caller: settings, scene, bundle.
    #[error("{0}")]
    InvalidArgument(String),
    /// A tile result failed validation; the tile was re-queued.
    #[error("tile result refused: {0}")]
    InvalidResult(String),
    /// No such job, worker or blob.
    #[error("{0}")]
    NotFound(String),
    /// The request does not fit the current state (e.g. a result before the job is done).
    #[error("{0}")]
    FailedPrecondition(String),
    /// Storage failed.
    #[error("storage: {0}")]
    Storage(#[from] StoreError),
    /// File IO failed.
    #[error("io: {0}")]
    Io(#[from] std::io::Error),
    /// A finished job's outputs could not be written.
    #[error("outputs: {0}")]
    Output(#[from] crate::output::OutputError),
}

/// A leased tile with what a worker needs to render it.
#[derive(Clone, Debug)]
pub struct LeaseGrant {
    /// The lease.
    pub lease: LeaseRef,
    /// What to render.
    pub tile: TileSpec,
    /// The job's description (settings, bundle).
    pub job: JobSpec,
    /// EMIS: the counts to render with.
    pub strategy: Option<TileStrategy>,
}

/// Which finished output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputKind {
    /// The EXR.
    Exr,
    /// The PNG preview.
    Png,
}

/// Counters for `/metrics`.
#[derive(Clone, Debug, Default)]
pub struct Counters {
    /// Results accepted.
    pub results_accepted: u64,
    /// Results refused by validation.
    pub results_refused: u64,
    /// Stale or duplicate results ignored.
    pub results_ignored: u64,
    /// Leases that expired.
    pub leases_expired: u64,
    /// Tiles merged into films.
    pub tiles_merged: u64,
}

struct Inner {
    model: JobsModel,
    /// The last commit ticket handed out (see [`JobService::persist`]).
    ticket: Ticket,
    films: HashMap<String, Film>,
    emis: HashMap<String, EmisJob>,
    /// EMIS decisions of finished jobs (whose state is dropped).
    strategies: HashMap<String, StrategyView>,
    held: HashMap<(String, usize), (TileAccum, Option<PilotData>)>,
    files: HashMap<String, JobFiles>,
    checkpoints: HashMap<String, CheckpointState>,
    workers: BTreeMap<String, WorkerRow>,
    counters: Counters,
}

/// The job service.
pub struct JobService {
    cfg: ServiceConfig,
    blobs: BlobStore,
    scenes_dir: PathBuf,
    inner: Mutex<Inner>,
    commits: Committer,
    /// Signalled when tiles become available (for long-polling workers).
    pub work: tokio::sync::Notify,
    /// Bumped on every job change (for watchers).
    pub changed: tokio::sync::watch::Sender<u64>,
}

impl JobService {
    /// Opens the data directory and resumes every unfinished job.
    pub fn open(data_dir: &Path, cfg: ServiceConfig, now_ms: u64) -> Result<JobService, ServiceError> {
        std::fs::create_dir_all(data_dir)?;
        let store = Store::open(&data_dir.join("tessera.sqlite"))?;
        let blobs = BlobStore::open(&data_dir.join("blobs"))?;
        let mut inner = Inner {
            model: JobsModel::default(),
            ticket: 0,
            films: HashMap::new(),
            emis: HashMap::new(),
            strategies: HashMap::new(),
            held: HashMap::new(),
            files: HashMap::new(),
            checkpoints: HashMap::new(),
            workers: BTreeMap::new(),
            counters: Counters::default(),
        };
        for w in store.load_workers()? {
            inner.workers.insert(w.id.clone(), w);
        }
        let jobs = store.load_jobs(now_ms + cfg.lease_timeout_ms)?;
        let svc_ids: Vec<String> = jobs.iter().map(|(j, _)| j.id.clone()).collect();
        for (job, files) in jobs {
            if !job.state.is_terminal() {
                let (film, emis_bytes) = match &files.checkpoint {
                    Some(name) => blobs.get_checkpoint(name)?,
                    None => (Film::new(job.spec.width, job.spec.height), Vec::new()),
                };
                inner.films.insert(job.id.clone(), film);
                let emis = match emis_bytes.is_empty() {
                    true => EmisJob::new(&job.spec),
                    false => Some(EmisJob::restore(&job.spec, &emis_bytes).map_err(|e| {
                        ServiceError::Io(std::io::Error::other(format!("EMIS checkpoint of job {}: {e}", job.id)))
                    })?),
                };
                if let Some(e) = emis {
                    inner.emis.insert(job.id.clone(), e);
                }
            }
            inner.files.insert(job.id.clone(), files);
            inner.model.restore(job);
        }
        let svc = JobService {
            cfg,
            blobs,
            scenes_dir: data_dir.join("scenes"),
            inner: Mutex::new(inner),
            commits: Committer::new(store),
            work: tokio::sync::Notify::new(),
            changed: tokio::sync::watch::channel(0).0,
        };
        {
            for id in svc_ids {
                // accepted tiles after the checkpoint first: an update must see the whole
                // pass (merging the pass's last tile runs its barrier, and the update, again)
                let finishing = svc.merge_ready(&mut svc.lock(), &id, now_ms, Changes::new(), Vec::new())?;
                if let Some(f) = finishing {
                    svc.finish(f)?;
                }
                if svc.lock().model.jobs[&id].state == JobState::Optimizing {
                    // stopped between a barrier and its update, with the pass in the
                    // checkpoint: run the update now
                    svc.optimize(&mut svc.lock(), &id, now_ms)?;
                }
            }
            let ticket = svc.lock().ticket;
            svc.commits.wait(ticket)?;
        }
        Ok(svc)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        // a panic while holding the lock leaves a model that was persisted transition by
        // transition, so carrying on with it is safe
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Queues what changed for the database (in the order of the transitions, since the caller
    /// holds the lock). It is durable once [`JobService::sync`] or `commits.wait(inner.ticket)`
    /// returns: every public method does one of the two before it answers.
    fn persist(&self, inner: &mut Inner, changes: &Changes, extras: &[Extra]) -> Result<(), ServiceError> {
        if changes.is_empty() && extras.is_empty() {
            return Ok(());
        }
        inner.ticket = self.commits.enqueue(Batch::of(&inner.model, changes, extras));
        self.changed.send_modify(|v| *v += 1);
        Ok(())
    }

    /// Waits, holding the lock, until everything queued so far is committed (the calls off the
    /// hot path; `upload` and `lease` wait after releasing the lock, so their commits group).
    fn sync(&self, inner: &Inner) -> Result<(), ServiceError> {
        Ok(self.commits.wait(inner.ticket)?)
    }

    /// Validates and stores a scene bundle and settings, and queues the job.
    #[tracing::instrument(skip_all, fields(scene = %bundle.scene_path))]
    pub fn submit(
        &self,
        bundle: Bundle,
        settings: RenderSettings,
        priority: i32,
        name: Option<String>,
        now_ms: u64,
    ) -> Result<JobView, ServiceError> {
        settings.validate().map_err(|e| ServiceError::InvalidArgument(e.to_string()))?;
        let (digest, scene) = self.store_bundle(&bundle, &settings)?;
        let integrator_settings = settings.resolved(&scene);
        integrator_settings.make_renderer(&scene).map_err(|e| ServiceError::InvalidArgument(e.to_string()))?;
        let spec = JobSpec {
            name: name.filter(|n| !n.is_empty()).unwrap_or_else(|| default_name(&bundle.scene_path)),
            priority,
            full_frame: integrator_settings.integrator.full_frame(),
            settings: integrator_settings,
            width: scene.camera.width,
            height: scene.camera.height,
            bundle_digest: digest,
            scene_path: bundle.scene_path.clone(),
        };
        let id = uuid::Uuid::new_v4().to_string();
        let mut inner = self.lock();
        let changes =
            inner.model.submit(&id, spec.clone(), now_ms).map_err(|e| ServiceError::Io(std::io::Error::other(e)))?;
        inner.films.insert(id.clone(), Film::new(spec.width, spec.height));
        if let Some(e) = EmisJob::new(&spec) {
            inner.emis.insert(id.clone(), e);
        }
        self.persist(&mut inner, &changes, &[])?;
        self.sync(&inner)?;
        tracing::info!(job_id = %id, integrator = %spec.settings.integrator, "job submitted");
        self.work.notify_waiters();
        Ok(self.view(&inner, &id, now_ms))
    }

    /// Stores the bundle blob, unpacks it and loads the scene from it to validate it. Scene
    /// errors name the file inside the bundle, its line and column.
    fn store_bundle(&self, bundle: &Bundle, settings: &RenderSettings) -> Result<(String, Scene), ServiceError> {
        let invalid = ServiceError::InvalidArgument;
        if tessera_common::bundle::safe_relative_path(&bundle.scene_path).is_none() {
            return Err(invalid(format!("bundle scene path \"{}\" is not a relative path", bundle.scene_path)));
        }
        if !bundle.files.iter().any(|(p, _)| *p == bundle.scene_path) {
            return Err(invalid(format!("bundle has no file \"{}\" (the scene)", bundle.scene_path)));
        }
        for (path, _) in &bundle.files {
            if tessera_common::bundle::safe_relative_path(path).is_none() {
                return Err(invalid(format!("bundle file path \"{path}\" must be relative without \"..\"")));
            }
        }
        let digest = self.blobs.put(&tessera_proto::bundle::encode(bundle))?;
        let dir = self.scenes_dir.join(&digest);
        if !dir.exists() {
            let tmp = self.scenes_dir.join(format!("{digest}.{}", uuid::Uuid::new_v4()));
            for (path, data) in &bundle.files {
                let p = tmp.join(tessera_common::bundle::safe_relative_path(path).expect("invariant: checked above"));
                std::fs::create_dir_all(p.parent().expect("invariant: joined path has a parent"))?;
                std::fs::write(&p, data)?;
            }
            if std::fs::rename(&tmp, &dir).is_err() {
                // another submission unpacked the same bundle first
                let _ = std::fs::remove_dir_all(&tmp);
            }
        }
        let scene = Scene::load_with(&dir.join(&bundle.scene_path), &settings.define_map()).map_err(|e| {
            let prefix = format!("{}/", dir.display());
            invalid(e.to_string().replace(&prefix, ""))
        })?;
        Ok((digest, scene))
    }

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
                let strategy = match state.emis.get_mut(&l.job) {
                    Some(e) => Some(e.strategy(&self.blobs, job.collects(l.tile))?),
                    None => None,
                };
                Ok(LeaseGrant { tile: job.tiles[l.tile].spec.clone(), job: job.spec.clone(), lease: l, strategy })
            })
            .collect::<Result<Vec<_>, ServiceError>>()?;
        let ticket = inner.ticket;
        drop(inner);
        self.commits.wait(ticket)?;
        Ok(grants)
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

    /// Re-queues expired leases.
    pub fn expire(&self, now_ms: u64) -> Result<(), ServiceError> {
        let mut inner = self.lock();
        let changes = inner.model.expire(now_ms);
        if !changes.is_empty() {
            inner.counters.leases_expired += changes.values().map(|t| t.len() as u64).sum::<u64>();
            tracing::warn!(tiles = changes.values().map(|t| t.len()).sum::<usize>(), "leases expired");
            self.persist(&mut inner, &changes, &[])?;
            self.sync(&inner)?;
            self.work.notify_waiters();
        }
        Ok(())
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
                inner.held.insert((lease.job.clone(), lease.tile), result);
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

    /// A job's view with its EMIS decisions (kept after the job ends).
    fn view(&self, inner: &Inner, job: &str, now_ms: u64) -> JobView {
        let mut view = JobView::of(&inner.model.jobs[job], now_ms);
        view.strategy = match inner.emis.get(job) {
            Some(e) => e.view(),
            None => inner.strategies.get(job).cloned(),
        };
        view
    }

    /// Cancels a job.
    pub fn cancel(&self, job: &str, now_ms: u64) -> Result<JobView, ServiceError> {
        let mut inner = self.lock();
        let changes = inner.model.cancel(job, now_ms).map_err(|e| ServiceError::NotFound(e.to_string()))?;
        self.persist(&mut inner, &changes, &[])?;
        self.sync(&inner)?;
        inner.films.remove(job);
        if let Some(view) = inner.emis.remove(job).and_then(|e| e.view()) {
            inner.strategies.insert(job.to_string(), view);
        }
        tracing::info!(job_id = %job, "job cancelled");
        Ok(self.view(&inner, job, now_ms))
    }

    /// One job.
    ///
    /// Answered only once everything the view shows is committed (uploads are answered after
    /// their commit but become visible before it), so a client never sees progress that a
    /// crash could take back.
    pub fn get(&self, job: &str, now_ms: u64) -> Result<JobView, ServiceError> {
        let inner = self.lock();
        let j = inner.model.jobs.get(job).ok_or_else(|| ServiceError::NotFound(format!("job {job} not found")))?;
        let view = self.view(&inner, &j.id, now_ms);
        let ticket = inner.ticket;
        drop(inner);
        self.commits.wait(ticket)?;
        Ok(view)
    }

    /// Every job, newest first (committed state, as [`JobService::get`]).
    pub fn list(&self, now_ms: u64) -> Result<Vec<JobView>, ServiceError> {
        let inner = self.lock();
        let mut jobs: Vec<_> = inner.model.jobs.values().collect();
        jobs.sort_by_key(|j| std::cmp::Reverse(j.seq));
        let views = jobs.into_iter().map(|j| self.view(&inner, &j.id, now_ms)).collect();
        let ticket = inner.ticket;
        drop(inner);
        self.commits.wait(ticket)?;
        Ok(views)
    }

    /// A finished job's EXR or PNG.
    pub fn output(&self, job: &str, kind: OutputKind) -> Result<Vec<u8>, ServiceError> {
        let digest = {
            let inner = self.lock();
            let j = inner.model.jobs.get(job).ok_or_else(|| ServiceError::NotFound(format!("job {job} not found")))?;
            if j.state != JobState::Done {
                return Err(ServiceError::FailedPrecondition(format!("job {job} is {}, not done", j.state.as_str())));
            }
            let files = inner.files.get(job).cloned().unwrap_or_default();
            match kind {
                OutputKind::Exr => files.result_exr,
                OutputKind::Png => files.preview_png,
            }
        };
        let digest = digest.ok_or_else(|| ServiceError::NotFound(format!("job {job} has no stored result")))?;
        self.blob(&digest)
    }

    /// A content-addressed blob.
    pub fn blob(&self, digest: &str) -> Result<Vec<u8>, ServiceError> {
        self.blobs.get(digest)?.ok_or_else(|| ServiceError::NotFound(format!("blob {digest} not found")))
    }

    /// Registered workers with their current leases.
    pub fn workers(&self, now_ms: u64) -> Vec<WorkerView> {
        let inner = self.lock();
        inner
            .workers
            .values()
            .map(|w| WorkerView {
                id: w.id.clone(),
                name: w.name.clone(),
                threads: w.threads,
                last_seen_s_ago: now_ms.saturating_sub(w.last_seen_ms) as f64 / 1000.0,
                leases: inner.model.leases_of(&w.id).len(),
            })
            .collect()
    }

    /// Counters and gauges for `/metrics`: (counters, jobs per state, queued tiles, leased tiles).
    pub fn metrics(&self) -> (Counters, BTreeMap<&'static str, usize>, usize, usize) {
        let inner = self.lock();
        let mut states = BTreeMap::new();
        let (mut queued, mut leased) = (0, 0);
        for j in inner.model.jobs.values() {
            *states.entry(j.state.as_str()).or_default() += 1;
            if !j.state.is_terminal() {
                queued += j.tiles.iter().filter(|t| t.state == TileState::Queued).count();
                leased += j.tiles.iter().filter(|t| matches!(t.state, TileState::Leased { .. })).count();
            }
        }
        (inner.counters.clone(), states, queued, leased)
    }

    /// The lease timeout.
    pub fn lease_timeout_ms(&self) -> u64 {
        self.cfg.lease_timeout_ms
    }
}

fn default_name(scene_path: &str) -> String {
    let p = Path::new(scene_path);
    let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or("job");
    match (stem, p.parent().and_then(|d| d.file_name()).and_then(|s| s.to_str())) {
        ("scene", Some(dir)) => dir.to_string(),
        _ => stem.to_string(),
    }
}
