//! The service's merge path: validating an uploaded result (image sums and EMIS pilot data),
//! merging accepted results into the film strictly in tile order, the barriers that follow
//! (next pass, EMIS update, finish with outputs) and checkpoints of the film and EMIS state.

use super::{Inner, JobService, ServiceError};
use crate::job::emis::EmisJob;
use crate::job::model::{Changes, TileSpec};
use crate::job::plan::BarrierAction;
use crate::job::validate::{ResultClaim, validate_result};
use crate::storage::Extra;
use tessera_common::film::exr::{Attribute, ExrExtras};
use tessera_common::film::{Film, TileAccum};
use tessera_common::integrator::emis::PilotData;

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
        let inner = self.lock();
        let pilot = match inner.emis.get(job) {
            Some(e) => e.decode_pilot(tile, collect, pilot)?,
            None if pilot.is_empty() => None,
            None => return Err("result has pilot data but the job is not an EMIS job".into()),
        };
        Ok((accum, pilot))
    }

    /// The update at an EMIS barrier: optimise on the merged film and moments, then plan the
    /// next pass with the new strategy. Persisted with a checkpoint of both, so a restart
    /// resumes after the update (or, if it stopped before, runs it again identically).
    pub(super) fn optimize(&self, inner: &mut Inner, job: &str, now_ms: u64) -> Result<(), ServiceError> {
        let iterations = inner.model.jobs[job].spp_merged();
        let (Some(film), Some(emis)) = (inner.films.get(job), inner.emis.get_mut(job)) else {
            let changes = inner.model.fail(job, "the EMIS state of this job is missing".into(), now_ms);
            return self.persist(inner, &changes, &[]);
        };
        let span = tracing::info_span!("emis_update", job_id = %job, iterations);
        span.in_scope(|| emis.update(film, iterations));
        let changes = inner.model.optimized(job, now_ms).map_err(|e| ServiceError::Io(std::io::Error::other(e)))?;
        let upto = inner.model.jobs[job].merged;
        self.checkpoint(inner, job, upto, &changes, None, now_ms)?;
        self.work.notify_waiters();
        Ok(())
    }

    /// Writes a checkpoint of the film (and EMIS state) holding `tiles[..upto]` and persists
    /// `changes` (and `outputs`) with it; then drops the superseded checkpoint and the merged
    /// results.
    fn checkpoint(
        &self,
        inner: &mut Inner,
        job: &str,
        upto: usize,
        changes: &Changes,
        outputs: Option<Extra>,
        now_ms: u64,
    ) -> Result<(), ServiceError> {
        let Some(film) = inner.films.get(job) else { return self.persist(inner, changes, &[]) };
        let emis = inner.emis.get(job).map(EmisJob::checkpoint).unwrap_or_default();
        let old = inner.files.get(job).and_then(|f| f.checkpoint.clone());
        let file = self.blobs.put_checkpoint(job, upto, film, &emis)?;
        let mut extras = vec![Extra::Checkpoint { job: job.to_string(), merged: upto, file: file.clone() }];
        extras.extend(outputs);
        self.persist(inner, changes, &extras)?;
        inner.last_checkpoint_ms.insert(job.to_string(), now_ms);
        inner.files.entry(job.to_string()).or_default().checkpoint = Some(file.clone());
        if let Some(old) = old.filter(|o| *o != file) {
            self.blobs.remove_checkpoint(&old);
        }
        let j = &inner.model.jobs[job];
        for (i, t) in j.tiles[..upto].iter().enumerate() {
            self.blobs.remove_result(job, i, t.epoch);
        }
        Ok(())
    }

    /// Merges the accepted tiles that are next in order, runs barriers, checkpoints.
    pub(super) fn merge_ready(&self, inner: &mut Inner, job: &str, now_ms: u64) -> Result<(), ServiceError> {
        let range = inner.model.mergeable(job);
        if range.is_empty() {
            return Ok(());
        }
        let Some(mut film) = inner.films.remove(job) else { return Ok(()) };
        let merged = self.merge_range(inner, job, range.clone(), &mut film);
        inner.films.insert(job.to_string(), film);
        merged?;
        inner.counters.tiles_merged += range.len() as u64;
        let (action, changes) = inner.model.merged(job, range.end, now_ms);
        let upto = inner.model.jobs[job].merged;
        let due =
            now_ms.saturating_sub(*inner.last_checkpoint_ms.get(job).unwrap_or(&0)) >= self.cfg.checkpoint_interval_ms;
        match action {
            Some(BarrierAction::Finish) => {
                let (exr, png) = self.write_outputs(inner, job)?;
                let outputs = Extra::Outputs { job: job.to_string(), exr: exr.clone(), png: png.clone() };
                self.checkpoint(inner, job, upto, &changes, Some(outputs), now_ms)?;
                let f = inner.files.entry(job.to_string()).or_default();
                (f.result_exr, f.preview_png) = (Some(exr), Some(png));
                inner.films.remove(job);
                if let Some(view) = inner.emis.remove(job).and_then(|e| e.view()) {
                    inner.strategies.insert(job.to_string(), view);
                }
                tracing::info!(job_id = %job, "job done");
            }
            Some(BarrierAction::NextPass(_)) => {
                self.checkpoint(inner, job, upto, &changes, None, now_ms)?;
                self.work.notify_waiters();
            }
            Some(BarrierAction::Optimize) => {
                // the barrier and the update are persisted together (with the checkpoint)
                self.persist(inner, &changes, &[])?;
                self.optimize(inner, job, now_ms)?;
            }
            None if due => self.checkpoint(inner, job, upto, &changes, None, now_ms)?,
            None => self.persist(inner, &changes, &[])?,
        }
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

    /// An accepted result read back from the blob store (after a restart).
    fn stored_result(
        &self,
        inner: &Inner,
        job: &str,
        i: usize,
    ) -> Result<(TileAccum, Option<PilotData>), ServiceError> {
        let j = &inner.model.jobs[job];
        let t = &j.tiles[i];
        let bytes = self.blobs.get_result(job, i, t.epoch)?;
        let corrupt =
            |why: String| ServiceError::Io(std::io::Error::other(format!("stored result of tile {i}: {why}")));
        let (head, payload) = bytes.split_at_checked(16).ok_or_else(|| corrupt("too short".into()))?;
        let non_finite = u64::from_le_bytes(head[..8].try_into().expect("invariant: 8 bytes"));
        let pilot_bytes = u64::from_le_bytes(head[8..].try_into().expect("invariant: 8 bytes")) as usize;
        let image_bytes = payload.len().checked_sub(pilot_bytes).ok_or_else(|| corrupt("too short".into()))?;
        let (image, pilot) = payload.split_at(image_bytes);
        let (sum, count) = tessera_proto::decode_tile_payload(image, t.spec.rect.area())
            .ok_or_else(|| corrupt("wrong image size".into()))?;
        let pilot = match inner.emis.get(job) {
            Some(e) => e.decode_pilot(&t.spec, j.collects(i), pilot).map_err(corrupt)?,
            None => None,
        };
        Ok((TileAccum { rect: t.spec.rect, sum, count, non_finite }, pilot))
    }

    /// Writes the result EXR (with the EMIS layers and decisions) and PNG preview as blobs;
    /// returns their digests.
    fn write_outputs(&self, inner: &Inner, job: &str) -> Result<(String, String), ServiceError> {
        let spec = &inner.model.jobs[job].spec;
        let film = &inner.films[job];
        let text = |k: &str, v: String| (format!("tessera/{k}"), Attribute::Text(v));
        let mut extras = ExrExtras {
            counts: Some(&film.count),
            layers: Vec::new(),
            attributes: vec![
                text("integrator", spec.settings.integrator.to_string()),
                text("spp", film.count.iter().max().copied().unwrap_or(0).to_string()),
                text("seed", spec.settings.seed.unwrap_or(0).to_string()),
                text("scene", spec.name.clone()),
                text("job", job.to_string()),
            ],
        };
        let emis = inner.emis.get(job).map(|e| &e.state);
        let mask = emis.map(|e| e.merge_mask());
        if let (Some(e), Some(mask)) = (emis, &mask) {
            crate::local::add_emis_extras(e, mask, &mut extras);
        }
        Ok(self.blobs.put_outputs(film, &extras)?)
    }
}
