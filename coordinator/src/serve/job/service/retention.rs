//! Deleting ended jobs, when a client asks ([`JobService::delete`]) or when they ended more than
//! `--retain-finished` ago ([`JobService::expire_finished`]). The model and the service's
//! memory forget the job, one transaction deletes its rows, and only after that commit do its
//! files go: checkpoint, outputs (EMIS's strategy PNG and report too), merge masks, old result
//! files, and its bundle with the unpacked scene unless another job, or a submission in flight,
//! uses the same bundle. The database then gives the space back. A crash between the commit and
//! the files leaves only files nobody names, which the start-up sweep
//! ([`JobService::sweep_orphans`]) removes. Why an active job is refused rather than cancelled:
//! docs/decisions/0016-deleting-jobs.md.

use super::runtime::JobRuntime;
use super::{Inner, JobService, ServiceError};
use crate::serve::job::emis::MergeSpec;
use crate::serve::job::model::{Job, Sequence, TransitionError};
use crate::serve::storage::blobs::remove_all;
use crate::serve::storage::{Live, sqlite::Batch};
use std::collections::{BTreeSet, HashSet};

/// Jobs one [`JobService::expire_finished`] deletes at most, so that a backlog (a first start
/// with a short retention over a long history) holds the service's lock in short turns.
pub const EXPIRE_BATCH: usize = 64;

/// A bundle held by a submission until its job is in the model (see [`JobService::pin_bundle`]).
pub(super) struct BundlePin<'a> {
    svc: &'a JobService,
    digest: String,
}

impl Drop for BundlePin<'_> {
    fn drop(&mut self) {
        let mut pins = self.svc.submitting.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(n) = pins.get_mut(&self.digest) {
            *n -= 1;
            if *n == 0 {
                pins.remove(&self.digest);
            }
        }
    }
}

/// A refused transition as the API reports it: an unknown job is not found, an active one is
/// a conflict with its state.
pub(super) fn refused(e: TransitionError) -> ServiceError {
    match e {
        TransitionError::UnknownJob(job) => ServiceError::NotFound(format!("job {job} not found")),
        e @ TransitionError::Unfinished { .. } => ServiceError::FailedPrecondition(e.to_string()),
        e => e.into(),
    }
}

impl JobService {
    /// Deletes a finished, failed or cancelled job with all its data; an active job is refused
    /// ([`ServiceError::FailedPrecondition`]: cancel it first). Answered once the rows are
    /// committed and the files are gone.
    pub fn delete(&self, job: &str) -> Result<(), ServiceError> {
        self.disk.make_room();
        let mut inner = self.lock();
        let job = &Self::resolve(&inner, job)?;
        self.remove_jobs(&mut inner, std::slice::from_ref(job))?;
        tracing::info!(job_id = %job, "job deleted");
        drop(inner);
        self.disk.restore_ballast();
        Ok(())
    }

    /// Deletes the jobs that ended at least `--retain-finished` ago, at most
    /// [`EXPIRE_BATCH`] of them (the oldest); returns how many.
    pub fn expire_finished(&self, now_ms: u64) -> Result<usize, ServiceError> {
        let Some(retain_ms) = self.cfg.retain_finished_ms else { return Ok(0) };
        let mut inner = self.lock();
        let mut ids = inner.model.expired(now_ms, retain_ms);
        ids.truncate(EXPIRE_BATCH);
        if !ids.is_empty() {
            self.remove_jobs(&mut inner, &ids)?;
            tracing::info!(jobs = ids.len(), "finished jobs expired");
        }
        Ok(ids.len())
    }

    /// The `--retain-finished` period, if any.
    pub fn retain_finished_ms(&self) -> Option<u64> {
        self.cfg.retain_finished_ms
    }

    /// Removes ended jobs from memory, deletes their rows (one transaction), then their files.
    /// A job of frames goes with its frames.
    fn remove_jobs(&self, inner: &mut Inner, ids: &[String]) -> Result<(), ServiceError> {
        let mut removed: Vec<(Job, JobRuntime)> = Vec::new();
        let mut sequences = Vec::new();
        // the jobs (a sequence's frames in its place) and then the sequences
        let (mut jobs, mut all) = (Vec::new(), Vec::new());
        for id in ids {
            let frames = inner.model.sequences.get(id).map(|s| s.frame_ids().collect::<Vec<_>>());
            match frames {
                Some(frames) => {
                    match inner.model.remove_sequence(id) {
                        Ok(s) => sequences.push(s),
                        Err(e) => {
                            restore(inner, removed, sequences);
                            return Err(refused(e));
                        }
                    }
                    jobs.extend(frames.into_iter().filter(|f| inner.model.jobs.contains_key(f)));
                    all.push(id.clone());
                }
                None => jobs.push(id.clone()),
            }
        }
        all.extend(jobs.iter().cloned());
        for id in &jobs {
            match inner.model.remove(id) {
                Ok(job) => removed.push((job, inner.jobs.remove(id).unwrap_or_default())),
                Err(e) => {
                    restore(inner, removed, sequences);
                    return Err(refused(e));
                }
            }
        }
        inner.ticket = self.commits.enqueue(Batch::deleting(&all));
        if let Err(e) = self.sync(inner) {
            // the rows are still there, and so is the job
            restore(inner, removed, sequences);
            return Err(e);
        }
        let bundles = sequences.into_iter().map(|s| s.spec.bundle_digest);
        self.changed.send_modify(|v| *v += 1);
        let mut blobs = BTreeSet::new();
        for (job, runtime) in removed {
            if let Some(checkpoint) = &runtime.files.checkpoint {
                self.blobs.remove_checkpoint(checkpoint);
            }
            if let Err(e) = self.blobs.remove_results(&job.id) {
                tracing::warn!(job_id = %job.id, error = %e, "cannot delete old result files");
            }
            blobs.extend(runtime.files.outputs().cloned().chain(runtime.masks));
            blobs.extend(warm_blobs(&job).cloned());
            blobs.insert(job.spec.bundle_digest);
        }
        blobs.extend(bundles);
        self.remove_unused_blobs(inner, blobs);
        match self.commits.store().reclaim() {
            Ok(pages) => tracing::debug!(pages, "database space given back"),
            // the rows are gone; the space comes back with the next delete
            Err(e) => tracing::warn!(error = %e, "cannot give database space back"),
        }
        Ok(())
    }

