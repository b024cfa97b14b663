//! SQLite storage of jobs, tiles and workers (rusqlite, bundled SQLite, WAL journal with
//! `synchronous = FULL`, so a committed transition survives a crash of the process or the
//! machine).
//!
//! Rows mirror the model: a job row (spec, passes and per-worker failures as JSON), one row per
//! tile. The merged-prefix length `merged` is written only together with the film checkpoint
//! that contains exactly those tiles, in one transaction: that pairing is what makes merging
//! exactly-once across restarts. Tiles merged after the last checkpoint are stored as
//! `accepted` and merged again on start-up from their results, which the `results` table keeps
//! (written in the transaction that accepts them, deleted in the one that records the
//! checkpoint covering them: one commit per result, and no file per result). Results of a
//! megabyte or more are files instead (docs/decisions/0009-results-in-the-database.md).
//!
//! Deleting a job removes its job, tile and result rows in one transaction queued like any
//! other batch (so it lands after every earlier change of the job); the space is given back by
//! incremental auto-vacuum (see [`super::space`]).

use crate::serve::job::model::{Changes, Job, JobSpec, JobState, JobsModel, Pass, Tile, TileSpec, TileState};
use rusqlite::{Connection, OptionalExtension, params};
use std::path::Path;
use tessera_common::driver::Driver;
use tessera_common::film::Rect;

/// Storage failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StoreError {
    /// SQLite reported an error.
    #[error("database: {0}")]
    Sqlite(#[from] rusqlite::Error),
    /// A group commit that held this change failed (the first error is logged).
    #[error("database commit failed: {0}")]
    Commit(String),
    /// A stored row could not be decoded.
    #[error("database row of job {job}: {message}")]
    Corrupt {
        /// The job.
        job: String,
        /// What is wrong.
        message: String,
    },
}

/// Extra per-job facts that are not part of the state machine.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JobFiles {
    /// The film checkpoint holding `tiles[..merged]`.
    pub checkpoint: Option<String>,
    /// Digest of the result EXR.
    pub result_exr: Option<String>,
    /// Digest of the preview PNG.
    pub preview_png: Option<String>,
    /// EMIS: digest of the strategy PNG.
    pub strategy_png: Option<String>,
    /// EMIS: digest of the JSON report of every update.
    pub emis_json: Option<String>,
}

impl JobFiles {
    /// The digests of every output blob (not the checkpoint, which is a file of its own).
    pub fn outputs(&self) -> impl Iterator<Item = &String> {
        self.result_exr.iter().chain(&self.preview_png).chain(&self.strategy_png).chain(&self.emis_json)
    }
}

/// The blobs a finished job's outputs were stored as.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OutputDigests {
    /// The EXR.
    pub exr: String,
    /// The PNG preview.
    pub png: String,
    /// EMIS: the strategy PNG.
    pub strategy_png: Option<String>,
    /// EMIS: the JSON report.
    pub emis_json: Option<String>,
}

impl OutputDigests {
    /// Every digest.
    pub fn all(&self) -> impl Iterator<Item = &String> {
        [&self.exr, &self.png].into_iter().chain(&self.strategy_png).chain(&self.emis_json)
    }
}

/// Something to write with a transition.
#[derive(Clone, Debug)]
pub enum Extra {
    /// A film checkpoint now holds `tiles[..merged]`.
    Checkpoint {
        /// The job.
        job: String,
        /// Tiles in it.
        merged: usize,
        /// Its file name.
        file: String,
    },
    /// An accepted result's payload (`TileResultHeader`'s layout), kept until a checkpoint or the
    /// outputs cover its tile.
    Result {
        /// The job.
        job: String,
        /// Tile index.
        tile: usize,
        /// Lease epoch.
        epoch: u64,
        /// Non-finite samples the worker counted.
        non_finite: u64,
        /// The payload.
        payload: Vec<u8>,
    },
    /// The job's outputs were written from a film holding `tiles[..merged]`; they replace its
    /// checkpoint.
    Outputs {
        /// The job.
        job: String,
        /// Their blobs.
        outputs: OutputDigests,
        /// Tiles in them.
        merged: usize,
    },
}

