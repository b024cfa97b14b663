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
//! upload, results) on blocking threads. The calls are grouped by who makes them: clients
//! ([`submit`], [`query`], [`retention`] for deleting ended jobs), workers ([`leases`]), and the
//! merge path ([`merge`]); what the service holds per job is one [`runtime::JobRuntime`].

mod control;
mod events;
mod frames;
mod leases;
mod merge;
mod query;
mod retention;
mod runtime;
mod submit;
mod upload;
mod workers;

use super::emis::{EmisJob, TileStrategy};
pub use super::model::LeaseLifetime;
use super::model::{
    Changes, Effect, Effects, Event, JobSpec, JobState, JobsModel, LeaseRef, TileSpec, TransitionError,
};
use crate::serve::storage::commit::{Committer, Ticket};
use crate::serve::storage::disk::{Disk, Space};
use crate::serve::storage::{BlobStore, Extra, Store, StoreError, WorkerRow, sqlite::Batch};
use runtime::JobRuntime;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use tessera_common::film::Film;

pub use super::view::{JobView, StrategyView, WorkerView};
pub use frames::FramesRequest;
pub use merge::CHECKPOINT_SPACING;
pub use query::{JobFilter, Metrics, OutputKind};
pub use tessera_common::bundle::Bundle;
pub use upload::BundleUpload;

/// Tunables of the service.
#[derive(Clone, Debug)]
pub struct ServiceConfig {
    /// A lease lives this long without a heartbeat.
    pub lease_timeout_ms: u64,
    /// How long a lease may live with heartbeats but no result.
    pub lease_lifetime: LeaseLifetime,
    /// Least time between film checkpoints of a job. The interval also grows with the
    /// checkpoint's cost (see [`CHECKPOINT_SPACING`]); a finished job's outputs replace its last
    /// checkpoint.
    pub checkpoint_interval_ms: u64,
    /// What a submitted scene's decoded textures and meshes may take when the coordinator
    /// loads it (workers load it with their own).
    pub scene_limits: tessera_common::scene::SceneLimits,
    /// What a job's settings may ask of a worker (light paths, connections, memory per tile).
    pub work_limits: tessera_common::settings::WorkLimits,
    /// The largest film a job may have, in pixels: the coordinator holds it (16 bytes a pixel,
    /// more under EMIS) from the job's first run to its end.
    pub max_pixels: u64,
    /// Jobs that ended this long ago are deleted with all their data
    /// ([`JobService::expire_finished`]); `None` keeps them until a client deletes them.
    pub retain_finished_ms: Option<u64>,
    /// The most tiles a job may plan (a full-frame integrator's sample budget plans one per
    /// iteration, each a row in memory and in the database).
    pub max_tiles: u64,
    /// Accepted results of at least this many bytes are stored as files instead of database
    /// rows ([`crate::serve::storage::blobs::RESULT_FILE_BYTES`] outside tests).
    pub result_file_bytes: usize,
    /// The most workers the coordinator knows at once; registrations past it are refused.
    pub max_workers: usize,
    /// Workers silent this long, holding no lease, are forgotten.
    pub forget_workers_ms: u64,
    /// Free bytes kept in reserve on the data folder's disk: below them, submissions and
    /// leases are refused ([`JobService::check_space`]).
    pub min_free_bytes: u64,
}

/// `tessera serve --min-free-space` unless given, in MiB.
pub const DEFAULT_MIN_FREE_SPACE_MIB: u64 = 1024;

/// [`ServiceConfig::max_workers`] unless `tessera serve --max-workers` says otherwise.
pub const DEFAULT_MAX_WORKERS: usize = 10_000;
/// The longest name a worker may register with.
pub const MAX_WORKER_NAME_BYTES: usize = 256;
/// The most render threads a worker may claim.
pub const MAX_WORKER_THREADS: u32 = 1 << 16;

/// [`ServiceConfig::max_tiles`] unless `tessera serve --max-job-tiles` says otherwise.
pub const DEFAULT_MAX_TILES: u64 = 1_000_000;

/// [`ServiceConfig::max_pixels`] unless `tessera serve --max-pixels` says otherwise: 8192².
pub const DEFAULT_MAX_PIXELS: u64 = 8192 * 8192;

