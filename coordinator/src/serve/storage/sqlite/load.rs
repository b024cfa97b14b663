//! Loading jobs back at start-up: each job row with its tiles, decoded into the model's
//! [`Job`] with its driver restored, or the reason it cannot be (one broken job must not keep
//! the others from loading).

use super::{JobFiles, Store, StoreError};
use crate::serve::job::model::{Job, JobSpec, JobState, Pass, Sequence, Tile, TileSpec, TileState};
use rusqlite::OptionalExtension;
use tessera_common::driver::Driver;
use tessera_common::film::Rect;

/// A job row as stored.
struct JobRow {
    id: String,
    seq: i64,
    spec: String,
    state: String,
    passes: String,
    worker_failures: String,
    error: Option<String>,
    created_ms: i64,
    started_ms: Option<i64>,
    finished_ms: Option<i64>,
    merged: i64,
    paused_ms: Option<i64>,
    priority: Option<i32>,
    decided: Option<String>,
    files: JobFiles,
}

impl Store {
    /// Every job as last committed, with its files, or why its rows do not decode (with its
    /// id). Leased tiles get `deadline_ms`.
    #[allow(clippy::type_complexity)]
    pub fn load_jobs(
        &self,
        deadline_ms: u64,
    ) -> Result<Vec<Result<(Job, JobFiles), (String, StoreError)>>, StoreError> {
        let mut stmt = self.conn.prepare(
            "SELECT id, seq, spec, state, passes, worker_failures, error, created_ms, started_ms, finished_ms,
                    merged, checkpoint, result_exr, preview_png, strategy_png, emis_json, paused_ms, priority,
                    decided
             FROM jobs ORDER BY seq",
        )?;
        let rows = stmt.query_map([], |r| {
            Ok(JobRow {
                id: r.get(0)?,
                seq: r.get(1)?,
                spec: r.get(2)?,
                state: r.get(3)?,
                passes: r.get(4)?,
                worker_failures: r.get(5)?,
                error: r.get(6)?,
                created_ms: r.get(7)?,
                started_ms: r.get(8)?,
                finished_ms: r.get(9)?,
                merged: r.get(10)?,
                files: JobFiles {
                    checkpoint: r.get(11)?,
                    result_exr: r.get(12)?,
                    preview_png: r.get(13)?,
                    strategy_png: r.get(14)?,
                    emis_json: r.get(15)?,
                },
                paused_ms: r.get(16)?,
                priority: r.get(17)?,
                decided: r.get(18)?,
            })
        })?;
        let mut out = Vec::new();
        for row in rows {
            let row = row?;
            let id = row.id.clone();
            out.push(self.decode_job(row, deadline_ms).map_err(|e| (id, e)));
        }
        Ok(out)
    }

    fn decode_job(&self, row: JobRow, deadline_ms: u64) -> Result<(Job, JobFiles), StoreError> {
        let id = row.id;
        let corrupt = |message: String| StoreError::Corrupt { job: id.clone(), message };
        let mut spec = JobSpec::from_stored(&id, &row.spec).map_err(|e| corrupt(format!("spec: {e}")))?;
        // changed after submission (null in rows from before priorities could change)
        if let Some(priority) = row.priority {
            spec.priority = priority;
        }
        let state: JobState =
            serde_json::from_value(serde_json::Value::String(row.state)).map_err(|e| corrupt(format!("state: {e}")))?;
        let passes: Vec<Pass> = serde_json::from_str(&row.passes).map_err(|e| corrupt(format!("passes: {e}")))?;
        let worker_failures =
            serde_json::from_str(&row.worker_failures).map_err(|e| corrupt(format!("worker_failures: {e}")))?;
        let decided = row.decided.map(|d| serde_json::from_str(&d)).transpose();
        let decided = decided.map_err(|e| corrupt(format!("decided: {e}")))?;
        let merged = row.merged as usize;
        let tiles = self.load_tiles(&id, merged, deadline_ms)?;
        if merged > tiles.len() {
            return Err(corrupt("more tiles merged than planned".into()));
        }
        let samples = |i: usize| tiles[i].spec.samples.clone();
        let driver = Driver::restore(spec.shape(), passes, row.started_ms.map(|t| t as f64), tiles.len(), samples)
            .map_err(|e| corrupt(format!("tiles do not match passes: {e}")))?;
        let mut job = Job {
            id: id.clone(),
            seq: row.seq as u64,
            spec,
            state,
            driver,
            tiles,
            merged,
            worker_failures,
            last_failure: None,
            error: row.error,
            created_ms: row.created_ms as u64,
            finished_ms: row.finished_ms.map(|t| t as u64),
            slowest_ms_per_sample: None,
            index: Default::default(),
            paused_ms: row.paused_ms.map(|t| t as u64),
            decided,
        };
        job.reindex();
        Ok((job, row.files))
    }

