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

use crate::serve::job::model::{Changes, JobsModel, TileState};
use rusqlite::{Connection, OptionalExtension, params};
use std::path::Path;
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
    strategy_png TEXT, emis_json TEXT, paused_ms INTEGER, priority INTEGER, decided TEXT);
CREATE TABLE IF NOT EXISTS tiles (
    job_id TEXT NOT NULL, idx INTEGER NOT NULL, x0 INTEGER NOT NULL, y0 INTEGER NOT NULL,
    x1 INTEGER NOT NULL, y1 INTEGER NOT NULL, s0 INTEGER NOT NULL, s1 INTEGER NOT NULL,
    epoch INTEGER NOT NULL, state TEXT NOT NULL, worker TEXT, failures INTEGER NOT NULL,
    PRIMARY KEY (job_id, idx));
CREATE TABLE IF NOT EXISTS sequences (
    id TEXT PRIMARY KEY, seq INTEGER NOT NULL, spec TEXT NOT NULL, created_ms INTEGER NOT NULL,
    cancelled INTEGER NOT NULL DEFAULT 0, paused_ms INTEGER);
CREATE TABLE IF NOT EXISTS results (
    job_id TEXT NOT NULL, idx INTEGER NOT NULL, epoch INTEGER NOT NULL, non_finite INTEGER NOT NULL,
    payload BLOB NOT NULL, PRIMARY KEY (job_id, idx, epoch));
CREATE TABLE IF NOT EXISTS workers (
    id TEXT PRIMARY KEY, name TEXT NOT NULL, threads INTEGER NOT NULL,
    registered_ms INTEGER NOT NULL, last_seen_ms INTEGER NOT NULL, secret_sha256 TEXT, host TEXT, tags TEXT,
    mode TEXT);
";

/// A sequence's row: id, seq, spec JSON, created, cancelled, paused since.
type SequenceRow = (String, i64, String, i64, bool, Option<i64>);

/// The rows of one transition, taken from the model under the service's lock and written
/// later, possibly together with other batches (see `storage::commit`).
#[derive(Clone, Debug, Default)]
pub struct Batch {
    jobs: Vec<JobRow>,
    tiles: Vec<TileRow>,
    extras: Vec<Extra>,
    /// Sequences (jobs of many frames) whose row changed.
    sequences: Vec<SequenceRow>,
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
    paused_ms: Option<i64>,
    priority: i32,
    decided: Option<String>,
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
            if let Some(s) = model.sequences.get(id) {
                let paused_ms = s.paused_ms.map(|t| t as i64);
                batch.sequences.push((
                    s.id.clone(),
                    s.seq as i64,
                    json(&s.spec),
                    s.created_ms as i64,
                    s.cancelled,
                    paused_ms,
                ));
            }
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
                paused_ms: job.paused_ms.map(|t| t as i64),
                priority: job.spec.priority,
                decided: job.decided.as_ref().map(json),
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
        self.jobs.is_empty()
            && self.tiles.is_empty()
            && self.extras.is_empty()
            && self.deletes.is_empty()
            && self.sequences.is_empty()
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
        // databases from before workers kept their identity and address, before EMIS jobs
        // stored their strategy PNG and report, before jobs could be paused or reprioritised, and
        // before workers had tags and could be disabled, and before frames started warm
        let added = [
            ("workers", "secret_sha256", "TEXT"),
            ("workers", "host", "TEXT"),
            ("jobs", "strategy_png", "TEXT"),
            ("jobs", "emis_json", "TEXT"),
            ("jobs", "paused_ms", "INTEGER"),
            ("jobs", "priority", "INTEGER"),
            ("workers", "tags", "TEXT"),
            ("workers", "mode", "TEXT"),
            ("jobs", "decided", "TEXT"),
        ];
        for (table, column, kind) in added {
            let exists =
                conn.prepare("SELECT 1 FROM pragma_table_info(?1) WHERE name = ?2")?.exists(params![table, column])?;
            if !exists {
                conn.execute_batch(&format!("ALTER TABLE {table} ADD COLUMN {column} {kind}"))?;
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
                    "INSERT INTO jobs (id, seq, spec, state, passes, worker_failures, error, created_ms, started_ms,
                        finished_ms, paused_ms, priority, decided)
                     VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13)
                     ON CONFLICT(id) DO UPDATE SET state = ?4, passes = ?5, worker_failures = ?6, error = ?7,
                        started_ms = ?9, finished_ms = ?10, paused_ms = ?11, priority = ?12, decided = ?13",
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
                    j.finished_ms,
                    j.paused_ms,
                    j.priority,
                    j.decided
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
            for (id, seq, spec, created_ms, cancelled, paused_ms) in &batch.sequences {
                tx.prepare_cached(
                    "INSERT OR REPLACE INTO sequences (id, seq, spec, created_ms, cancelled, paused_ms)
                     VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                )?
                .execute(params![id, seq, spec, created_ms, cancelled, paused_ms])?;
            }
            for job in &batch.deletes {
                for sql in [
                    "DELETE FROM results WHERE job_id = ?1",
                    "DELETE FROM tiles WHERE job_id = ?1",
                    "DELETE FROM jobs WHERE id = ?1",
                    "DELETE FROM sequences WHERE id = ?1",
                ] {
                    tx.prepare_cached(sql)?.execute([job])?;
                }
            }
        }
        tx.commit()?;
        Ok(())
    }

    /// Marks a job whose rows cannot be loaded as failed with `error`, so that it stays so.
    pub fn mark_failed(&self, job: &str, error: &str, now_ms: u64) -> Result<(), StoreError> {
        self.conn.execute(
            "UPDATE jobs SET state = 'failed', error = ?2, finished_ms = COALESCE(finished_ms, ?3) WHERE id = ?1",
            params![job, error, now_ms as i64],
        )?;
        Ok(())
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

mod load;
mod workers;

pub use workers::{WorkerMode, WorkerRow};

#[cfg(test)]
#[path = "sqlite_tests.rs"]
mod tests;