/// A registered worker.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkerRow {
    /// Id.
    pub id: String,
    /// Host name or label.
    pub name: String,
    /// Render threads.
    pub threads: u32,
    /// Registration time.
    pub registered_ms: u64,
    /// Last contact.
    pub last_seen_ms: u64,
    /// SHA-256 (hex) of the secret a worker that keeps its identity registered with.
    pub secret_sha256: Option<String>,
    /// The address it registered from, which its failures are also counted against.
    pub host: Option<String>,
}

/// The database.
pub struct Store {
    pub(super) conn: Connection,
}

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY, seq INTEGER NOT NULL, spec TEXT NOT NULL, state TEXT NOT NULL,
    passes TEXT NOT NULL, worker_failures TEXT NOT NULL, error TEXT,
    created_ms INTEGER NOT NULL, started_ms INTEGER, finished_ms INTEGER,
    merged INTEGER NOT NULL DEFAULT 0, checkpoint TEXT, result_exr TEXT, preview_png TEXT,
    strategy_png TEXT, emis_json TEXT);
CREATE TABLE IF NOT EXISTS tiles (
    job_id TEXT NOT NULL, idx INTEGER NOT NULL, x0 INTEGER NOT NULL, y0 INTEGER NOT NULL,
    x1 INTEGER NOT NULL, y1 INTEGER NOT NULL, s0 INTEGER NOT NULL, s1 INTEGER NOT NULL,
    epoch INTEGER NOT NULL, state TEXT NOT NULL, worker TEXT, failures INTEGER NOT NULL,
    PRIMARY KEY (job_id, idx));
CREATE TABLE IF NOT EXISTS results (
    job_id TEXT NOT NULL, idx INTEGER NOT NULL, epoch INTEGER NOT NULL, non_finite INTEGER NOT NULL,
    payload BLOB NOT NULL, PRIMARY KEY (job_id, idx, epoch));
CREATE TABLE IF NOT EXISTS workers (
    id TEXT PRIMARY KEY, name TEXT NOT NULL, threads INTEGER NOT NULL,
    registered_ms INTEGER NOT NULL, last_seen_ms INTEGER NOT NULL, secret_sha256 TEXT, host TEXT);
";

/// The rows of one transition, taken from the model under the service's lock and written
/// later, possibly together with other batches (see `storage::commit`).
#[derive(Clone, Debug, Default)]
pub struct Batch {
    jobs: Vec<JobRow>,
    tiles: Vec<TileRow>,
    extras: Vec<Extra>,
    /// Jobs whose rows go, after the rest of the batch.
    deletes: Vec<String>,
}

#[derive(Clone, Debug)]
struct JobRow {
    id: String,
    seq: i64,
    spec: String,
    state: &'static str,
    passes: String,
    worker_failures: String,
    error: Option<String>,
    created_ms: i64,
    started_ms: Option<i64>,
    finished_ms: Option<i64>,
}

#[derive(Clone, Debug)]
struct TileRow {
    job: String,
    idx: i64,
    rect: Rect,
    samples: (u32, u32),
    epoch: i64,
    state: &'static str,
    worker: Option<String>,
    failures: u32,
}

impl Batch {
    /// The rows `changes` names from `model`, plus `extras`.
    pub fn of(model: &JobsModel, changes: &Changes, extras: &[Extra]) -> Batch {
        let mut batch = Batch { extras: extras.to_vec(), ..Batch::default() };
        for (id, tiles) in changes {
            let Some(job) = model.jobs.get(id) else { continue };
            batch.jobs.push(JobRow {
                id: job.id.clone(),
                seq: job.seq as i64,
                spec: json(&job.spec),
                state: job.state.as_str(),
                passes: json(&job.passes()),
                worker_failures: json(&job.worker_failures),
                error: job.error.clone(),
                created_ms: job.created_ms as i64,
                started_ms: job.started_ms().map(|t| t as i64),
                finished_ms: job.finished_ms.map(|t| t as i64),
            });
            for &i in tiles {
                let t = &job.tiles[i];
                let (state, worker) = match &t.state {
                    TileState::Queued => ("queued", None),
                    TileState::Leased { worker, .. } => ("leased", Some(worker.clone())),
                    // merged tiles are `accepted` until a checkpoint covers them (see module doc)
                    TileState::Accepted | TileState::Merged => ("accepted", None),
                };
                batch.tiles.push(TileRow {
                    job: id.clone(),
                    idx: i as i64,
                    rect: t.spec.rect,
                    samples: (t.spec.samples.start, t.spec.samples.end),
                    epoch: t.epoch as i64,
                    state,
                    worker,
                    failures: t.failures,
                });
            }
        }
        batch
    }

