//! The workers a coordinator knows, as rows: identity, address, tags and the mode an operator
//! set (enabled, disabled, draining), so that all of it outlives a restart.

use super::{Store, StoreError};
use rusqlite::params;

/// Whether a worker is given work, as an operator set it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WorkerMode {
    /// It is.
    #[default]
    Enabled,
    /// It is not: what it holds it finishes, then it idles.
    Disabled,
    /// It is not, and it is told to stop once what it holds is done (a worker started with
    /// `--exit-when-drained` exits then).
    Draining,
}

impl WorkerMode {
    /// Lowercase name, as stored and shown.
    pub fn as_str(self) -> &'static str {
        match self {
            WorkerMode::Enabled => "enabled",
            WorkerMode::Disabled => "disabled",
            WorkerMode::Draining => "draining",
        }
    }

    fn parse(s: Option<String>) -> WorkerMode {
        match s.as_deref() {
            Some("disabled") => WorkerMode::Disabled,
            Some("draining") => WorkerMode::Draining,
            _ => WorkerMode::Enabled,
        }
    }
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
    /// Its tags (`--tags`): it is given only jobs whose required tags it all has.
    pub tags: Vec<String>,
    /// Whether it is given work.
    pub mode: WorkerMode,
}

impl Store {
    /// Registers or refreshes a worker.
    pub fn save_worker(&self, w: &WorkerRow) -> Result<(), StoreError> {
        let tags = serde_json::to_string(&w.tags).expect("invariant: strings serialise");
        self.conn.execute(
            "INSERT OR REPLACE INTO workers (id, name, threads, registered_ms, last_seen_ms, secret_sha256, host, tags, mode)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)",
            params![
                w.id,
                w.name,
                w.threads,
                w.registered_ms as i64,
                w.last_seen_ms as i64,
                w.secret_sha256,
                w.host,
                tags,
                w.mode.as_str()
            ],
        )?;
        Ok(())
    }

    /// Forgets the worker `id`.
    pub fn delete_worker(&self, id: &str) -> Result<(), StoreError> {
        self.conn.execute("DELETE FROM workers WHERE id = ?1", params![id])?;
        Ok(())
    }

    /// Every registered worker (tags that do not decode are dropped: the worker sends them
    /// again when it registers).
    pub fn load_workers(&self) -> Result<Vec<WorkerRow>, StoreError> {
        let mut stmt = self.conn.prepare(
            "SELECT id, name, threads, registered_ms, last_seen_ms, secret_sha256, host, tags, mode FROM workers",
        )?;
        let rows = stmt.query_map([], |r| {
            let tags: Option<String> = r.get(7)?;
            Ok(WorkerRow {
                id: r.get(0)?,
                name: r.get(1)?,
                threads: r.get(2)?,
                registered_ms: r.get::<_, i64>(3)? as u64,
                last_seen_ms: r.get::<_, i64>(4)? as u64,
                secret_sha256: r.get(5)?,
                host: r.get(6)?,
                tags: tags.and_then(|t| serde_json::from_str(&t).ok()).unwrap_or_default(),
                mode: WorkerMode::parse(r.get(8)?),
            })
        })?;
        Ok(rows.collect::<Result<_, _>>()?)
    }
}
