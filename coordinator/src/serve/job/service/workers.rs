//! The workers as operators see and steer them: each one's state (idle, busy, disabled,
//! draining, offline) and tags, and the modes an operator sets from the server: disable (no
//! new tiles), enable, and drain (no new tiles, and the worker is told to stop once it holds
//! none). Modes are stored, so they outlive restarts of either side.

use super::{Inner, JobService, ServiceError};
use crate::serve::job::view::WorkerView;
use crate::serve::storage::{WorkerMode, WorkerRow};

impl JobService {
    /// Registered workers with their state and current leases.
    pub fn workers(&self, now_ms: u64) -> Vec<WorkerView> {
        let inner = self.lock();
        inner.workers.values().map(|w| self.worker_view(&inner, w, now_ms)).collect()
    }

    pub(super) fn worker_view(&self, inner: &Inner, w: &WorkerRow, now_ms: u64) -> WorkerView {
        let leases = inner.model.leases_of(&w.id).len();
        let silent_ms = now_ms.saturating_sub(w.last_seen_ms);
        let state = match w.mode {
            _ if silent_ms > self.cfg.lease_timeout_ms => "offline",
            WorkerMode::Disabled => "disabled",
            WorkerMode::Draining => "draining",
            WorkerMode::Enabled if leases > 0 => "busy",
            WorkerMode::Enabled => "idle",
        };
        WorkerView {
            id: w.id.clone(),
            name: w.name.clone(),
            threads: w.threads,
            last_seen_s_ago: silent_ms as f64 / 1000.0,
            leases,
            state,
            tags: w.tags.clone(),
        }
    }

    /// Whether a live, enabled worker has every tag `job` requires.
    pub(super) fn anyone_serves(&self, inner: &Inner, job: &crate::serve::job::model::Job, now_ms: u64) -> bool {
        inner.workers.values().any(|w| {
            w.mode == WorkerMode::Enabled
                && now_ms.saturating_sub(w.last_seen_ms) <= self.cfg.lease_timeout_ms
                && inner.model.serves(&w.id, job)
        })
    }

    /// Whether an operator drains `worker` (it is told so with every lease answer).
    pub fn draining(&self, worker: &str) -> bool {
        self.lock().workers.get(worker).is_some_and(|w| w.mode == WorkerMode::Draining)
    }

    /// Sets the mode of a worker named by its id or a unique prefix of at least 6 characters;
    /// answers with its view once stored.
    pub fn set_worker_mode(&self, id: &str, mode: WorkerMode, now_ms: u64) -> Result<WorkerView, ServiceError> {
        let mut inner = self.lock();
        let id = resolve_worker(&inner, id)?;
        let row = inner.workers.get_mut(&id).expect("invariant: just resolved");
        row.mode = mode;
        let row = row.clone();
        self.commits.store().save_worker(&row)?;
        tracing::info!(worker_id = %id, mode = mode.as_str(), "worker mode set");
        // an enabled worker may lease now; the others' long polls answer their drain
        self.work.notify_waiters();
        Ok(self.worker_view(&inner, &row, now_ms))
    }
}

/// The worker `id` names: its id, or a unique prefix of at least
/// [`crate::serve::job::model::MIN_ID_PREFIX`] characters.
fn resolve_worker(inner: &Inner, id: &str) -> Result<String, ServiceError> {
    if inner.workers.contains_key(id) {
        return Ok(id.to_string());
    }
    let not_found = || ServiceError::NotFound(format!("worker {id} not found"));
    if id.len() < crate::serve::job::model::MIN_ID_PREFIX {
        return Err(not_found());
    }
    let mut matches = inner.workers.range(id.to_string()..).map(|(k, _)| k).take_while(|k| k.starts_with(id));
    match (matches.next(), matches.count()) {
        (Some(k), 0) => Ok(k.clone()),
        (Some(_), more) => Err(ServiceError::InvalidArgument(format!(
            "worker id prefix {id} matches {} workers: give more of the id",
            more + 1
        ))),
        (None, _) => Err(not_found()),
    }
}