impl ServiceError {
    /// The database failed (not one job's data): the service must not go
    /// on as if it had not.
    pub fn is_storage(&self) -> bool {
        matches!(self, ServiceError::Storage(StoreError::Sqlite(_) | StoreError::Commit(_)))
    }
}

/// Why a call failed; the API layer maps each variant onto its error table.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ServiceError {
    /// Bad input from the caller: settings, scene, bundle.
    #[error("{0}")]
    InvalidArgument(String),
    /// An upload (a scene bundle) is over the coordinator's limit.
    #[error("{0}")]
    TooLarge(String),
    /// A bounded resource is in use (too many workers, an upload already running).
    #[error("{0}")]
    ResourceExhausted(String),
    /// The data folder's disk has less free space than the coordinator keeps in reserve.
    #[error("{0}")]
    InsufficientStorage(String),
    /// A tile result failed validation; the tile was re-queued.
    #[error("tile result refused: {0}")]
    InvalidResult(String),
    /// No such job, worker or blob.
    #[error("{0}")]
    NotFound(String),
    /// The request does not fit the current state (e.g. a result before the job is done).
    #[error("{0}")]
    FailedPrecondition(String),
    /// The state machine refused a transition the service asked for.
    #[error("job state: {0}")]
    Transition(#[from] TransitionError),
    /// Stored data (a result, a checkpoint, an EMIS state) does not decode.
    #[error("corrupt {what}: {message}")]
    Corrupt {
        /// What was read.
        what: String,
        /// What is wrong.
        message: String,
    },
    /// A job's EMIS state refused pilot data that had passed validation.
    #[error("EMIS state of job {job}: {message}")]
    Emis {
        /// The job.
        job: String,
        /// What is wrong.
        message: String,
    },
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
    /// Times the expiry timer found the coordinator had stalled (leases postponed).
    pub stalls: u64,
    /// Pixel samples merged into films (its rate is the farm's samples per second).
    pub samples_merged: u64,
    /// Tiles a worker reported it could not render.
    pub tile_failures: u64,
}

struct Inner {
    model: JobsModel,
    /// The last commit ticket handed out (see [`JobService::persist`]).
    ticket: Ticket,
    /// Every job's in-memory state beside the model's, by job id.
    jobs: HashMap<String, JobRuntime>,
    workers: BTreeMap<String, WorkerRow>,
    counters: Counters,
    /// When the expiry timer last ran, to notice the coordinator's own stalls.
    last_expiry_ms: Option<u64>,
}

impl Inner {
    /// The runtime of `job` (created empty on first use).
    fn job(&mut self, job: &str) -> &mut JobRuntime {
        self.jobs.entry(job.to_string()).or_default()
    }

    /// The EMIS state of an unfinished EMIS job, made when first needed (its first lease, or
    /// its first merge after a restart): its moment buffers take hundreds of bytes a pixel,
    /// which queued jobs must not hold. A warm start whose masks cannot be read leaves it
    /// unmade, which fails the job at its first update.
    fn emis(&mut self, job: &str, blobs: &BlobStore) -> Option<&mut EmisJob> {
        let j = self.model.jobs.get(job)?;
        let runtime = self.jobs.entry(job.to_string()).or_default();
        if runtime.emis.is_none() && !j.state.is_terminal() {
            match EmisJob::new(&j.spec, blobs) {
                Ok(emis) => runtime.emis = emis,
                Err(error) => tracing::error!(job_id = %job, %error, "cannot make the EMIS state"),
            }
        }
        runtime.emis.as_mut()
    }
}

/// The job service.
pub struct JobService {
    cfg: ServiceConfig,
    /// The data folder's free space and its reserve.
    disk: Disk,
    blobs: BlobStore,
    scenes_dir: PathBuf,
    inner: Mutex<Inner>,
    /// Bundles being stored by submissions not yet in the model, by digest (with a count):
    /// deleting a job must not take a bundle one of them is about to use.
    submitting: Mutex<HashMap<String, usize>>,
    commits: Committer,
    /// Signalled when tiles become available (for long-polling workers).
    pub work: tokio::sync::Notify,
    /// Bumped on every job change (for watchers).
    pub changed: tokio::sync::watch::Sender<u64>,
}

