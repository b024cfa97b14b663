//! Dependencies between jobs (`--after`): a job starts only once every job it waits for is
//! done. While one of them runs it is queued ("waiting for job …"); when one failed, was
//! cancelled or is gone, or is itself blocked, it is shown `blocked` with the reason, and runs
//! when that job is requeued and done. Nothing is stored for this: it is read off the jobs.

use super::{Job, JobState, JobsModel};
use std::collections::HashSet;

/// Most jobs one question about a dependency chain looks at: a chain is bounded by it, whatever
/// a client built.
const MAX_VISITS: usize = 256;

/// Why a queued job does not start.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Waiting {
    /// A job it waits for is not done yet.
    For(String),
    /// A job it waits for (directly or down the chain) will not be done unless requeued.
    Blocked {
        /// That job.
        job: String,
        /// What became of it: `failed`, `was cancelled`, `was deleted`, `is blocked`.
        why: &'static str,
    },
}

impl Waiting {
    /// The phase clients see.
    pub fn phase(&self) -> String {
        match self {
            Waiting::For(job) => format!("waiting for job {job}"),
            Waiting::Blocked { job, why } => format!("blocked: job {job} {why}"),
        }
    }
}

impl JobsModel {
    /// Whether every job `job` waits for is done (it may be leased).
    pub(super) fn upstream_done(&self, job: &Job) -> bool {
        job.spec.after.iter().all(|a| self.jobs.get(a).is_some_and(|u| u.state == JobState::Done))
    }

    /// Why a job that has not started does not start, if it waits for others.
    pub fn waiting(&self, job: &Job) -> Option<Waiting> {
        if job.state != JobState::Queued || self.upstream_done(job) {
            return None;
        }
        let mut seen = HashSet::new();
        for a in &job.spec.after {
            if let Some(why) = self.blocked(a, &mut seen) {
                return Some(Waiting::Blocked { job: a.clone(), why });
            }
        }
        let running = job.spec.after.iter().find(|a| self.jobs.get(*a).is_some_and(|u| u.state != JobState::Done));
        running.map(|a| Waiting::For(a.clone()))
    }

    /// Why job `id` will not be done unless a client acts, looking at no more than
    /// [`MAX_VISITS`] jobs down its chain (deeper, it counts as waiting).
    fn blocked(&self, id: &str, seen: &mut HashSet<String>) -> Option<&'static str> {
        if seen.len() >= MAX_VISITS || !seen.insert(id.to_string()) {
            return None;
        }
        let Some(job) = self.jobs.get(id) else { return Some("was deleted") };
        match job.state {
            JobState::Failed => Some("failed"),
            JobState::Cancelled => Some("was cancelled"),
            JobState::Queued => job.spec.after.iter().any(|a| self.blocked(a, seen).is_some()).then_some("is blocked"),
            _ => None,
        }
    }
}
