//! Merging accepted results into a job's film, in tile order, with what follows a merge: pass
//! barriers, film checkpoints (spaced by their cost) and, when the last tile is in, the job's
//! outputs, which are encoded without the service's lock.

use super::{Inner, JobService, ServiceError};
use crate::job::model::{Changes, JobSpec};
use crate::job::plan::BarrierAction;
use crate::storage::Extra;
use tessera_common::film::{Film, TileAccum};

/// A checkpoint writes the whole film while uploads wait, so consecutive checkpoints of a job
/// are at least this many times the last one's duration apart: writing them takes at most
/// about 1/`CHECKPOINT_SPACING` of the time, whatever the film's size (a 4K film is 230 MB).
/// Durability does not depend on it: results stay in the database until a checkpoint covers
/// them; a longer interval only means more results to merge again after a restart.
pub const CHECKPOINT_SPACING: u64 = 20;

/// A job whose last tiles are merged into `film`, waiting for its outputs (see
/// [`JobService::finish`]).
pub(super) struct Finishing {
    pub(super) job: String,
    pub(super) spec: JobSpec,
    pub(super) film: Film,
    pub(super) upto: usize,
    pub(super) now_ms: u64,
}

/// The last checkpoint of a job.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct CheckpointState {
    /// When it was written.
    pub(super) at_ms: u64,
    /// How long writing it took.
    pub(super) cost_ms: u64,
}

impl JobService {
    /// Merges the accepted tiles that are next in order, runs barriers, checkpoints. `pending`
    /// and `extras` (not yet persisted: the accepted result that made tiles mergeable) are
    /// committed in the same transaction as the merge.
    pub(super) fn merge_ready(
        &self,
        inner: &mut Inner,
        job: &str,
        now_ms: u64,
        pending: Changes,
        mut extras: Vec<Extra>,
    ) -> Result<Option<Finishing>, ServiceError> {
        let range = inner.model.mergeable(job);
        let film = if range.is_empty() { None } else { inner.films.remove(job) };
        let Some(mut film) = film else { return self.persist(inner, &pending, &extras).map(|()| None) };
        let merged = self.merge_range(inner, job, range.clone(), &mut film);
        let merged = match merged {
            Ok(()) => film,
            Err(e) => {
                inner.films.insert(job.to_string(), film);
                self.persist(inner, &pending, &extras)?;
                return Err(e);
            }
        };
        inner.counters.tiles_merged += range.len() as u64;
        if inner.model.merge_finishes(job, range.end, now_ms) {
            // encoding a frame's outputs takes seconds for big films: `finish` does it without
            // the lock; the accepted result is committed now
            self.persist(inner, &pending, &extras)?;
            let spec = inner.model.jobs[job].spec.clone();
            return Ok(Some(Finishing { job: job.to_string(), spec, film: merged, upto: range.end, now_ms }));
        }
        let (action, mut changes) = inner.model.merged(job, range.end, now_ms);
        for (j, tiles) in pending {
            changes.entry(j).or_default().extend(tiles);
        }
        let upto = inner.model.jobs[job].merged;
        // a job's first merge (after submission or a restart) starts its checkpoint clock
        let last = *inner.checkpoints.entry(job.to_string()).or_insert(CheckpointState { at_ms: now_ms, cost_ms: 0 });
        let interval = self.cfg.checkpoint_interval_ms.max(last.cost_ms.saturating_mul(CHECKPOINT_SPACING));
        let due = now_ms.saturating_sub(last.at_ms) >= interval;
        if action == Some(BarrierAction::Finish) {
            // not reached: `merge_finishes` answered the same question above
            let (exr, png) = self.write_outputs(&inner.model.jobs[job].spec, job, &merged)?;
            self.record_outputs(inner, job, (exr, png), upto, &changes, extras)?;
        } else if due || matches!(action, Some(BarrierAction::NextPass(_))) {
            let old = inner.files.get(job).and_then(|f| f.checkpoint.clone());
            let started = std::time::Instant::now();
            let file = self.blobs.put_checkpoint(job, upto, &merged)?;
            let cost_ms = started.elapsed().as_millis() as u64;
            // after the pending result, so a result the checkpoint covers is deleted with it
            extras.push(Extra::Checkpoint { job: job.to_string(), merged: upto, file: file.clone() });
            self.persist(inner, &changes, &extras)?;
            inner.checkpoints.insert(job.to_string(), CheckpointState { at_ms: now_ms, cost_ms });
            inner.files.entry(job.to_string()).or_default().checkpoint = Some(file.clone());
            if let Some(old) = old.filter(|o| *o != file) {
                self.blobs.remove_checkpoint(&old);
            }
        } else {
            self.persist(inner, &changes, &extras)?;
        }
        match action {
            Some(BarrierAction::Finish) => {}
            Some(BarrierAction::NextPass(_)) => self.work.notify_waiters(),
            Some(BarrierAction::Optimize) => {
                // EMIS hook: run the optimiser on the merged pilot film and moments here, then
                // call `JobsModel::optimized` with the final pass. No integrator plans a pilot
                // pass yet, so reaching this is a planning bug: fail the job loudly.
                let changes = inner.model.fail(job, "no optimiser is available for this job".into(), now_ms);
                self.persist(inner, &changes, &[])?;
            }
            None => {}
        }
        if !inner.model.jobs[job].state.is_terminal() {
            inner.films.insert(job.to_string(), merged);
        }
        Ok(None)
    }

