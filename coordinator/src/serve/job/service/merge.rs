//! Validating an uploaded result (image sums and EMIS pilot data) and merging accepted results
//! into a job's film, in tile order, with what follows a merge: pass barriers, EMIS updates,
//! checkpoints of the film and EMIS state (spaced by their cost) and, when the last tile is in,
//! the job's outputs, which are encoded without the service's lock.

use super::{Inner, JobService, ServiceError};
use crate::output::{Outputs, PngEffort, Provenance};
use crate::serve::job::emis::EmisJob;
use crate::serve::job::model::{Changes, JobSpec, TileSpec};
use crate::serve::job::plan::BarrierAction;
use crate::serve::job::validate::{ResultClaim, validate_result};
use crate::serve::storage::Extra;
use tessera_common::emis::PilotData;
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
    /// EMIS: the state, for the outputs' layers and the decisions shown afterwards.
    pub(super) emis: Option<EmisJob>,
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
    /// Checks a result's image sums and, for EMIS tiles, its pilot data (which the worker
    /// appends to the payload); the error says what is wrong.
    pub(super) fn validate(
        &self,
        job: &str,
        tile: &TileSpec,
        collect: bool,
        claim: &ResultClaim,
        payload: &[u8],
    ) -> Result<(TileAccum, Option<PilotData>), String> {
        let pilot_bytes = usize::try_from(claim.pilot_bytes).ok().filter(|&n| n <= payload.len()).ok_or_else(|| {
            format!("result claims {} pilot bytes in a payload of {}", claim.pilot_bytes, payload.len())
        })?;
        let (image, pilot) = payload.split_at(payload.len() - pilot_bytes);
        let accum = validate_result(tile, claim, image)?;
        // megabytes of pilot data are decoded without holding the service's lock
        let shape = self.lock().emis.get(job).map(EmisJob::shape);
        let pilot = match shape {
            Some(shape) => shape.decode(tile, collect, pilot)?,
            None if pilot.is_empty() => None,
            None => return Err("result has pilot data but the job is not an EMIS job".into()),
        };
        Ok((accum, pilot))
    }

    /// The update at an EMIS barrier: optimise on the merged film and moments, then plan the
    /// next pass with the new strategy. Committed with a checkpoint of both, so a restart
    /// resumes after the update (or, if it stopped before, runs it again identically).
    pub(super) fn optimize(&self, inner: &mut Inner, job: &str, now_ms: u64) -> Result<(), ServiceError> {
        let iterations = inner.model.jobs[job].spp_merged();
        let (Some(film), Some(emis)) = (inner.films.get(job), inner.emis.get_mut(job)) else {
            let changes = inner.model.fail(job, "the EMIS state of this job is missing".into(), now_ms);
            return self.persist(inner, &changes, &[]);
        };
        let span = tracing::info_span!("emis_update", job_id = %job, iterations);
        let restarted = span.in_scope(|| emis.update(film, iterations));
        if restarted {
            // a path-tracing start ended: its iterations leave the image (the checkpoint
            // below stores the empty film with the new strategy)
            let (w, h) = (film.width, film.height);
            inner.films.insert(job.to_string(), Film::new(w, h));
        }
        let changes =
            inner.model.optimized(job, restarted, now_ms).map_err(|e| ServiceError::Io(std::io::Error::other(e)))?;
        let upto = inner.model.jobs[job].merged;
        self.checkpoint(inner, job, upto, &changes, Vec::new(), now_ms)?;
        self.work.notify_waiters();
        Ok(())
    }

    /// Writes a checkpoint of the job's film (and EMIS state) holding `tiles[..upto]` and
    /// commits it with `changes` and `extras` (the results it covers are deleted with it).
    fn checkpoint(
        &self,
        inner: &mut Inner,
        job: &str,
        upto: usize,
        changes: &Changes,
        mut extras: Vec<Extra>,
        now_ms: u64,
    ) -> Result<(), ServiceError> {
        let Some(film) = inner.films.get(job) else { return self.persist(inner, changes, &extras) };
        let emis = inner.emis.get(job).map(EmisJob::checkpoint).unwrap_or_default();
        let old = inner.files.get(job).and_then(|f| f.checkpoint.clone());
        let started = std::time::Instant::now();
        let file = self.blobs.put_checkpoint(job, upto, film, &emis)?;
        let cost_ms = started.elapsed().as_millis() as u64;
        // after the pending result, so a result the checkpoint covers is deleted with it
        extras.push(Extra::Checkpoint { job: job.to_string(), merged: upto, file: file.clone() });
        self.persist(inner, changes, &extras)?;
        inner.checkpoints.insert(job.to_string(), CheckpointState { at_ms: now_ms, cost_ms });
        inner.files.entry(job.to_string()).or_default().checkpoint = Some(file.clone());
        if let Some(old) = old.filter(|o| *o != file) {
            // the database names the old file until the new name is committed
            self.sync(inner)?;
            self.blobs.remove_checkpoint(&old);
        }
        Ok(())
    }

    /// Merges the accepted tiles that are next in order, runs barriers, checkpoints. `pending`
    /// and `extras` (not yet persisted: the accepted result that made tiles mergeable) are
    /// committed in the same transaction as the merge.
    pub(super) fn merge_ready(
        &self,
        inner: &mut Inner,
        job: &str,
        now_ms: u64,
        pending: Changes,
        extras: Vec<Extra>,
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
            let emis = inner.emis.remove(job);
            return Ok(Some(Finishing { job: job.to_string(), spec, film: merged, upto: range.end, now_ms, emis }));
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
        inner.films.insert(job.to_string(), merged);
        if action == Some(BarrierAction::Finish) {
            // not reached: `merge_finishes` answered the same question above
            let emis = inner.emis.remove(job);
            let film = inner.films.remove(job).expect("invariant: inserted above");
            let outputs = self.write_outputs(&inner.model.jobs[job].spec, job, &film, emis.as_ref())?;
            self.record_outputs(inner, job, outputs, upto, &changes, extras, emis)?;
        } else if due || matches!(action, Some(BarrierAction::NextPass(_))) {
            self.checkpoint(inner, job, upto, &changes, extras, now_ms)?;
        } else {
            self.persist(inner, &changes, &extras)?;
        }
        match action {
            Some(BarrierAction::NextPass(_)) => self.work.notify_waiters(),
            // the update is committed with its own checkpoint of the new strategy
            Some(BarrierAction::Optimize) => self.optimize(inner, job, now_ms)?,
            Some(BarrierAction::Finish) | None => {}
        }
        Ok(None)
    }

    /// Writes a finished job's outputs without holding the lock, then records them with the
    /// job's last merge in one transaction. Until then the job shows every tile done but is not
    /// `done`, so nobody asks for outputs that do not exist yet; a crash in between merges the
    /// accepted tiles again on start-up and finishes the job then.
    pub(super) fn finish(&self, f: Finishing) -> Result<(), ServiceError> {
        let outputs = self.write_outputs(&f.spec, &f.job, &f.film, f.emis.as_ref())?;
        let mut inner = self.lock();
        let (action, changes) = inner.model.merged(&f.job, f.upto, f.now_ms);
        if action == Some(BarrierAction::Finish) {
            self.record_outputs(&mut inner, &f.job, outputs, f.upto, &changes, Vec::new(), f.emis)?;
        } else {
            // cancelled while the outputs were written
            self.persist(&mut inner, &changes, &[])?;
        }
        self.sync(&inner)
    }

    /// Commits a finished job's outputs (they replace its checkpoint: a finished film is never
    /// read again) with `changes` and `extras`; keeps the EMIS decisions for status views.
    #[allow(clippy::too_many_arguments)]
    fn record_outputs(
        &self,
        inner: &mut Inner,
        job: &str,
        (exr, png): (String, String),
        upto: usize,
        changes: &Changes,
        mut extras: Vec<Extra>,
        emis: Option<EmisJob>,
    ) -> Result<(), ServiceError> {
        if let Some(view) = emis.and_then(|e| e.view()) {
            inner.strategies.insert(job.to_string(), view);
        }
        let old = inner.files.get(job).and_then(|f| f.checkpoint.clone());
        extras.push(Extra::Outputs { job: job.to_string(), exr: exr.clone(), png: png.clone(), merged: upto });
        self.persist(inner, changes, &extras)?;
        let f = inner.files.entry(job.to_string()).or_default();
        (f.result_exr, f.preview_png, f.checkpoint) = (Some(exr), Some(png), None);
        if let Some(old) = old {
            // the database names the old file until the outputs are committed
            self.sync(inner)?;
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
            let (accum, pilot) = match inner.held.remove(&(job.to_string(), i)) {
                Some(r) => r,
                None => self.stored_result(inner, job, i)?,
            };
            film.merge_tile(&accum);
            if let (Some(p), Some(e)) = (pilot, inner.emis.get_mut(job)) {
                e.absorb(&p).map_err(|m| ServiceError::Io(std::io::Error::other(m)))?;
            }
        }
        Ok(())
    }

    /// An accepted result read back from the database (after a restart). The payload is the
    /// image sums of the tile's rectangle followed by the EMIS pilot data, if any.
    fn stored_result(
        &self,
        inner: &Inner,
        job: &str,
        i: usize,
    ) -> Result<(TileAccum, Option<PilotData>), ServiceError> {
        let j = &inner.model.jobs[job];
        let t = &j.tiles[i];
        let corrupt = |why: &str| ServiceError::Io(std::io::Error::other(format!("stored result of tile {i}: {why}")));
        let (non_finite, bytes) = match self.commits.store().load_result(job, i, t.epoch)? {
            Some(r) => r,
            // data directories of earlier versions kept results in files
            None => {
                let bytes = self.blobs.get_result(job, i, t.epoch)?;
                let nf = bytes.get(..8).ok_or_else(|| corrupt("too short"))?.try_into().expect("invariant: 8 bytes");
                (u64::from_le_bytes(nf), bytes[8..].to_vec())
            }
        };
        let image_bytes = t.spec.rect.area() * tessera_proto::RESULT_BYTES_PER_PIXEL;
        let (image, pilot) = bytes.split_at_checked(image_bytes).ok_or_else(|| corrupt("too short"))?;
        let (sum, count) =
            tessera_proto::decode_tile_payload(image, t.spec.rect.area()).ok_or_else(|| corrupt("wrong size"))?;
        let pilot = match inner.emis.get(job) {
            Some(e) => e.decode_pilot(&t.spec, j.collects(i), pilot).map_err(|m| corrupt(&m))?,
            None => None,
        };
        Ok((TileAccum { rect: t.spec.rect, sum, count, non_finite }, pilot))
    }

    /// Writes the result EXR (with the EMIS layers and decisions) and PNG preview as blobs,
    /// as `tessera render` writes them (the PNG with fast compression); returns their digests.
    fn write_outputs(
        &self,
        spec: &JobSpec,
        job: &str,
        film: &Film,
        emis: Option<&EmisJob>,
    ) -> Result<(String, String), ServiceError> {
        let provenance = Provenance {
            integrator: spec.settings.integrator.to_string(),
            spp: film.count.iter().max().copied().unwrap_or(0),
            seed: spec.settings.seed.unwrap_or(0),
            scene: spec.name.clone(),
            extra: vec![("job".into(), job.to_string())],
        };
        let outputs = Outputs::new(film, &provenance, emis.map(|e| &e.state));
        let (exr, png) = (self.blobs.temp_path(".exr"), self.blobs.temp_path(".png"));
        let written = outputs
            .write_exr(&exr)
            .and_then(|()| outputs.write_png(&png, PngEffort::Fast))
            .map_err(ServiceError::from)
            .and_then(|()| Ok((self.blobs.put_file(&exr)?, self.blobs.put_file(&png)?)));
        if written.is_err() {
            let _ = std::fs::remove_file(exr);
            let _ = std::fs::remove_file(png);
        }
        written
    }
}
