//! The job controls clients have besides cancelling and deleting: pause, resume, a new
//! priority, and requeueing a failed or cancelled job (the model's `control.rs` says what
//! each does to the job). Each answers with the job's view once the change is committed.

use super::{JobService, ServiceError, restore_running};
use crate::serve::job::model::Event;
use crate::serve::job::view::JobView;

impl JobService {
    /// Applies a control event to `job`, commits it and answers with the job's view; workers
    /// waiting for work look again (a resumed or reprioritised job may be theirs now).
    fn control(&self, job: &str, event: impl FnOnce(&str) -> Event<'_>, now_ms: u64) -> Result<JobView, ServiceError> {
        let mut inner = self.lock();
        let job = &Self::resolve(&inner, job)?;
        let effects = inner.model.apply(event(job), now_ms).map_err(super::retention::refused)?;
        self.persist(&mut inner, &effects.changes, &[])?;
        self.sync(&inner)?;
        self.work.notify_waiters();
        Ok(self.view(&inner, job, now_ms))
    }

    /// Pauses a job: no tile of it is leased until it is resumed; tiles leased already are
    /// rendered and merged.
    pub fn pause(&self, job: &str, now_ms: u64) -> Result<JobView, ServiceError> {
        let view = self.control(job, |job| Event::Pause { job }, now_ms)?;
        tracing::info!(job_id = %job, "job paused");
        Ok(view)
    }

    /// Resumes a paused job.
    pub fn resume_job(&self, job: &str, now_ms: u64) -> Result<JobView, ServiceError> {
        let view = self.control(job, |job| Event::Resume { job }, now_ms)?;
        tracing::info!(job_id = %job, "job resumed");
        Ok(view)
    }

    /// Gives a job a new priority (higher runs first).
    pub fn set_priority(&self, job: &str, priority: i32, now_ms: u64) -> Result<JobView, ServiceError> {
        let view = self.control(job, |job| Event::SetPriority { job, priority }, now_ms)?;
        tracing::info!(job_id = %job, priority, "job priority changed");
        Ok(view)
    }

    /// Requeues a failed or cancelled job: it runs on from its last checkpoint, with the tiles
    /// accepted since merged again, as after a restart.
    pub fn requeue(&self, job: &str, now_ms: u64) -> Result<JobView, ServiceError> {
        self.check_space()?;
        let mut inner = self.lock();
        let job = &Self::resolve(&inner, job)?;
        if inner.model.sequences.contains_key(job) {
            drop(inner);
            return self.requeue_frames(job, now_ms);
        }
        // refused before the job's checkpoint is read
        inner.model.requeueable(job).map_err(super::retention::refused)?;
        // the checkpoint the database names, with everything queued before it committed
        self.sync(&inner)?;
        let merged = self.commits.store().checkpointed(job)?.unwrap_or(0);
        let spec = inner.model.jobs.get(job).map(|j| j.spec.clone()).expect("invariant: checked above");
        let (film, emis) = restore_running(&self.blobs, job, &spec, &inner.job(job).files)?;
        let runtime = inner.job(job);
        (runtime.film, runtime.emis, runtime.checkpoint) = (film, emis, None);
        runtime.result_files = true;
        let effects = inner.model.apply(Event::Requeue { job, merged }, now_ms)?;
        tracing::info!(job_id = %job, merged, "job requeued");
        if let Err(e) = self.run_restored(inner, job, effects, now_ms) {
            if e.is_storage() {
                return Err(e);
            }
            self.fail_job(job, &format!("cannot requeue the job: {e}"), now_ms)?;
        }
        let inner = self.lock();
        self.sync(&inner)?;
        self.work.notify_waiters();
        Ok(self.view(&inner, job, now_ms))
    }
}

impl JobService {
    /// Requeues a job of frames: the frames not planned yet will be, and each failed or
    /// cancelled frame runs on from its checkpoint.
    fn requeue_frames(&self, id: &str, now_ms: u64) -> Result<JobView, ServiceError> {
        let frames = {
            let mut inner = self.lock();
            let effects = inner.model.apply(Event::Requeue { job: id, merged: 0 }, now_ms)?;
            self.persist(&mut inner, &effects.changes, &[])?;
            let frames = inner.model.frames_of(id).into_iter().map(|j| j.id.clone());
            frames.filter(|f| inner.model.requeueable(f).is_ok()).collect::<Vec<_>>()
        };
        for frame in &frames {
            self.requeue(frame, now_ms)?;
        }
        self.plan_frames(now_ms)?;
        tracing::info!(job_id = %id, frames = frames.len(), "job of frames requeued");
        let inner = self.lock();
        self.sync(&inner)?;
        Ok(self.view(&inner, id, now_ms))
    }
}
