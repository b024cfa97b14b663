//! Giving the database's space back after jobs are deleted. SQLite keeps freed pages in its
//! file unless auto-vacuum is on; the database uses `auto_vacuum = INCREMENTAL`, so the pages
//! are returned on request ([`reclaim`], run by `Store::reclaim` after deletes) instead of on every commit,
//! which would move pages around while uploads wait. A database made before this (mode NONE)
//! is switched over with one `VACUUM` when it is opened.
//!
//! In WAL mode the file only shrinks when the log is checkpointed, so [`reclaim`] also
//! checkpoints with `TRUNCATE`, which empties the `-wal` file as well
//! (docs/decisions/0016-deleting-jobs.md has the measurement).

use rusqlite::Connection;

/// `PRAGMA auto_vacuum` value of INCREMENTAL.
const INCREMENTAL: i64 = 2;

/// Turns on incremental auto-vacuum: set before the first table exists it takes effect at once;
/// an existing database needs a `VACUUM` (once, at start-up: it rewrites the whole file).
pub(super) fn use_incremental_vacuum(conn: &Connection) -> rusqlite::Result<()> {
    let mode: i64 = conn.pragma_query_value(None, "auto_vacuum", |r| r.get(0))?;
    if mode == INCREMENTAL {
        return Ok(());
    }
    conn.pragma_update(None, "auto_vacuum", "INCREMENTAL")?;
    let tables: i64 = conn.query_row("SELECT count(*) FROM sqlite_master", [], |r| r.get(0))?;
    if tables > 0 {
        tracing::info!("switching the database to incremental auto-vacuum (one VACUUM)");
        conn.execute_batch("VACUUM")?;
    }
    Ok(())
}

/// Returns the free pages to the file system and empties the write-ahead log; returns how many
/// pages were freed.
pub(super) fn reclaim(conn: &Connection) -> rusqlite::Result<u64> {
    let free: i64 = conn.pragma_query_value(None, "freelist_count", |r| r.get(0))?;
    if free > 0 {
        // each step frees one page and yields a row: run it to the end
        let mut stmt = conn.prepare("PRAGMA incremental_vacuum")?;
        let mut rows = stmt.query([])?;
        while rows.next()?.is_some() {}
    }
    conn.query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()))?;
    Ok(free.max(0) as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serve::job::model::calls::Calls;
    use crate::serve::job::model::{Changes, JobSpec, JobsModel};
    use crate::serve::storage::Extra;
    use crate::serve::storage::sqlite::{Batch, Store};
    use tessera_common::settings::IntegratorName;

    fn spec() -> JobSpec {
        JobSpec::bare("n", IntegratorName::Pt, Some(1), 256, 256)
    }

    fn count(store: &Store, table: &str, job: &str) -> i64 {
        let column = if table == "jobs" { "id" } else { "job_id" };
        store.conn.query_row(&format!("SELECT count(*) FROM {table} WHERE {column} = ?1"), [job], |r| r.get(0)).unwrap()
    }

    #[test]
    fn deleting_a_job_removes_its_rows_and_shrinks_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("db.sqlite");
        let mut store = Store::open(&path).unwrap();
        let mut m = JobsModel::default();
        for id in ["big", "small"] {
            let c = m.submit(id, spec(), 1).unwrap();
            store.persist(&m, &c, &[]).unwrap();
        }
        // 4 MB of accepted results for "big" (incompressible, so the pages are really used)
        let results: Vec<Extra> = (0..16)
            .map(|tile| Extra::Result {
                job: "big".into(),
                tile,
                epoch: 0,
                non_finite: 0,
                payload: (0..256 << 10).map(|i: u32| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect(),
            })
            .collect();
        store.persist(&m, &Changes::new(), &results).unwrap();
        store.reclaim().unwrap();
        let before = std::fs::metadata(&path).unwrap().len();
        assert!(before > 4 << 20, "{before}");
        m.cancel("big", 2).unwrap();
        m.remove("big").unwrap();
        store.write(&[Batch::deleting(&["big".into()])]).unwrap();
        for table in ["jobs", "tiles", "results"] {
            assert_eq!(count(&store, table, "big"), 0, "{table}");
        }
        assert_eq!((count(&store, "jobs", "small"), count(&store, "tiles", "small")), (1, 16));
        let freed = store.reclaim().unwrap();
        let after = std::fs::metadata(&path).unwrap().len();
        assert!(freed > 1000 && after + (4 << 20) <= before, "{before} -> {after} bytes, {freed} pages freed");
        assert_eq!(std::fs::metadata(dir.path().join("db.sqlite-wal")).map_or(0, |m| m.len()), 0);
        // what is left still loads
        let loaded = store.load_jobs(0).unwrap();
        assert_eq!(loaded.len(), 1);
        assert_eq!(loaded[0].as_ref().unwrap().0.id, "small");
    }

    #[test]
    fn a_database_made_without_auto_vacuum_is_switched_on_open() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("db.sqlite");
        {
            let conn = Connection::open(&path).unwrap();
            conn.pragma_update(None, "journal_mode", "WAL").unwrap();
            conn.execute_batch("CREATE TABLE workers (id TEXT PRIMARY KEY, name TEXT NOT NULL, threads INTEGER NOT NULL, registered_ms INTEGER NOT NULL, last_seen_ms INTEGER NOT NULL); INSERT INTO workers VALUES ('w', 'n', 2, 1, 2);").unwrap();
            let mode: i64 = conn.pragma_query_value(None, "auto_vacuum", |r| r.get(0)).unwrap();
            assert_eq!(mode, 0);
        }
        let store = Store::open(&path).unwrap();
        let mode: i64 = store.conn.pragma_query_value(None, "auto_vacuum", |r| r.get(0)).unwrap();
        assert_eq!(mode, INCREMENTAL);
        assert_eq!(store.load_workers().unwrap().len(), 1, "the rows survive the VACUUM");
        drop(store);
        let fresh = Store::open(&dir.path().join("fresh.sqlite")).unwrap();
        let mode: i64 = fresh.conn.pragma_query_value(None, "auto_vacuum", |r| r.get(0)).unwrap();
        assert_eq!(mode, INCREMENTAL, "a new database has it from the start");
    }
}
