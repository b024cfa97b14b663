//! The pure, synchronous job state machine: jobs, each wrapping the job driver that
//! `tessera render` runs (`tessera_common::driver`: passes, barriers, pacing, EMIS updates),
//! with its tiles, leases with epochs, exactly-once acceptance of results and the canonical
//! merge order. No IO and no clock: time is passed in. Everything that changes a job goes
//! through [`JobsModel::apply`] (see `event.rs`): the service persists the [`Changes`] it
//! reports before it answers anyone, then runs the [`Effect`]s it asks for.
//!
//! Tile life: `Queued → Leased{worker, deadline} → Accepted → Merged`. A lease that expires,
//! a refused (invalid) result or a reported failure send the tile back to `Queued` with its
//! epoch + 1, so a late answer to the old lease is recognised as stale. Accepted results are
//! merged in tile-index order only (the driver's order, see `tessera_common::driver`), so `tiles[..merged]` is exactly the
//! set of tiles in the film.
//!
//! Job life: `Queued → (Pilot → Optimizing →) Final → Finishing → Done | Failed | Cancelled`,
//! then removed (by a client or the retention sweep, see `retention.rs`).

mod after;
#[cfg(test)]
pub(crate) mod calls;
mod control;
mod error;
mod event;
mod failures;
mod index;
mod leasing;
mod sequence;

pub use super::spec::{JobSpec, TileSpec};
pub use after::Waiting;
pub use error::TransitionError;
pub use event::{Effect, Effects, Event};
pub use failures::{BLOCKLIST_AFTER_FAILURES, HOST_BLOCKLIST_AFTER_FAILURES, MAX_FAILURES_PER_HOST};
use failures::{fail_tile, host_of};
pub use index::TileIndex;
pub use leasing::LeaseLifetime;
pub use sequence::{FRAMES_IN_FLIGHT, FrameRef, Sequence, SequenceSpec};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;
use tessera_common::driver::{Driver, Step};
pub use tessera_common::driver::{Pass, PassKind};

/// The shortest job id prefix that names a job (a uuid has 36 characters).
pub const MIN_ID_PREFIX: usize = 6;

/// A tile that failed this many times fails its job.
pub const MAX_TILE_FAILURES: u32 = 6;

/// Lifecycle state of a job.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JobState {
    /// Accepted, nothing leased yet.
    Queued,
    /// Rendering the pilot pass (EMIS).
    Pilot,
    /// Waiting for the optimiser at a barrier (EMIS).
    Optimizing,
    /// Rendering final passes.
    Final,
    /// Every tile is merged; the outputs are being written (shown as `final`).
    Finishing,
    /// Finished; the result is stored.
    Done,
    /// Stopped by an error.
    Failed,
    /// Stopped by a client.
    Cancelled,
    /// Shown for a job a client paused (the model keeps the state it runs in beside
    /// [`Job::paused_ms`]).
    Paused,
    /// Shown for a queued job that waits for one that failed or was cancelled (see `after.rs`).
    Blocked,
}

impl JobState {
    /// Done, failed or cancelled.
    pub fn is_terminal(self) -> bool {
        matches!(self, JobState::Done | JobState::Failed | JobState::Cancelled)
    }

    /// The state clients see: a finishing job is `final` (see [`JobState::as_str`]).
    pub fn shown(self) -> JobState {
        match self {
            JobState::Finishing => JobState::Final,
            s => s,
        }
    }

    /// Lowercase name, as in JSON. A finishing job is `final` to clients and in storage:
    /// until its outputs are committed it is a final pass whose tiles are all done (after a
    /// restart it merges them again and finishes then).
    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Pilot => "pilot",
            JobState::Optimizing => "optimizing",
            JobState::Final | JobState::Finishing => "final",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
            JobState::Paused => "paused",
            JobState::Blocked => "blocked",
        }
    }
}

/// Where a tile is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum TileState {
    /// Waiting for a worker.
    Queued,
    /// Held by `worker` until `deadline_ms` unless heartbeats extend it, and never much
    /// longer than the job's tiles take (see `leasing.rs`).
    Leased {
        /// The holder.
        worker: String,
        /// Expiry time.
        deadline_ms: u64,
        /// When it was leased (or restored after a restart).
        since_ms: u64,
    },
    /// A valid result is stored and waits for its turn in the merge order.
    Accepted,
    /// In the film.
    Merged,
}

