//! Removing jobs from the model: a client's delete and the `--retain-finished` sweep. Only a
//! job that has ended (done, failed or cancelled) can go, so no lease, result or barrier ever
//! refers to a job that is no longer there; an active job must be cancelled first. Pure, like
//! the rest of the model: the service deletes the job's rows and files after this.
//!
//! ```text
//! model.remove("job")?                  // Err(Unfinished) while it runs
//! model.expired(now_ms, 24 * 3_600_000) // ended a day or more ago, oldest first
//! ```

use super::model::{Job, JobState, JobsModel, TransitionError};

impl JobsModel {
    /// Removes a finished, failed or cancelled job and returns it.
    pub fn remove(&mut self, job: &str) -> Result<Job, TransitionError> {
        let j = self.jobs.get(job).ok_or_else(|| TransitionError::UnknownJob(job.to_string()))?;
        if !j.state.is_terminal() {
            return Err(TransitionError::Unfinished { job: job.to_string(), state: j.state.as_str() });
        }
        Ok(self.jobs.remove(job).expect("invariant: the job was just found"))
    }

    /// The jobs that ended at least `retain_ms` before `now_ms`, oldest first: a job of frames
    /// when its last frame ended, never a frame alone.
    pub fn expired(&self, now_ms: u64, retain_ms: u64) -> Vec<String> {
        let stills = self
            .jobs
            .values()
            .filter(|j| j.state.is_terminal() && j.spec.frame.is_none())
            // a terminal job always has `finished_ms`; one restored without it counts from its
            // creation, so it still expires
            .map(|j| (j.finished_ms.unwrap_or(j.created_ms), j.id.as_str()));
        let sequences =
            self.sequences.values().filter(|s| self.sequence_state(&s.id).is_some_and(JobState::is_terminal)).map(
                |s| {
                    let last = self.frames_of(&s.id).iter().filter_map(|j| j.finished_ms).max();
                    (last.unwrap_or(s.created_ms), s.id.as_str())
                },
            );
        let mut ended: Vec<(u64, &str)> =
            stills.chain(sequences).filter(|(at, _)| now_ms.saturating_sub(*at) >= retain_ms).collect();
        ended.sort();
        ended.into_iter().map(|(_, id)| id.to_string()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::super::model::calls::Calls;
    use super::super::model::{JobSpec, JobState};
    use super::*;
    use tessera_common::settings::IntegratorName;

    fn spec() -> JobSpec {
        JobSpec::bare("j", IntegratorName::Pt, Some(1), 64, 64)
    }

    #[test]
    fn remove_refuses_active_jobs_and_takes_ended_ones() {
        let mut m = JobsModel::default();
        m.submit("a", spec(), 0).unwrap();
        assert_eq!(m.remove("a"), Err(TransitionError::Unfinished { job: "a".into(), state: "queued" }));
        let (leases, _) = m.lease("w", 1, 1, 1000);
        assert_eq!(leases.len(), 1);
        assert!(matches!(m.remove("a"), Err(TransitionError::Unfinished { state: "final", .. })));
        m.cancel("a", 2).unwrap();
        assert_eq!(m.remove("a").unwrap().state, JobState::Cancelled);
        assert!(m.jobs.is_empty());
        assert_eq!(m.remove("a"), Err(TransitionError::UnknownJob("a".into())));
        // a result for a lease of the removed job is stale, and nothing is leased
        let (outcome, changes) = m.result("w", &leases[0], Ok(()), 3);
        assert_eq!((outcome, changes.is_empty()), (super::super::model::ResultOutcome::Stale, true));
        assert!(m.lease("w", 1, 3, 1000).0.is_empty());
    }

    #[test]
    fn expired_lists_ended_jobs_past_the_retention_oldest_first() {
        let mut m = JobsModel::default();
        for (id, end) in [("late", 300), ("early", 100), ("running", 0), ("failed", 200)] {
            m.submit(id, spec(), 0).unwrap();
            match id {
                "running" => {}
                "failed" => {
                    m.fail(id, "boom".into(), end);
                }
                _ => {
                    m.cancel(id, end).unwrap();
                }
            }
        }
        assert_eq!(m.expired(1_150, 1_000), vec!["early".to_string()]);
        assert_eq!(m.expired(1_300, 1_000), vec!["early", "failed", "late"]);
        assert!(m.expired(1_099, 1_000).is_empty());
        assert_eq!(m.expired(10_000, 0).len(), 3, "never the running job");
    }
}