    /// Writes a finished job's outputs without holding the lock, then records them with the
    /// job's last merge in one transaction. Until then the job shows every tile done but is not
    /// `done`, so nobody asks for outputs that do not exist yet; a crash in between merges the
    /// accepted tiles again on start-up and finishes the job then.
    pub(super) fn finish(&self, f: Finishing) -> Result<(), ServiceError> {
        let outputs = self.write_outputs(&f.spec, &f.job, &f.film)?;
        let mut inner = self.lock();
        let (action, changes) = inner.model.merged(&f.job, f.upto, f.now_ms);
        if action == Some(BarrierAction::Finish) {
            self.record_outputs(&mut inner, &f.job, outputs, f.upto, &changes, Vec::new())?;
        } else {
            // cancelled while the outputs were written
            self.persist(&mut inner, &changes, &[])?;
        }
        self.sync(&inner)
    }

    /// Commits a finished job's outputs (they replace its checkpoint: a finished film is never
    /// read again) with `changes` and `extras`.
    fn record_outputs(
        &self,
        inner: &mut Inner,
        job: &str,
        (exr, png): (String, String),
        upto: usize,
        changes: &Changes,
        mut extras: Vec<Extra>,
    ) -> Result<(), ServiceError> {
        let old = inner.files.get(job).and_then(|f| f.checkpoint.clone());
        extras.push(Extra::Outputs { job: job.to_string(), exr: exr.clone(), png: png.clone(), merged: upto });
        self.persist(inner, changes, &extras)?;
        let f = inner.files.entry(job.to_string()).or_default();
        (f.result_exr, f.preview_png, f.checkpoint) = (Some(exr), Some(png), None);
        if let Some(old) = old {
            self.blobs.remove_checkpoint(&old);
        }
        inner.films.remove(job);
        tracing::info!(job_id = %job, "job done");
        Ok(())
    }

    fn merge_range(
        &self,
        inner: &mut Inner,
        job: &str,
        range: std::ops::Range<usize>,
        film: &mut Film,
    ) -> Result<(), ServiceError> {
        for i in range {
            let accum = match inner.held.remove(&(job.to_string(), i)) {
                Some(a) => a,
                None => {
                    let t = &inner.model.jobs[job].tiles[i];
                    let corrupt =
                        || ServiceError::Io(std::io::Error::other(format!("stored result of tile {i} is corrupt")));
                    let (non_finite, bytes) = match self.commits.store().load_result(job, i, t.epoch)? {
                        Some(r) => r,
                        // data directories of earlier versions kept results in files
                        None => {
                            let bytes = self.blobs.get_result(job, i, t.epoch)?;
                            let nf = bytes.get(..8).ok_or_else(corrupt)?.try_into().map_err(|_| corrupt())?;
                            (u64::from_le_bytes(nf), bytes[8..].to_vec())
                        }
                    };
                    let (sum, count) =
                        tessera_proto::decode_tile_payload(&bytes, t.spec.rect.area()).ok_or_else(corrupt)?;
                    TileAccum { rect: t.spec.rect, sum, count, non_finite }
                }
            };
            film.merge_tile(&accum);
        }
        Ok(())
    }

    /// Writes the result EXR and PNG preview as blobs; returns their digests.
    fn write_outputs(&self, spec: &JobSpec, job: &str, film: &Film) -> Result<(String, String), ServiceError> {
        let attributes = vec![
            ("tessera/integrator".to_string(), spec.settings.integrator.to_string()),
            ("tessera/spp".to_string(), film.count.iter().max().copied().unwrap_or(0).to_string()),
            ("tessera/seed".to_string(), spec.settings.seed.unwrap_or(0).to_string()),
            ("tessera/scene".to_string(), spec.name.clone()),
            ("tessera/job".to_string(), job.to_string()),
        ];
        Ok(self.blobs.put_outputs(film, &attributes)?)
    }
}