/// One work unit of a job.
#[derive(Clone, Debug, PartialEq)]
pub struct Tile {
    /// What to render.
    pub spec: TileSpec,
    /// Current lease epoch; results for other epochs are stale.
    pub epoch: u64,
    /// Where it is.
    pub state: TileState,
    /// Failed attempts (expired, refused, reported).
    pub failures: u32,
}

/// A job and everything the scheduler knows about it.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    /// Unique id.
    pub id: String,
    /// Submission order, the tie-breaker between equal priorities.
    pub seq: u64,
    /// What to render.
    pub spec: JobSpec,
    /// Lifecycle state.
    pub state: JobState,
    /// Its passes, barriers and pacing, as `tessera render` runs them; the passes' tile
    /// ranges tile `tiles` without gaps.
    pub driver: Driver,
    /// All planned tiles, in merge order.
    pub tiles: Vec<Tile>,
    /// `tiles[..merged]` are in the film.
    pub merged: usize,
    /// Failed leases per worker; reaching [`BLOCKLIST_AFTER_FAILURES`] blocklists the worker.
    pub worker_failures: BTreeMap<String, u32>,
    /// Why a tile last failed, for the error of a job every worker is blocklisted for (kept
    /// in memory only: after a restart the error goes without it).
    pub last_failure: Option<String>,
    /// Why the job failed.
    pub error: Option<String>,
    /// Submission time.
    pub created_ms: u64,
    /// Reaching a terminal state.
    pub finished_ms: Option<u64>,
    /// The slowest rate any accepted result of this job was rendered at, from lease to
    /// result, per pixel sample: what bounds a lease's lifetime. Measured again after a restart.
    pub slowest_ms_per_sample: Option<f64>,
    /// Its queued and leased tiles (derived from `tiles`).
    pub index: TileIndex,
    /// Paused by a client since then: no tile is leased (see `control.rs`).
    pub paused_ms: Option<u64>,
    /// EMIS, a frame of a job of frames that starts each from the one before: the decision
    /// its updates ended on, which the next frame starts from (see `sequence.rs`).
    pub decided: Option<super::spec::WarmStart>,
}

/// Results that arrive ahead of the merge frontier wait in memory: a job leases no further
/// ahead than about this many bytes of them ...
pub const HELD_RESULTS_BYTES: u64 = 512 << 20;
/// ... but always at least this many tiles from the frontier on.
pub const MIN_LEASE_WINDOW: usize = 2;

impl Job {
    /// The tiles that may be leased: from the merge frontier, as many as
    /// [`HELD_RESULTS_BYTES`] of results allows (their image sums, and the moments of a pass
    /// that collects them), at least [`MIN_LEASE_WINDOW`].
    pub fn leasable(&self) -> Range<usize> {
        let Some(next) = self.tiles.get(self.merged) else { return self.merged..self.merged };
        let collect = self.driver.collects(self.merged);
        let per_pixel = 32 + if collect { tessera_proto::MAX_PILOT_BYTES_PER_PIXEL } else { 0 };
        let bytes = (next.spec.rect.area() as u64).max(1) * per_pixel;
        let window = ((HELD_RESULTS_BYTES / bytes) as usize).max(MIN_LEASE_WINDOW);
        self.merged..(self.merged + window).min(self.tiles.len())
    }

    /// Pixel samples merged into the film.
    pub fn samples_merged(&self) -> u64 {
        self.tiles[..self.merged].iter().map(|t| t.spec.pixel_samples()).sum()
    }

    /// Pixel samples planned so far.
    pub fn samples_planned(&self) -> u64 {
        self.tiles.iter().map(|t| t.spec.pixel_samples()).sum()
    }

    /// Samples per pixel merged (the end of the last merged pass's sample range), counting
    /// iterations a restart discarded.
    pub fn spp_merged(&self) -> u32 {
        self.tiles[..self.merged].iter().map(|t| t.spec.samples.end).max().unwrap_or(0)
    }

    /// The planned passes, in order.
    pub fn passes(&self) -> &[Pass] {
        self.driver.passes()
    }

    /// The first lease (the driver's clock starts there).
    pub fn started_ms(&self) -> Option<u64> {
        self.driver.started_ms().map(|t| t as u64)
    }

    /// The first iteration the film keeps (see [`Driver::kept_from`]).
    pub fn kept_from(&self) -> u32 {
        self.driver.kept_from()
    }

