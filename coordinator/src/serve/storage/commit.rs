//! Group commit: transitions are queued in the order the service makes them (under its lock)
//! and written by whichever waiting caller gets there first, all queued batches in one SQLite
//! transaction, so concurrent uploads share one commit (one fsync) instead of each paying for
//! its own while holding the service's lock.
//!
//! Durability is unchanged: a caller answers only after [`Committer::wait`] returned for its
//! ticket, i.e. after the transaction holding its batch committed with `synchronous = FULL`.
//! Batches are written in ticket order, so a later state of a row never loses to an earlier one.

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
    /// Failed groups: (first ticket, last ticket, error).
    failed: Vec<(Ticket, Ticket, String)>,
}

/// The commit queue in front of the database.
pub struct Committer {
    queue: Mutex<Queue>,
    done: Condvar,
    store: Mutex<Store>,
}

fn relock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // the queue and the store stay consistent across a panic (a failed group is recorded)
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Committer {
    /// Wraps an open store.
    pub fn new(store: Store) -> Committer {
        Committer { queue: Mutex::new(Queue::default()), done: Condvar::new(), store: Mutex::new(store) }
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
            if q.committed >= ticket {
                return match q.failed.iter().find(|(a, b, _)| (*a..=*b).contains(&ticket)) {
                    Some((_, _, e)) => Err(StoreError::Commit(e.clone())),
                    None => Ok(()),
                };
            }
            if q.writing {
                q = self.done.wait(q).unwrap_or_else(|p| p.into_inner());
                continue;
            }
            q.writing = true;
            let group = std::mem::take(&mut q.pending);
            let (first, last) = (q.committed + 1, q.enqueued);
            drop(q);
            let written = relock(&self.store).write(&group);
            q = relock(&self.queue);
            q.writing = false;
            q.committed = last;
            if let Err(e) = written {
                tracing::error!(error = %e, batches = group.len(), "database commit failed");
                q.failed.push((first, last, e.to_string()));
            }
            self.done.notify_all();
        }
    }
}