impl JobService {
    /// Fails when the data folder's disk is below its reserve: no new work is taken then.
    pub fn check_space(&self) -> Result<(), ServiceError> {
        self.disk.refusal().map_or(Ok(()), |why| Err(ServiceError::InsufficientStorage(why)))
    }

    /// The data folder's free space, if it can be read.
    pub fn space(&self) -> Option<Space> {
        self.disk.space()
    }

    /// Opens the data directory and resumes every unfinished job.
    pub fn open(data_dir: &Path, cfg: ServiceConfig, now_ms: u64) -> Result<JobService, ServiceError> {
        std::fs::create_dir_all(data_dir)?;
        let store = Store::open(&data_dir.join("tessera.sqlite"))?;
        let blobs = BlobStore::open(&data_dir.join("blobs"))?;
        let mut inner = Inner {
            model: JobsModel::default(),
            ticket: 0,
            jobs: HashMap::new(),
            workers: BTreeMap::new(),
            counters: Counters::default(),
            last_expiry_ms: None,
        };
        for w in store.load_workers()? {
            if let Some(host) = &w.host {
                inner.model.hosts.insert(w.id.clone(), host.clone());
            }
            if !w.tags.is_empty() {
                inner.model.tags.insert(w.id.clone(), w.tags.iter().cloned().collect());
            }
            inner.workers.insert(w.id.clone(), w);
        }
        // one job that cannot be loaded or resumed fails with its error; the others go on
        let mut broken = Vec::new();
        let mut ids = Vec::new();
        for loaded in store.load_jobs(now_ms + cfg.lease_timeout_ms)? {
            let (job, files) = match loaded {
                Ok(j) => j,
                Err((id, e)) => {
                    let error = format!("cannot load the job after a restart: {e}");
                    tracing::error!(job_id = %id, %error, "job failed");
                    store.mark_failed(&id, &error, now_ms)?;
                    // listed as failed with its error, though its settings are lost
                    inner.model.restore(unreadable_job(&id, error, now_ms));
                    continue;
                }
            };
            let mut runtime = JobRuntime { files, ..JobRuntime::default() };
            // a finished EMIS job's state is gone with its checkpoint: its decisions come back
            // from the report stored with its outputs; a cancelled or failed one's from the
            // head of its last checkpoint
            runtime.decisions = match (&runtime.files.emis_json, &runtime.files.checkpoint) {
                (Some(report), _) => stored_decisions(&blobs, &job.id, report),
                (None, Some(checkpoint))
                    if job.state.is_terminal() && job.spec.settings.integrator.emis_method().is_some() =>
                {
                    checkpoint_decisions(&blobs, &job.id, checkpoint)
                }
                _ => None,
            };
            if !job.state.is_terminal() {
                match restore_running(&blobs, &job.id, &job.spec, &runtime.files) {
                    Ok((film, emis)) => {
                        (runtime.film, runtime.emis) = (film, emis);
                        runtime.result_files = true;
                        ids.push(job.id.clone());
                    }
                    Err(e) => broken.push((job.id.clone(), e)),
                }
            }
            inner.jobs.insert(job.id.clone(), runtime);
            inner.model.restore(job);
        }
        // after their frames' jobs: a sequence planned as many frames as there are
        for s in store.load_sequences()? {
            inner.model.restore_sequence(s);
        }
        let svc = JobService {
            disk: Disk::open(data_dir, cfg.min_free_bytes),
            cfg,
            blobs,
            scenes_dir: data_dir.join("scenes"),
            inner: Mutex::new(inner),
            submitting: Mutex::new(HashMap::new()),
            commits: committer(store),
            work: tokio::sync::Notify::new(),
            changed: tokio::sync::watch::channel(0).0,
        };
        for (id, e) in broken {
            svc.fail_job(&id, &format!("cannot resume the job after a restart: {e}"), now_ms)?;
        }
        for id in ids {
            if let Err(e) = svc.resume(&id, now_ms) {
                if e.is_storage() {
                    return Err(e);
                }
                svc.fail_job(&id, &format!("cannot resume the job after a restart: {e}"), now_ms)?;
            }
        }
        let ticket = svc.lock().ticket;
        svc.commits.wait(ticket)?;
        svc.sweep_orphans()?;
        Ok(svc)
    }