    /// Tiles accepted or merged.
    pub fn tiles_done(&self) -> usize {
        self.tiles.len() - self.index.queued.len() - self.index.leased.len()
    }

    /// Whether tile `tile` collects EMIS moments.
    pub fn collects(&self, tile: usize) -> bool {
        self.driver.collects(tile)
    }

    /// Queues the tiles of a pass the driver planned.
    fn add_tiles(&mut self, specs: Vec<TileSpec>) -> Range<usize> {
        let start = self.tiles.len();
        self.tiles.extend(specs.into_iter().map(|spec| Tile { spec, epoch: 0, state: TileState::Queued, failures: 0 }));
        let range = start..self.tiles.len();
        debug_assert_eq!(range.end, self.driver.tiles(), "invariant: the model holds the driver's tiles");
        self.index.queued.extend(range.clone());
        range
    }

    pub(super) fn finish(&mut self, state: JobState, now_ms: u64) {
        self.state = state;
        self.finished_ms = Some(now_ms);
    }
}

/// What a call changed, for the service to persist: per job, the tile indices whose rows
/// changed (the job's own row is always saved for a job listed here).
pub type Changes = BTreeMap<String, BTreeSet<usize>>;

/// Adds `other` to `changes`, joining the tiles of a job both name (a map's own `extend`
/// would keep only `other`'s, and their rows would not be written).
pub fn join(changes: &mut Changes, other: Changes) {
    for (job, tiles) in other {
        changes.entry(job).or_default().extend(tiles);
    }
}

fn touch(changes: &mut Changes, job: &str, tile: Option<usize>) {
    let set = changes.entry(job.to_string()).or_default();
    if let Some(t) = tile {
        set.insert(t);
    }
}

/// What a job's barrier did (see [`JobsModel::merged`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BarrierAction {
    /// It planned the next pass.
    NextPass,
    /// EMIS: an update is due ([`Effect::Optimize`]).
    Optimize,
    /// Nothing left: the job is finishing ([`Effect::WriteOutputs`]).
    Finish,
}

/// Identifies a lease: a tile of a job at an epoch.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct LeaseRef {
    /// The job.
    pub job: String,
    /// Tile index.
    pub tile: usize,
    /// Epoch it was leased at.
    pub epoch: u64,
}

/// What happened to an uploaded result.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ResultOutcome {
    /// Current lease, valid result: stored for merging.
    Accepted,
    /// Already accepted at this epoch.
    Duplicate,
    /// Not the current lease (expired, re-leased, cancelled, unknown).
    Stale,
    /// Current lease, invalid result: refused, tile re-queued.
    Refused(String),
}

/// All jobs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JobsModel {
    /// Jobs by id.
    pub jobs: BTreeMap<String, Job>,
    /// The address each worker registered from: failures count against it as well as against
    /// the worker, so that registering afresh does not escape them.
    pub hosts: BTreeMap<String, String>,
    /// The tags of each worker that has any: a job that requires tags goes only to workers
    /// with all of them.
    pub tags: BTreeMap<String, BTreeSet<String>>,
    /// Jobs of many frames, by id (each frame is a job in `jobs`).
    pub sequences: BTreeMap<String, Sequence>,
}

impl JobsModel {
    /// Whether `worker` has every tag `job` requires.
    pub fn serves(&self, worker: &str, job: &Job) -> bool {
        job.spec.require_tags.iter().all(|t| self.tags.get(worker).is_some_and(|have| have.contains(t)))
    }
}

impl JobsModel {
    /// Adds a job and plans its first pass.
    fn submit(&mut self, id: &str, spec: JobSpec, now_ms: u64) -> Result<Changes, TransitionError> {
        if self.jobs.contains_key(id) {
            return Err(TransitionError::DuplicateJob(id.to_string()));
        }
        let seq = self.next_seq();
        let (driver, first) = Driver::new(spec.shape());
        let mut job = Job {
            id: id.to_string(),
            seq,
            spec,
            state: JobState::Queued,
            driver,
            tiles: Vec::new(),
            merged: 0,
            worker_failures: BTreeMap::new(),
            last_failure: None,
            error: None,
            created_ms: now_ms,
            finished_ms: None,
            slowest_ms_per_sample: None,
            index: TileIndex::default(),
            paused_ms: None,
            decided: None,
        };
        let range = job.add_tiles(first);
        self.jobs.insert(id.to_string(), job);
        let mut changes = Changes::new();
        changes.insert(id.to_string(), range.collect());
        Ok(changes)
    }