    /// Deletes the blobs among `digests` that no job in `inner` names and no submission in
    /// flight is storing, with the unpacked folder of those that are bundles. A file that
    /// cannot be deleted is logged and left to the start-up sweep.
    pub(super) fn remove_unused_blobs(&self, inner: &Inner, digests: BTreeSet<String>) {
        let live = live_blobs(inner);
        // held while the files go: a submission pins its bundle before storing it, so it
        // either sees the pin refused here or stores the blob again after this
        let pins = self.submitting.lock().unwrap_or_else(|p| p.into_inner());
        for digest in digests.iter().filter(|d| !live.contains(*d) && !pins.contains_key(*d)) {
            let removed = self.blobs.remove(digest).and_then(|()| remove_all(&self.scenes_dir.join(digest)));
            if let Err(e) = removed {
                tracing::warn!(blob = %digest, error = %e, "cannot delete a blob");
            }
        }
    }

    /// Keeps a bundle from being deleted until the returned pin is dropped.
    pub(super) fn pin_bundle(&self, digest: &str) -> BundlePin<'_> {
        *self.submitting.lock().unwrap_or_else(|p| p.into_inner()).entry(digest.to_string()).or_default() += 1;
        BundlePin { svc: self, digest: digest.to_string() }
    }

    /// At start-up: deletes every blob, checkpoint, temporary file and unpacked bundle that no
    /// job names (left by a crash between a commit and the removal of files, or by an older
    /// version that kept them). The current merge masks of running EMIS jobs are stored again
    /// first, since a worker holding a lease from before the restart may still fetch one.
    pub(super) fn sweep_orphans(&self) -> Result<(), ServiceError> {
        let mut inner = self.lock();
        for runtime in inner.jobs.values_mut() {
            if let Some(emis) = runtime.emis.as_mut()
                && let MergeSpec::Mask(digest) = emis.strategy(&self.blobs, false)?.merge
            {
                runtime.masks.insert(digest);
            }
        }
        let live = Live {
            blobs: live_blobs(&inner),
            checkpoints: inner.jobs.values().filter_map(|r| r.files.checkpoint.clone()).collect(),
            jobs: inner.model.jobs.keys().cloned().collect(),
        };
        let mut removed = self.blobs.sweep(&live)?;
        if self.scenes_dir.exists() {
            for entry in std::fs::read_dir(&self.scenes_dir)? {
                let entry = entry?;
                if !live.blobs.contains(&*entry.file_name().to_string_lossy()) {
                    remove_all(&entry.path())?;
                    removed += 1;
                }
            }
        }
        if removed > 0 {
            tracing::info!(files = removed, "deleted files no job names");
        }
        Ok(())
    }

    /// Whether the model, and the service's per-job memory, still hold `job`.
    #[cfg(test)]
    pub(crate) fn holds(&self, job: &str) -> (bool, bool) {
        let inner = self.lock();
        (inner.model.jobs.contains_key(job), inner.jobs.contains_key(job))
    }
}

/// Puts jobs whose removal could not be committed back.
fn restore(inner: &mut Inner, removed: Vec<(Job, JobRuntime)>, sequences: Vec<Sequence>) {
    for (job, runtime) in removed {
        inner.jobs.insert(job.id.clone(), runtime);
        inner.model.restore(job);
    }
    for s in sequences {
        inner.model.restore_sequence(s);
    }
}

/// Every blob a job in `inner` names: bundles, outputs (EMIS strategy PNGs and reports
/// included), merge masks, and the masks of frames' warm starts.
fn live_blobs(inner: &Inner) -> HashSet<String> {
    // a job of frames plans its next frames from its bundle
    let sequences = inner.model.sequences.values().map(|s| s.spec.bundle_digest.clone());
    let bundles = inner.model.jobs.values().map(|j| j.spec.bundle_digest.clone()).chain(sequences);
    let files = inner.jobs.values().flat_map(|r| r.files.outputs().chain(&r.masks).cloned().collect::<Vec<_>>());
    let warm = inner.model.jobs.values().flat_map(|j| warm_blobs(j).cloned().collect::<Vec<_>>());
    bundles.chain(files).chain(warm).collect()
}

/// The masks of the decision a job of frames' frame started from and of the one it made.
fn warm_blobs(job: &Job) -> impl Iterator<Item = &String> {
    job.spec.warm.iter().chain(&job.decided).flat_map(|w| w.blobs())
}