    /// Fails `job` for an error outside the model (its data, its finish, its update): the job
    /// ends with `error`, its memory is freed, and every other job goes on.
    fn fail_job(&self, job: &str, error: &str, now_ms: u64) -> Result<(), ServiceError> {
        let mut inner = self.lock();
        self.fail_locked(&mut inner, job, error, now_ms)?;
        self.sync(&inner)
    }

    /// [`JobService::fail_job`] under the lock (committed with the caller's next wait).
    fn fail_locked(&self, inner: &mut Inner, job: &str, error: &str, now_ms: u64) -> Result<(), ServiceError> {
        let effects = inner.model.apply(Event::Fail { job, error: error.to_string() }, now_ms)?;
        self.persist(inner, &effects.changes, &[])?;
        self.ended(inner, &effects);
        Ok(())
    }

    /// Frees what the jobs that `effects` ended held (a done job's outputs are recorded by
    /// [`JobService::finish`]), says why the failed ones failed, and wakes the workers waiting
    /// for work, which may now go to other jobs.
    fn ended(&self, inner: &mut Inner, effects: &Effects) {
        let mut any = false;
        for (job, state) in effects.ended() {
            if state == JobState::Failed {
                let error = inner.model.jobs.get(job).and_then(|j| j.error.as_deref()).unwrap_or("");
                tracing::error!(job_id = %job, error, "job failed");
            }
            if state != JobState::Done {
                inner.job(job).end();
            }
            any = true;
        }
        if any {
            self.work.notify_waiters();
        }
    }

    /// Brings a job loaded from storage to where it stopped: merges the tiles accepted after
    /// its checkpoint (an update must see the whole pass: merging the pass's last tile runs its
    /// barrier, and the update, again), or runs the update it stopped before.
    fn resume(&self, id: &str, now_ms: u64) -> Result<(), ServiceError> {
        let mut inner = self.lock();
        let effects = inner.model.apply(Event::Restored { job: id }, now_ms)?;
        self.run_restored(inner, id, effects, now_ms)
    }

    /// Runs what a job whose film was just reloaded from its checkpoint asks for (after a
    /// restart or a requeue): merging the tiles accepted since, an update it stopped before, or
    /// the barrier a cancel cut off. `effects`' changes are committed with it.
    fn run_restored(
        &self,
        mut inner: std::sync::MutexGuard<'_, Inner>,
        id: &str,
        effects: Effects,
        now_ms: u64,
    ) -> Result<(), ServiceError> {
        let finishing = match effects.then.first().cloned() {
            Some(Effect::Optimize { iterations, restart_total, .. }) => {
                self.persist(&mut inner, &effects.changes, &[])?;
                return self.optimize(&mut inner, id, iterations, restart_total, now_ms);
            }
            Some(Effect::WriteOutputs { upto, .. }) => {
                self.persist(&mut inner, &effects.changes, &[])?;
                self.finishing(&mut inner, id, upto, now_ms)
            }
            _ => {
                let planned = effects.then.iter().any(|e| matches!(e, Effect::PassPlanned { .. }));
                let finishing = self.merge_ready(&mut inner, effects, Vec::new(), now_ms)?;
                if planned {
                    self.work.notify_waiters();
                }
                finishing
            }
        };
        drop(inner);
        match finishing {
            Some(f) => self.finish(f),
            None => Ok(()),
        }
    }