    /// The id of the job `id` names: its own id, or a unique prefix of at least
    /// [`MIN_ID_PREFIX`] characters.
    pub fn resolve<'a>(&'a self, id: &str) -> Result<&'a str, TransitionError> {
        if let Some((k, _)) = self.jobs.get_key_value(id) {
            return Ok(k);
        }
        if let Some((k, _)) = self.sequences.get_key_value(id) {
            return Ok(k);
        }
        if id.len() >= MIN_ID_PREFIX {
            // a frame is named by its whole id: a prefix names its sequence
            let sequences = self.sequences.range(id.to_string()..).map(|(k, _)| k).take_while(|k| k.starts_with(id));
            let jobs = self.jobs.range(id.to_string()..).filter(|(_, j)| j.spec.frame.is_none()).map(|(k, _)| k);
            let mut matches = sequences.chain(jobs.take_while(|k| k.starts_with(id)));
            match (matches.next(), matches.count()) {
                (Some(k), 0) => return Ok(k),
                (Some(_), more) => {
                    return Err(TransitionError::AmbiguousPrefix { prefix: id.to_string(), count: more + 1 });
                }
                (None, _) => {}
            }
        }
        Err(TransitionError::UnknownJob(id.to_string()))
    }

    /// Adds a job rebuilt from storage as it was.
    pub fn restore(&mut self, mut job: Job) {
        job.reindex();
        self.jobs.insert(job.id.clone(), job);
    }

    /// The tile a lease refers to, if that lease is still the current one.
    fn current_tile(&mut self, worker: &str, lease: &LeaseRef) -> Option<(&mut Job, usize)> {
        let job = self.jobs.get_mut(&lease.job)?;
        if job.state.is_terminal() {
            return None;
        }
        let tile = job.tiles.get(lease.tile)?;
        let held = matches!(&tile.state, TileState::Leased { worker: w, .. } if w == worker);
        (held && tile.epoch == lease.epoch).then_some((job, lease.tile))
    }

    /// Applies an uploaded result. `verdict` is the validation of its buffers (done outside
    /// this model): `Err(reason)` refuses it. Only the current lease's first result counts.
    fn result(
        &mut self,
        worker: &str,
        lease: &LeaseRef,
        verdict: Result<(), String>,
        now_ms: u64,
    ) -> (ResultOutcome, Changes) {
        let mut changes = Changes::new();
        let host = host_of(&self.hosts, worker).to_string();
        let Some((job, i)) = self.current_tile(worker, lease) else {
            let duplicate =
                self.jobs.get(&lease.job).and_then(|j| j.tiles.get(lease.tile)).is_some_and(|t| {
                    t.epoch == lease.epoch && matches!(t.state, TileState::Accepted | TileState::Merged)
                });
            return (if duplicate { ResultOutcome::Duplicate } else { ResultOutcome::Stale }, changes);
        };
        touch(&mut changes, &lease.job, Some(i));
        match verdict {
            Ok(()) => {
                if let TileState::Leased { since_ms, .. } = job.tiles[i].state {
                    let rate = now_ms.saturating_sub(since_ms) as f64 / job.tiles[i].spec.pixel_samples().max(1) as f64;
                    job.slowest_ms_per_sample = Some(job.slowest_ms_per_sample.map_or(rate, |r| r.max(rate)));
                }
                job.set_tile_state(i, TileState::Accepted);
                (ResultOutcome::Accepted, changes)
            }
            Err(reason) => {
                fail_tile(job, i, (worker, &host), &reason, now_ms);
                (ResultOutcome::Refused(reason), changes)
            }
        }
    }

    /// A worker could not render its lease: re-queue the tile and count the failure.
    fn report_failure(&mut self, worker: &str, lease: &LeaseRef, message: &str, now_ms: u64) -> Changes {
        let mut changes = Changes::new();
        let host = host_of(&self.hosts, worker).to_string();
        if let Some((job, i)) = self.current_tile(worker, lease) {
            fail_tile(job, i, (worker, &host), message, now_ms);
            touch(&mut changes, &lease.job, Some(i));
        }
        changes
    }

    /// Tiles of `job` that can be merged now: accepted ones right after the merged prefix.
    fn mergeable(&self, job: &str) -> Range<usize> {
        let Some(j) = self.jobs.get(job) else { return 0..0 };
        if j.state.is_terminal() {
            return j.merged..j.merged;
        }
        let end = j.tiles[j.merged..]
            .iter()
            .position(|t| t.state != TileState::Accepted)
            .map_or(j.tiles.len(), |n| j.merged + n);
        j.merged..end
    }

    /// Records that the service merged `tiles[..upto]` into the film, and runs the barrier of
    /// every pass that is now complete. Returns the barrier's action when one ran.
    fn merged(&mut self, job: &str, upto: usize, now_ms: u64) -> (Option<BarrierAction>, Changes) {
        let mut changes = Changes::new();
        let Some(j) = self.jobs.get_mut(job) else { return (None, changes) };
        for i in j.merged..upto.min(j.tiles.len()) {
            debug_assert_eq!(j.tiles[i].state, TileState::Accepted, "invariant: merging an unaccepted tile");
            j.tiles[i].state = TileState::Merged;
            touch(&mut changes, job, Some(i));
        }
        j.merged = j.merged.max(upto.min(j.tiles.len()));
        touch(&mut changes, job, None);
        if j.state.is_terminal() || j.merged < j.tiles.len() {
            return (None, changes);
        }
        // every planned tile is merged: the last pass's barrier
        let action = match j.driver.barrier(now_ms as f64) {
            Step::Render(tiles) => {
                let range = j.add_tiles(tiles);
                changes.entry(job.to_string()).or_default().extend(range);
                BarrierAction::NextPass
            }
            Step::Update(_) => {
                j.state = JobState::Optimizing;
                BarrierAction::Optimize
            }
            // the outputs are written outside the model, then [`JobsModel::outputs_written`]
            Step::Finish => {
                j.state = JobState::Finishing;
                BarrierAction::Finish
            }
        };
        (Some(action), changes)
    }

    /// The optimiser has chosen a strategy, with `nu` light paths per pixel, at an EMIS
    /// barrier: plan the next pass with it. `restart`: the update ended a path-tracing start,
    /// and the service cleared the film, so a sample budget counts from the next pass on.
    /// `collect`: the EMIS state still collects moments (path tracing may have settled).
    fn optimized(
        &mut self,
        job: &str,
        restart: bool,
        nu: f32,
        collect: bool,
        now_ms: u64,
    ) -> Result<Changes, TransitionError> {
        let j = self.jobs.get_mut(job).ok_or_else(|| TransitionError::UnknownJob(job.to_string()))?;
        if j.state != JobState::Optimizing {
            return Err(TransitionError::NotOptimizing(job.to_string()));
        }
        j.state = JobState::Final;
        let tiles = j.driver.updated(restart, nu, collect, now_ms as f64);
        let range = j.add_tiles(tiles);
        let mut changes = Changes::new();
        changes.insert(job.to_string(), range.collect());
        Ok(changes)
    }

    /// A finishing job's outputs are stored: it is done.
    fn outputs_written(&mut self, job: &str, now_ms: u64) -> Result<Changes, TransitionError> {
        let j = self.jobs.get_mut(job).ok_or_else(|| TransitionError::UnknownJob(job.to_string()))?;
        if j.state != JobState::Finishing {
            return Err(TransitionError::NotFinishing(job.to_string()));
        }
        j.finish(JobState::Done, now_ms);
        let mut changes = Changes::new();
        touch(&mut changes, job, None);
        Ok(changes)
    }

    /// Cancels a job: no more tiles are handed out and results in flight become stale.
    fn cancel(&mut self, job: &str, now_ms: u64) -> Result<Changes, TransitionError> {
        let j = self.jobs.get_mut(job).ok_or_else(|| TransitionError::UnknownJob(job.to_string()))?;
        let mut changes = Changes::new();
        if !j.state.is_terminal() {
            j.finish(JobState::Cancelled, now_ms);
            touch(&mut changes, job, None);
        }
        Ok(changes)
    }

    /// Marks a job failed (for errors found outside the model, e.g. storage).
    fn fail(&mut self, job: &str, error: String, now_ms: u64) -> Changes {
        let mut changes = Changes::new();
        if let Some(j) = self.jobs.get_mut(job).filter(|j| !j.state.is_terminal()) {
            j.error = Some(error);
            j.finish(JobState::Failed, now_ms);
            touch(&mut changes, job, None);
        }
        changes
    }
}
