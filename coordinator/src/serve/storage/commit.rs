//! Group commit: transitions are queued in the order the service makes them (under its lock)
//! and written by whichever waiting caller gets there first, all queued batches in one SQLite
//! transaction, so concurrent uploads share one commit (one fsync) instead of each paying for
//! its own while holding the service's lock.
//!
//! Durability is unchanged: a caller answers only after [`Committer::wait`] returned for its
//! ticket, i.e. after the transaction holding its batch committed with `synchronous = FULL`.
//! Batches are written in ticket order, so a later state of a row never loses to an earlier one.
//!
//! A failed commit is fail-stop: the service's memory has run ahead of the database, so no later
//! batch is written and no caller is answered as if its change were saved; the process stops
//! (see [`Committer::new`]) and the next start rebuilds from what the database holds.

use super::sqlite::{Batch, Store, StoreError};
use std::sync::{Condvar, Mutex, MutexGuard};

/// A position in the commit queue; `wait(ticket)` returns once it is durable.
pub type Ticket = u64;

#[derive(Default)]
struct Queue {
    pending: Vec<Batch>,
    /// Tickets handed out (the last one).
    enqueued: Ticket,
    /// Every ticket up to this one is written (or failed).
    committed: Ticket,
    /// A caller is writing a group now.
    writing: bool,
    /// The first failed commit: every ticket from then on fails.
    failed: Option<String>,
}

/// What happens after a failed commit (besides refusing every later one).
pub type OnFailure = Box<dyn Fn(&str) + Send + Sync>;

/// The commit queue in front of the database.
pub struct Committer {
    queue: Mutex<Queue>,
    done: Condvar,
    store: Mutex<Store>,
    on_failure: OnFailure,
    /// Test hook: commits left before one fails.
    #[cfg(test)]
    pub(crate) fail_after: std::sync::atomic::AtomicI64,
}

fn relock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // the queue and the store stay consistent across a panic (a failed group is recorded)
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Committer {
    /// Wraps an open store; a failed commit stops the process.
    pub fn new(store: Store) -> Committer {
        Committer::with_on_failure(
            store,
            Box::new(|error| {
                tracing::error!(%error, "database commit failed: stopping (the next start resumes from the database)");
                std::process::exit(70);
            }),
        )
    }

    /// Wraps an open store; `on_failure` runs once, at the first failed commit.
    pub fn with_on_failure(store: Store, on_failure: OnFailure) -> Committer {
        Committer {
            queue: Mutex::new(Queue::default()),
            done: Condvar::new(),
            store: Mutex::new(store),
            on_failure,
            #[cfg(test)]
            fail_after: std::sync::atomic::AtomicI64::new(i64::MAX),
        }
    }

    fn write(&self, group: &[Batch]) -> Result<(), StoreError> {
        #[cfg(test)]
        if self.fail_after.fetch_sub(1, std::sync::atomic::Ordering::Relaxed) <= 0 {
            return Err(StoreError::Commit("injected commit failure".into()));
        }
        relock(&self.store).write(group)
    }

    /// The store, for reads and for writes outside the queue (worker rows).
    pub fn store(&self) -> MutexGuard<'_, Store> {
        relock(&self.store)
    }

    /// Queues a batch; call in the order the transitions were made.
    pub fn enqueue(&self, batch: Batch) -> Ticket {
        let mut q = relock(&self.queue);
        q.pending.push(batch);
        q.enqueued += 1;
        q.enqueued
    }

    /// Returns once `ticket` is committed, writing the queued group itself if nobody else is.
    pub fn wait(&self, ticket: Ticket) -> Result<(), StoreError> {
        let mut q = relock(&self.queue);
        loop {
            if let Some(e) = &q.failed {
                return Err(StoreError::Commit(e.clone()));
            }
            if q.committed >= ticket {
                return Ok(());
            }
            if q.writing {
                q = self.done.wait(q).unwrap_or_else(|p| p.into_inner());
                continue;
            }
            q.writing = true;
            let group = std::mem::take(&mut q.pending);
            let last = q.enqueued;
            drop(q);
            let written = self.write(&group);
            q = relock(&self.queue);
            q.writing = false;
            q.committed = last;
            if let Err(e) = written {
                tracing::error!(error = %e, batches = group.len(), "database commit failed");
                q.failed = Some(e.to_string());
                (self.on_failure)(&e.to_string());
            }
            self.done.notify_all();
        }
    }
}