    /// Deletes every row of `jobs` (job, tiles, results).
    pub fn deleting(jobs: &[String]) -> Batch {
        Batch { deletes: jobs.to_vec(), ..Batch::default() }
    }

    /// Whether there is nothing to write.
    pub fn is_empty(&self) -> bool {
        self.jobs.is_empty() && self.tiles.is_empty() && self.extras.is_empty() && self.deletes.is_empty()
    }
}

fn write_extra(tx: &rusqlite::Transaction<'_>, extra: &Extra) -> Result<(), StoreError> {
    match extra {
        Extra::Checkpoint { job, merged, file } => {
            tx.execute(
                "UPDATE jobs SET merged = ?2, checkpoint = ?3 WHERE id = ?1",
                params![job, *merged as i64, file],
            )?;
            tx.execute("DELETE FROM results WHERE job_id = ?1 AND idx < ?2", params![job, *merged as i64])?
        }
        Extra::Outputs { job, outputs: o, merged } => {
            tx.execute(
                "UPDATE jobs SET result_exr = ?2, preview_png = ?3, strategy_png = ?4, emis_json = ?5, merged = ?6,
                    checkpoint = NULL WHERE id = ?1",
                params![job, o.exr, o.png, o.strategy_png, o.emis_json, *merged as i64],
            )?;
            tx.execute("DELETE FROM results WHERE job_id = ?1 AND idx < ?2", params![job, *merged as i64])?
        }
        Extra::Result { job, tile, epoch, non_finite, payload } => tx
            .prepare_cached(
                "INSERT OR REPLACE INTO results (job_id, idx, epoch, non_finite, payload) VALUES (?1, ?2, ?3, ?4, ?5)",
            )?
            .execute(params![job, *tile as i64, *epoch as i64, *non_finite as i64, payload])?,
    };
    Ok(())
}

fn json<T: serde::Serialize>(v: &T) -> String {
    serde_json::to_string(v).expect("invariant: plain data serialises")
}

impl Store {
    /// Returns the free pages to the file system and empties the write-ahead log (see
    /// `space.rs`); returns how many pages were freed.
    pub fn reclaim(&self) -> Result<u64, StoreError> {
        Ok(super::space::reclaim(&self.conn)?)
    }

    /// Opens (creating) the database file.
    pub fn open(path: &Path) -> Result<Store, StoreError> {
        let conn = Connection::open(path)?;
        // before the first table exists, or with a VACUUM for a database made without it
        super::space::use_incremental_vacuum(&conn)?;
        conn.pragma_update(None, "journal_mode", "WAL")?;
        conn.pragma_update(None, "synchronous", "FULL")?;
        conn.execute_batch(SCHEMA)?;
        // databases from before workers kept their identity and address, and before EMIS jobs
        // stored their strategy PNG and report
        let added =
            [("workers", "secret_sha256"), ("workers", "host"), ("jobs", "strategy_png"), ("jobs", "emis_json")];
        for (table, column) in added {
            let exists =
                conn.prepare("SELECT 1 FROM pragma_table_info(?1) WHERE name = ?2")?.exists(params![table, column])?;
            if !exists {
                conn.execute_batch(&format!("ALTER TABLE {table} ADD COLUMN {column} TEXT"))?;
            }
        }
        Ok(Store { conn })
    }

    /// Writes the rows `changes` names from `model`, plus `extras`, in one transaction.
    pub fn persist(&mut self, model: &JobsModel, changes: &Changes, extras: &[Extra]) -> Result<(), StoreError> {
        self.write(&[Batch::of(model, changes, extras)])
    }