    /// The full id of the job a client named by its id or a unique prefix of it.
    fn resolve(inner: &Inner, id: &str) -> Result<String, ServiceError> {
        inner.model.resolve(id).map(str::to_string).map_err(retention::refused)
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

    /// Test hook: whether the service holds `job`'s EMIS state (moments, guides).
    #[cfg(test)]
    pub(crate) fn holds_emis_state(&self, job: &str) -> bool {
        self.lock().jobs.get(job).is_some_and(|r| r.emis.is_some())
    }

    /// Test hook: the commit after the next `n` fails.
    #[cfg(test)]
    pub(crate) fn fail_commits_after(&self, n: i64) {
        self.commits.fail_after.store(n, std::sync::atomic::Ordering::Relaxed);
    }

    /// The lease timeout.
    pub fn lease_timeout_ms(&self) -> u64 {
        self.cfg.lease_timeout_ms
    }
}

/// What is shown of a job whose rows do not decode: its id, failed, with the error.
fn unreadable_job(id: &str, error: String, now_ms: u64) -> super::model::Job {
    let spec = JobSpec::bare(id, Default::default(), None, 0, 0);
    super::model::Job {
        id: id.to_string(),
        seq: 0,
        driver: tessera_common::driver::Driver::restore(spec.shape(), Vec::new(), None, 0, |_| 0..0)
            .expect("invariant: no passes tile no tiles"),
        spec,
        state: JobState::Failed,
        tiles: Vec::new(),
        merged: 0,
        worker_failures: BTreeMap::new(),
        last_failure: None,
        error: Some(error),
        created_ms: now_ms,
        finished_ms: Some(now_ms),
        slowest_ms_per_sample: None,
        index: Default::default(),
        paused_ms: None,
        decided: None,
    }
}

/// The commit queue: a failed commit stops the process, but in unit tests, which inject
/// failures and then check what the service answers and what a restart finds.
fn committer(store: Store) -> Committer {
    #[cfg(not(test))]
    return Committer::new(store);
    #[cfg(test)]
    Committer::with_on_failure(store, Box::new(|e| tracing::error!(error = %e, "commit failed (test: not stopping)")))
}

/// The EMIS decisions in a finished job's stored report; a report that cannot be read is
/// logged and the job shown without them (its outputs are still there to download).
fn stored_decisions(blobs: &BlobStore, id: &str, digest: &str) -> Option<StrategyView> {
    let read = match blobs.get(digest) {
        Ok(Some(bytes)) => serde_json::from_slice(&bytes).map_err(|e| e.to_string()),
        Ok(None) => Err("the blob is missing".into()),
        Err(e) => Err(e.to_string()),
    };
    match read {
        Ok(report) => StrategyView::from_report(report),
        Err(error) => {
            tracing::warn!(job_id = %id, blob = %digest, %error, "cannot read the EMIS report of a finished job");
            None
        }
    }
}

/// The EMIS decisions in the checkpoint of a job that ended without outputs, read without its
/// film; a checkpoint that cannot be read is logged and the job shown without them.
fn checkpoint_decisions(blobs: &BlobStore, id: &str, name: &str) -> Option<StrategyView> {
    let read = blobs
        .checkpoint_trailer(name)
        .map_err(|e| e.to_string())
        .and_then(|mut file| tessera_common::emis::EmisState::read_decisions(&mut file));
    match read {
        Ok(d) => Some(StrategyView {
            nu: d.nu,
            connections: d.connections,
            mean_connections: d.reports.last()?.mean_connections,
            mean_merge_probability: d.reports.last()?.mean_merge_probability,
            updates: d.reports,
        }),
        Err(error) => {
            tracing::warn!(job_id = %id, checkpoint = %name, %error, "cannot read the EMIS decisions of an ended job");
            None
        }
    }
}

/// The film and EMIS state of an unfinished job: from its checkpoint, or empty.
fn restore_running(
    blobs: &BlobStore,
    id: &str,
    spec: &JobSpec,
    files: &crate::serve::storage::JobFiles,
) -> Result<(Option<Film>, Option<EmisJob>), ServiceError> {
    // without a checkpoint the film is made when the job's first tiles merge
    let (film, emis_bytes) = match &files.checkpoint {
        Some(name) => blobs.get_checkpoint(name).map(|(film, emis)| (Some(film), emis))?,
        None => (None, Vec::new()),
    };
    // without EMIS bytes the state is made when first needed (`Inner::emis`)
    let emis = match emis_bytes.is_empty() {
        true => None,
        false => Some(
            EmisJob::restore(spec, &emis_bytes)
                .map_err(|message| ServiceError::Corrupt { what: format!("EMIS checkpoint of job {id}"), message })?,
        ),
    };
    Ok((film, emis))
}
