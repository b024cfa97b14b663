//! Validating an uploaded result (image sums and EMIS pilot data) and merging accepted results
//! into a job's film, in tile order, with what follows a merge: pass barriers, EMIS updates,
//! checkpoints of the film and EMIS state (spaced by their cost) and, when the last tile is in,
//! the job's outputs, which are encoded without the service's lock.

use super::runtime::{CheckpointState, HeldResult};
use super::{Inner, JobService, ServiceError};
use crate::output::{Outputs, PngEffort, Provenance};
use crate::serve::job::emis::EmisJob;
use crate::serve::job::model::{Changes, Effect, Effects, Event, JobSpec, TileSpec, join};
use crate::serve::job::validate::{ResultClaim, validate_result};
use crate::serve::storage::{Extra, OutputDigests};
use std::ops::Range;
use tessera_common::emis::RestartTotal;
use tessera_common::film::Film;
use tessera_common::film::filter::Filter;

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
    ) -> Result<HeldResult, String> {
        let pilot_bytes = usize::try_from(claim.pilot_bytes).ok().filter(|&n| n <= payload.len()).ok_or_else(|| {
            format!("result claims {} pilot bytes in a payload of {}", claim.pilot_bytes, payload.len())
        })?;
        let (image, pilot) = payload.split_at(payload.len() - pilot_bytes);
        let layout = self.lock().model.jobs.get(job).map(|j| j.spec.layout(tile.rect)).ok_or("the job is gone")?;
        let accum = validate_result(tile, layout, claim, image)?;
        // megabytes of pilot data are decoded without holding the service's lock
        let shape = self.lock().emis(job, &self.blobs).map(|e| e.shape());
        let pilot = match shape {
            Some(shape) => shape.decode(tile, collect, pilot)?,
            None if pilot.is_empty() => None,
            None => return Err("result has pilot data but the job is not an EMIS job".into()),
        };
        Ok((accum, pilot))
    }

    /// The update at an EMIS barrier ([`Effect::Optimize`]): optimise on the merged film and
    /// moments, then plan the next pass with the new strategy. Committed with a checkpoint of
    /// both, so a restart resumes after the update (or, if it stopped before, runs it again
    /// identically).
    pub(super) fn optimize(
        &self,
        inner: &mut Inner,
        job: &str,
        iterations: u32,
        restart_total: RestartTotal,
        now_ms: u64,
    ) -> Result<(), ServiceError> {
        let filter = inner.model.jobs.get(job).map(|j| Filter::new(j.spec.filter));
        inner.emis(job, &self.blobs);
        let runtime = inner.job(job);
        let (Some(film), Some(emis), Some(filter)) = (runtime.film.as_mut(), runtime.emis.as_mut(), filter) else {
            return self.fail_locked(inner, job, "the EMIS state of this job is missing", now_ms);
        };
        let span = tracing::info_span!("emis_update", job_id = %job, iterations);
        let restarted = span.in_scope(|| emis.update(film, iterations, restart_total));
        if let Some(report) = emis.state.reports.last() {
            super::events::emis_update(job, report);
        }
        if restarted {
            // a path-tracing start ended: its iterations leave the film for the EMIS state,
            // which combines them at the end (the checkpoint stores both)
            *film = Film::for_filter(film.width, film.height, &filter);
        }
        let (nu, collect) = (emis.state.strategy.nu, emis.state.collecting());
        let mut effects = inner.model.apply(Event::Optimized { job, restart: restarted, nu, collect }, now_ms)?;
        join(&mut effects.changes, self.decide(inner, job, false, now_ms)?);
        let upto = inner.model.jobs.get(job).map_or(0, |j| j.merged);
        self.checkpoint(inner, job, upto, &effects.changes, Vec::new(), now_ms)?;
        self.pass_planned(inner, job);
        Ok(())
    }

    /// [`Effect::PassPlanned`]: its tiles are queued for the workers.
    fn pass_planned(&self, inner: &Inner, job: &str) {
        super::events::pass_planned(&inner.model, job);
        self.work.notify_waiters();
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
        let runtime = inner.job(job);
        let Some(film) = &runtime.film else { return self.persist(inner, changes, &extras) };
        let emis = runtime.emis.as_ref().map(EmisJob::checkpoint).unwrap_or_default();
        let old = runtime.files.checkpoint.clone();
        let started = std::time::Instant::now();
        let file = self.blobs.put_checkpoint(job, upto, film, &emis)?;
        let cost_ms = started.elapsed().as_millis() as u64;
        // after the pending result, so a result the checkpoint covers is deleted with it
        extras.push(Extra::Checkpoint { job: job.to_string(), merged: upto, file: file.clone() });
        self.persist(inner, changes, &extras)?;
        let runtime = inner.job(job);
        runtime.checkpoint = Some(CheckpointState { at_ms: now_ms, cost_ms });
        runtime.files.checkpoint = Some(file.clone());
        if let Some(old) = old.filter(|o| *o != file) {
            // the database names the old file until the new name is committed
            self.sync(inner)?;
            self.blobs.remove_checkpoint(&old);
        }
        if inner.job(job).result_files {
            // needed until the checkpoint holding them is committed
            self.sync(inner)?;
            if let Err(e) = self.blobs.remove_results_below(job, upto) {
                tracing::warn!(job_id = %job, error = %e, "cannot remove result files a checkpoint holds");
            }
        }
        Ok(())
    }

    /// Runs the [`Effect::Merge`] among `effects` (of a result or a resume): merges those
    /// tiles into the film, then runs the barrier, checkpoints and what the barrier asks for.
    /// `effects`' changes and `extras` (not yet persisted: the accepted result that made tiles
    /// mergeable) are committed in the same transaction as the merge. A finishing job's
    /// outputs are written by the caller, without the lock ([`JobService::finish`]).
    pub(super) fn merge_ready(
        &self,
        inner: &mut Inner,
        effects: Effects,
        extras: Vec<Extra>,
        now_ms: u64,
    ) -> Result<Option<Finishing>, ServiceError> {
        let Effects { changes: pending, then } = effects;
        let Some((job, range)) = then.into_iter().find_map(|e| match e {
            Effect::Merge { job, tiles } => Some((job, tiles)),
            _ => None,
        }) else {
            return self.persist(inner, &pending, &extras).map(|()| None);
        };
        let Some(film) = self.merge_into_film(inner, &job, range.clone(), &pending, &extras, now_ms)? else {
            return Ok(None);
        };
        inner.counters.tiles_merged += range.len() as u64;
        let tiles = &inner.model.jobs[&job].tiles;
        inner.counters.samples_merged += tiles[range.clone()].iter().map(|t| t.spec.pixel_samples()).sum::<u64>();
        let mut merged = Effects { changes: pending, then: Vec::new() };
        merged.extend(inner.model.apply(Event::Merged { job: &job, upto: range.end }, now_ms)?);
        inner.job(&job).film = Some(film);
        if let Some(Effect::WriteOutputs { upto, .. }) = merged.then.first() {
            // encoding a frame's outputs takes seconds for big films: `finish` does it without
            // the lock; the accepted result is committed now
            let upto = *upto;
            join(&mut merged.changes, self.decide(inner, &job, true, now_ms)?);
            self.persist(inner, &merged.changes, &extras)?;
            return Ok(self.finishing(inner, &job, upto, now_ms));
        }
        self.after_merge(inner, &job, merged, extras, now_ms)?;
        Ok(None)
    }

    /// What [`JobService::finish`] takes from a finishing job: its film, spec and EMIS state.
    pub(super) fn finishing(&self, inner: &mut Inner, job: &str, upto: usize, now_ms: u64) -> Option<Finishing> {
        let spec = inner.model.jobs.get(job)?.spec.clone();
        let runtime = inner.job(job);
        let film = match runtime.film.take() {
            Some(film) => film,
            None => Film::for_filter(spec.width, spec.height, &Filter::new(spec.filter)),
        };
        let emis = runtime.emis.take();
        Some(Finishing { job: job.to_string(), spec, film, upto, now_ms, emis })
    }

    /// Merges `range` into the job's film (made at its first merge: a queued job holds none).
    /// A result that cannot be read back or absorbed fails its job, since no retry can merge
    /// it (`None`, with `pending` and `extras` committed).
    fn merge_into_film(
        &self,
        inner: &mut Inner,
        job: &str,
        range: Range<usize>,
        pending: &Changes,
        extras: &[Extra],
        now_ms: u64,
    ) -> Result<Option<Film>, ServiceError> {
        let mut film = match inner.job(job).film.take() {
            Some(film) => film,
            None => {
                let spec = &inner.model.jobs.get(job).expect("invariant: a merging job exists").spec;
                Film::for_filter(spec.width, spec.height, &Filter::new(spec.filter))
            }
        };
        let Err(e) = self.merge_range(inner, job, range, &mut film) else { return Ok(Some(film)) };
        // `merge_range` may have merged part of the range
        inner.job(job).film = Some(film);
        self.persist(inner, pending, extras)?;
        if !matches!(e, ServiceError::Corrupt { .. } | ServiceError::Emis { .. }) {
            return Err(e);
        }
        self.fail_locked(inner, job, &format!("cannot merge its results: {e}"), now_ms)?;
        Ok(None)
    }

    /// Commits a merge that did not finish the job (with a checkpoint when one is due or a
    /// pass ended) and runs what its barrier asks for: the next pass, or an EMIS update.
    fn after_merge(
        &self,
        inner: &mut Inner,
        job: &str,
        merged: Effects,
        extras: Vec<Extra>,
        now_ms: u64,
    ) -> Result<(), ServiceError> {
        let upto = inner.model.jobs.get(job).map_or(0, |j| j.merged);
        // a job's first merge (after submission or a restart) starts its checkpoint clock
        let last = *inner.job(job).checkpoint.get_or_insert(CheckpointState { at_ms: now_ms, cost_ms: 0 });
        let interval = self.cfg.checkpoint_interval_ms.max(last.cost_ms.saturating_mul(CHECKPOINT_SPACING));
        let due = now_ms.saturating_sub(last.at_ms) >= interval;
        let mut merged = merged;
        join(&mut merged.changes, self.decide(inner, job, false, now_ms)?);
        let changes = &merged.changes;
        match merged.then.first() {
            Some(Effect::PassPlanned { .. }) => {
                self.checkpoint(inner, job, upto, changes, extras, now_ms)?;
                self.pass_planned(inner, job);
            }
            // the update is committed with its own checkpoint of the new strategy
            Some(&Effect::Optimize { iterations, restart_total, .. }) => {
                self.checkpoint_or_persist(inner, job, upto, changes, extras, now_ms, due)?;
                if let Err(e) = self.optimize(inner, job, iterations, restart_total, now_ms) {
                    if e.is_storage() {
                        return Err(e);
                    }
                    // e.g. its checkpoint cannot be written: the job cannot go on
                    self.fail_locked(inner, job, &format!("EMIS update failed: {e}"), now_ms)?;
                }
            }
            _ => self.checkpoint_or_persist(inner, job, upto, changes, extras, now_ms, due)?,
        }
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    fn checkpoint_or_persist(
        &self,
        inner: &mut Inner,
        job: &str,
        upto: usize,
        changes: &Changes,
        extras: Vec<Extra>,
        now_ms: u64,
        due: bool,
    ) -> Result<(), ServiceError> {
        if due {
            self.checkpoint(inner, job, upto, changes, extras, now_ms)
        } else {
            self.persist(inner, changes, &extras)
        }
    }

    /// Writes a finished job's outputs without holding the lock, then records them with the
    /// job's last merge in one transaction. Until then the job shows every tile done but is not
    /// `done`, so nobody asks for outputs that do not exist yet; a crash in between merges the
    /// accepted tiles again on start-up and finishes the job then.
    pub(super) fn finish(&self, f: Finishing) -> Result<(), ServiceError> {
        let outputs = match self.write_outputs(&f.spec, &f.job, &f.film, f.emis.as_ref()) {
            Ok(o) => o,
            // its film is gone with `f`: a job whose outputs cannot be written fails
            Err(e) => return self.fail_job(&f.job, &format!("cannot write its outputs: {e}"), f.now_ms),
        };
        let mut inner = self.lock();
        match inner.model.apply(Event::OutputsWritten { job: &f.job }, f.now_ms) {
            Ok(effects) => self.record_outputs(&mut inner, &f.job, outputs, f.upto, &effects.changes, f.emis)?,
            // cancelled (or cancelled and deleted) while the outputs were written: nothing will
            // name them
            Err(_) => self.remove_unused_blobs(&inner, outputs.all().cloned().collect()),
        }
        self.sync(&inner)
    }

    /// Commits a finished job's outputs (they replace its checkpoint: a finished film is never
    /// read again) with `changes`; keeps the EMIS decisions for status views.
    fn record_outputs(
        &self,
        inner: &mut Inner,
        job: &str,
        outputs: OutputDigests,
        upto: usize,
        changes: &Changes,
        emis: Option<EmisJob>,
    ) -> Result<(), ServiceError> {
        let old = inner.job(job).files.checkpoint.clone();
        let extras = [Extra::Outputs { job: job.to_string(), outputs: outputs.clone(), merged: upto }];
        self.persist(inner, changes, &extras)?;
        let runtime = inner.job(job);
        runtime.emis = emis;
        runtime.end();
        let f = &mut runtime.files;
        (f.result_exr, f.preview_png, f.checkpoint) = (Some(outputs.exr), Some(outputs.png), None);
        (f.strategy_png, f.emis_json) = (outputs.strategy_png, outputs.emis_json);
        if let Some(old) = old {
            // the database names the old file until the outputs are committed
            self.sync(inner)?;
            self.blobs.remove_checkpoint(&old);
        }
        if std::mem::take(&mut inner.job(job).result_files) {
            self.sync(inner)?;
            if let Err(e) = self.blobs.remove_results(job) {
                tracing::warn!(job_id = %job, error = %e, "cannot remove the result files of a finished job");
            }
        }
        let Some(j) = inner.model.jobs.get(job) else { return Ok(()) };
        tracing::info!(
            job_id = %job,
            tiles = j.tiles.len(),
            spp = j.spp_merged(),
            duration_ms = j.finished_ms.unwrap_or(0).saturating_sub(j.created_ms),
            "job done"
        );
        Ok(())
    }

    /// Merges `range` into `film` and the EMIS moments, all or nothing: every result is checked
    /// first (a stored one read back and dropped, so that a long range after a restart is not
    /// held in memory at once), and on an error the film is untouched.
    fn merge_range(
        &self,
        inner: &mut Inner,
        job: &str,
        range: std::ops::Range<usize>,
        film: &mut Film,
    ) -> Result<(), ServiceError> {
        // after a restart the EMIS state may not be made yet: stored pilot data needs it
        inner.emis(job, &self.blobs);
        let emis_error = |message| ServiceError::Emis { job: job.to_string(), message };
        for i in range.clone() {
            let runtime = inner.job(job);
            let pilot = match runtime.held.get(&i) {
                Some((_, pilot)) => pilot.as_ref().map(|p| runtime.emis.as_ref().map(|e| e.check(p))),
                None => {
                    let (_, pilot) = self.stored_result(inner, job, i)?;
                    pilot.map(|p| inner.job(job).emis.as_ref().map(|e| e.check(&p)))
                }
            };
            pilot.flatten().transpose().map_err(emis_error)?;
        }
        for i in range {
            let (accum, pilot) = match inner.job(job).held.remove(&i) {
                Some(r) => r,
                // read a moment ago: failing now leaves a partly merged film, so the job fails
                None => self.stored_result(inner, job, i).map_err(|e| ServiceError::Corrupt {
                    what: format!("stored result of job {job} tile {i}"),
                    message: format!("read back once, then not: {e}"),
                })?,
            };
            film.merge_tile(&accum);
            if let (Some(p), Some(e)) = (pilot, inner.job(job).emis.as_mut()) {
                e.absorb(&p).expect("invariant: pilot data checked before the merge");
            }
        }
        Ok(())
    }

    /// An accepted result read back from the database (after a restart). The payload is the
    /// image sums of the tile's rectangle followed by the EMIS pilot data, if any.
    fn stored_result(&self, inner: &Inner, job: &str, i: usize) -> Result<HeldResult, ServiceError> {
        let corrupt = |why: &str| ServiceError::Corrupt {
            what: format!("stored result of job {job} tile {i}"),
            message: why.into(),
        };
        let j = inner.model.jobs.get(job).ok_or_else(|| corrupt("the job is gone"))?;
        let t = j.tiles.get(i).ok_or_else(|| corrupt("no such tile"))?;
        let (non_finite, bytes) = match self.commits.store().load_result(job, i, t.epoch)? {
            Some(r) => r,
            // a large result is a file, not a row (docs/decisions/0009-results-in-the-database.md)
            None => {
                let bytes = self.blobs.get_result(job, i, t.epoch)?;
                let nf = bytes.get(..8).ok_or_else(|| corrupt("too short"))?.try_into().expect("invariant: 8 bytes");
                (u64::from_le_bytes(nf), bytes[8..].to_vec())
            }
        };
        let layout = j.spec.layout(t.spec.rect);
        let image_bytes = tessera_link::payload::payload_bytes(&layout).ok_or_else(|| corrupt("too large"))?;
        let (image, pilot) = bytes.split_at_checked(image_bytes).ok_or_else(|| corrupt("too short"))?;
        let accum = tessera_link::payload::decode_tile(image, t.spec.rect, layout, non_finite)
            .ok_or_else(|| corrupt("wrong size"))?;
        let pilot = match inner.jobs.get(job).and_then(|r| r.emis.as_ref()) {
            Some(e) => e.decode_pilot(&t.spec, j.collects(i), pilot).map_err(|m| corrupt(&m))?,
            None => None,
        };
        Ok((accum, pilot))
    }

    /// Writes the result EXR (with the EMIS layers and decisions) and PNG preview as blobs,
    /// as `tessera render` writes them (the PNG with fast compression), and for EMIS the
    /// strategy PNG (byte for byte as `tessera render`'s) and JSON report (the same but for
    /// the updates' timings); returns their digests.
    fn write_outputs(
        &self,
        spec: &JobSpec,
        job: &str,
        film: &Film,
        emis: Option<&EmisJob>,
    ) -> Result<OutputDigests, ServiceError> {
        let spp = film.count.iter().max().copied().unwrap_or(0);
        let provenance = Provenance {
            integrator: spec.settings.integrator.to_string(),
            spp,
            seed: spec.settings.seed.unwrap_or(0),
            scene: spec.name.clone(),
            extra: vec![("job".into(), job.to_string())],
        };
        let outputs = Outputs::new(film, &provenance, emis.map(|e| &e.state));
        // every file is written before any is stored, so a failure stores nothing
        let temp = TempFiles([".exr", ".png", ".strategy.png"].map(|suffix| self.blobs.temp_path(suffix)));
        let [exr, png, strategy] = &temp.0;
        outputs.write_exr(exr)?;
        outputs.write_png(png, PngEffort::Fast)?;
        // default compression, unlike the preview: the same bytes as `tessera render`'s file,
        // and only EMIS jobs pay for it, once
        let has_strategy = outputs.write_strategy_png(strategy, PngEffort::Default)?;
        // the report's `iterations`, like `tessera render`'s, counts the kept iterations
        let report = outputs.emis_report_text(spec.settings.integrator.as_str(), spp);
        let digests = OutputDigests {
            exr: self.blobs.put_file(exr)?,
            png: self.blobs.put_file(png)?,
            strategy_png: if has_strategy { Some(self.blobs.put_file(strategy)?) } else { None },
            emis_json: report.map(|text| self.blobs.put(text.as_bytes())).transpose()?,
        };
        Ok(digests)
    }
}

/// Temporary files removed when dropped: `put_file` moves a file into the store, so what is
/// left is what an error stopped halfway.
struct TempFiles([std::path::PathBuf; 3]);

impl Drop for TempFiles {
    fn drop(&mut self) {
        for path in &self.0 {
            if path.exists() {
                let _ = std::fs::remove_file(path);
            }
        }
    }
}