    /// Writes `batches` in order in one transaction (one commit, one fsync: group commit).
    pub fn write(&mut self, batches: &[Batch]) -> Result<(), StoreError> {
        let tx = self.conn.transaction()?;
        for batch in batches {
            for j in &batch.jobs {
                tx.prepare_cached(
                    "INSERT INTO jobs (id, seq, spec, state, passes, worker_failures, error, created_ms, started_ms, finished_ms)
                     VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10)
                     ON CONFLICT(id) DO UPDATE SET state = ?4, passes = ?5, worker_failures = ?6, error = ?7,
                        started_ms = ?9, finished_ms = ?10",
                )?
                .execute(params![
                    j.id,
                    j.seq,
                    j.spec,
                    j.state,
                    j.passes,
                    j.worker_failures,
                    j.error,
                    j.created_ms,
                    j.started_ms,
                    j.finished_ms
                ])?;
            }
            let mut stmt = tx.prepare_cached(
                "INSERT OR REPLACE INTO tiles (job_id, idx, x0, y0, x1, y1, s0, s1, epoch, state, worker, failures)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12)",
            )?;
            for t in &batch.tiles {
                let r = t.rect;
                stmt.execute(params![
                    t.job,
                    t.idx,
                    r.x0,
                    r.y0,
                    r.x1,
                    r.y1,
                    t.samples.0,
                    t.samples.1,
                    t.epoch,
                    t.state,
                    t.worker,
                    t.failures
                ])?;
            }
            for extra in &batch.extras {
                write_extra(&tx, extra)?;
            }
            for job in &batch.deletes {
                for sql in [
                    "DELETE FROM results WHERE job_id = ?1",
                    "DELETE FROM tiles WHERE job_id = ?1",
                    "DELETE FROM jobs WHERE id = ?1",
                ] {
                    tx.prepare_cached(sql)?.execute([job])?;
                }
            }
        }
        tx.commit()?;
        Ok(())
    }

    /// Every job as last committed, with its files, or why its rows do not decode (with its
    /// id: one broken job must not keep the others from loading). Leased tiles get `deadline_ms`.
    #[allow(clippy::type_complexity)]
    pub fn load_jobs(
        &self,
        deadline_ms: u64,
    ) -> Result<Vec<Result<(Job, JobFiles), (String, StoreError)>>, StoreError> {
        let mut stmt = self.conn.prepare(
            "SELECT id, seq, spec, state, passes, worker_failures, error, created_ms, started_ms, finished_ms,
                    merged, checkpoint, result_exr, preview_png, strategy_png, emis_json FROM jobs ORDER BY seq",
        )?;
        let rows = stmt.query_map([], |r| {
            Ok((
                r.get::<_, String>(0)?,
                r.get::<_, i64>(1)?,
                r.get::<_, String>(2)?,
                r.get::<_, String>(3)?,
                r.get::<_, String>(4)?,
                r.get::<_, String>(5)?,
                r.get::<_, Option<String>>(6)?,
                r.get::<_, i64>(7)?,
                r.get::<_, Option<i64>>(8)?,
                r.get::<_, Option<i64>>(9)?,
                r.get::<_, i64>(10)?,
                JobFiles {
                    checkpoint: r.get(11)?,
                    result_exr: r.get(12)?,
                    preview_png: r.get(13)?,
                    strategy_png: r.get(14)?,
                    emis_json: r.get(15)?,
                },
            ))
        })?;
        let mut out = Vec::new();
        for row in rows {
            let row = row?;
            let id = row.0.clone();
            out.push(self.decode_job(row, deadline_ms).map_err(|e| (id, e)));
        }
        Ok(out)
    }

    #[allow(clippy::type_complexity)]
    fn decode_job(
        &self,
        row: (
            String,
            i64,
            String,
            String,
            String,
            String,
            Option<String>,
            i64,
            Option<i64>,
            Option<i64>,
            i64,
            JobFiles,
        ),
        deadline_ms: u64,
    ) -> Result<(Job, JobFiles), StoreError> {
        {
            let (id, seq, spec, state, passes, failures, error, created, started, finished, merged, files) = row;
            let corrupt = |message: String| StoreError::Corrupt { job: id.clone(), message };
            let spec = JobSpec::from_stored(&id, &spec).map_err(|e| corrupt(format!("spec: {e}")))?;
            let state: JobState =
                serde_json::from_value(serde_json::Value::String(state)).map_err(|e| corrupt(format!("state: {e}")))?;
            let passes: Vec<Pass> = serde_json::from_str(&passes).map_err(|e| corrupt(format!("passes: {e}")))?;
            let worker_failures =
                serde_json::from_str(&failures).map_err(|e| corrupt(format!("worker_failures: {e}")))?;
            let tiles = self.load_tiles(&id, merged as usize, deadline_ms)?;
            if merged as usize > tiles.len() {
                return Err(corrupt("more tiles merged than planned".into()));
            }
            let samples = |i: usize| tiles[i].spec.samples.clone();
            let driver = Driver::restore(spec.shape(), passes, started.map(|t| t as f64), tiles.len(), samples)
                .map_err(|e| corrupt(format!("tiles do not match passes: {e}")))?;
            let job = Job {
                id: id.clone(),
                seq: seq as u64,
                spec,
                state,
                driver,
                tiles,
                merged: merged as usize,
                worker_failures,
                last_failure: None,
                error,
                created_ms: created as u64,
                finished_ms: finished.map(|t| t as u64),
                slowest_ms_per_sample: None,
                index: Default::default(),
            };
            let mut job = job;
            job.reindex();
            Ok((job, files))
        }
    }

    /// Marks a job whose rows cannot be loaded as failed with `error`, so that it stays so.
    pub fn mark_failed(&self, job: &str, error: &str, now_ms: u64) -> Result<(), StoreError> {
        self.conn.execute(
            "UPDATE jobs SET state = 'failed', error = ?2, finished_ms = COALESCE(finished_ms, ?3) WHERE id = ?1",
            params![job, error, now_ms as i64],
        )?;
        Ok(())
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
            Ok((
                idx,
                Tile {
                    spec: TileSpec { rect, samples },
                    epoch: r.get::<_, i64>(7)? as u64,
                    state,
                    failures: r.get(10)?,
                },
            ))
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

    /// An accepted result not yet covered by a checkpoint: (non-finite count, payload).
    pub fn load_result(&self, job: &str, tile: usize, epoch: u64) -> Result<Option<(u64, Vec<u8>)>, StoreError> {
        Ok(self
            .conn
            .query_row(
                "SELECT non_finite, payload FROM results WHERE job_id = ?1 AND idx = ?2 AND epoch = ?3",
                params![job, tile as i64, epoch as i64],
                |r| Ok((r.get::<_, i64>(0)? as u64, r.get::<_, Vec<u8>>(1)?)),
            )
            .optional()?)
    }

    /// Registers or refreshes a worker.
    pub fn save_worker(&self, w: &WorkerRow) -> Result<(), StoreError> {
        self.conn.execute(
            "INSERT OR REPLACE INTO workers (id, name, threads, registered_ms, last_seen_ms, secret_sha256, host)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
            params![w.id, w.name, w.threads, w.registered_ms as i64, w.last_seen_ms as i64, w.secret_sha256, w.host],
        )?;
        Ok(())
    }

    /// Forgets the worker `id`.
    pub fn delete_worker(&self, id: &str) -> Result<(), StoreError> {
        self.conn.execute("DELETE FROM workers WHERE id = ?1", params![id])?;
        Ok(())
    }

    /// Every registered worker.
    pub fn load_workers(&self) -> Result<Vec<WorkerRow>, StoreError> {
        let mut stmt = self
            .conn
            .prepare("SELECT id, name, threads, registered_ms, last_seen_ms, secret_sha256, host FROM workers")?;
        let rows = stmt.query_map([], |r| {
            Ok(WorkerRow {
                id: r.get(0)?,
                name: r.get(1)?,
                threads: r.get(2)?,
                registered_ms: r.get::<_, i64>(3)? as u64,
                last_seen_ms: r.get::<_, i64>(4)? as u64,
                secret_sha256: r.get(5)?,
                host: r.get(6)?,
            })
        })?;
        Ok(rows.collect::<Result<_, _>>()?)
    }

    /// The stored files of a job.
    pub fn job_files(&self, job: &str) -> Result<Option<JobFiles>, StoreError> {
        Ok(self
            .conn
            .query_row(
                "SELECT checkpoint, result_exr, preview_png, strategy_png, emis_json FROM jobs WHERE id = ?1",
                [job],
                |r| {
                    Ok(JobFiles {
                        checkpoint: r.get(0)?,
                        result_exr: r.get(1)?,
                        preview_png: r.get(2)?,
                        strategy_png: r.get(3)?,
                        emis_json: r.get(4)?,
                    })
                },
            )
            .optional()?)
    }
}

#[cfg(test)]
#[path = "sqlite_tests.rs"]
mod tests;