    fn load_tiles(&self, job: &str, merged: usize, deadline_ms: u64) -> Result<Vec<Tile>, StoreError> {
        let mut stmt = self.conn.prepare_cached(
            "SELECT idx, x0, y0, x1, y1, s0, s1, epoch, state, worker, failures FROM tiles WHERE job_id = ?1 ORDER BY idx",
        )?;
        let rows = stmt.query_map([job], |r| {
            let idx: i64 = r.get(0)?;
            let rect = Rect { x0: r.get(1)?, y0: r.get(2)?, x1: r.get(3)?, y1: r.get(4)? };
            let samples = r.get::<_, u32>(5)?..r.get::<_, u32>(6)?;
            let state = match (r.get::<_, String>(8)?.as_str(), r.get::<_, Option<String>>(9)?) {
                ("leased", Some(worker)) => TileState::Leased { worker, deadline_ms, since_ms: deadline_ms },
                ("accepted", _) if (idx as usize) < merged => TileState::Merged,
                ("accepted", _) => TileState::Accepted,
                _ => TileState::Queued,
            };
            let tile = Tile {
                spec: TileSpec { rect, samples },
                epoch: r.get::<_, i64>(7)? as u64,
                state,
                failures: r.get(10)?,
            };
            Ok((idx, tile))
        })?;
        let mut tiles = Vec::new();
        for row in rows {
            let (idx, tile) = row?;
            if idx as usize != tiles.len() {
                return Err(StoreError::Corrupt { job: job.to_string(), message: format!("tile {idx} out of order") });
            }
            tiles.push(tile);
        }
        Ok(tiles)
    }

    /// The tiles a job's last checkpoint (or its outputs) holds, as committed.
    pub fn checkpointed(&self, job: &str) -> Result<Option<usize>, StoreError> {
        let merged = self.conn.query_row("SELECT merged FROM jobs WHERE id = ?1", [job], |r| r.get::<_, i64>(0));
        Ok(merged.optional()?.map(|m| m as usize))
    }

    /// Every sequence (job of many frames) as committed, with no frame planned: the caller
    /// counts the frames loaded as jobs. A row that does not decode is skipped and logged (its
    /// frames still load as jobs).
    pub fn load_sequences(&self) -> Result<Vec<Sequence>, StoreError> {
        let mut stmt =
            self.conn.prepare("SELECT id, seq, spec, created_ms, cancelled, paused_ms FROM sequences ORDER BY seq")?;
        let rows = stmt.query_map([], |r| {
            let row: (String, i64, String, i64, bool, Option<i64>) =
                (r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?, r.get(4)?, r.get(5)?);
            Ok(row)
        })?;
        let mut out = Vec::new();
        for row in rows {
            let (id, seq, spec, created_ms, cancelled, paused_ms) = row?;
            match serde_json::from_str(&spec) {
                Ok(spec) => out.push(Sequence {
                    id,
                    seq: seq as u64,
                    spec,
                    created_ms: created_ms as u64,
                    planned: 0,
                    cancelled,
                    paused_ms: paused_ms.map(|t| t as u64),
                }),
                Err(e) => tracing::error!(sequence = %id, error = %e, "cannot load a sequence's row"),
            }
        }
        Ok(out)
    }
}
