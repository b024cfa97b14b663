//! What a client may do to a submitted job besides cancelling it: pause it, resume it, change
//! its priority, and requeue it once it failed or was cancelled.
//!
//! - **Pause**: no tile of the job is leased any more. Tiles already leased render on; their
//!   results are accepted and merged, and a pass they complete runs its barrier (an EMIS
//!   update, or the outputs when nothing is left), so pausing loses no work. A time budget
//!   and the pass pacing count rendering time only: resuming moves the driver's clock on by
//!   the pause.
//! - **Requeue** (failed or cancelled): the job runs on from what its last checkpoint holds
//!   (`merged`, given by the service), as after a restart: tiles accepted since merge again,
//!   tiles that were leased go back to the queue with a new epoch, and failure counts and
//!   blocklists start afresh.

use super::{Changes, Job, JobState, JobsModel, PassKind, TileState, TransitionError, join, touch};

impl Job {
    /// The state clients see: `paused` for a paused job that has not ended, a finishing job
    /// as `final` (see [`JobState::as_str`]).
    pub fn shown_state(&self) -> JobState {
        match self.paused_ms {
            Some(_) if !self.state.is_terminal() => JobState::Paused,
            _ => self.state.shown(),
        }
    }

    /// The state of a job that runs its passes: queued before its first lease, else by the
    /// kind of its last pass.
    fn running_state(&self) -> JobState {
        match (self.driver.started_ms(), self.passes().last().map(|p| p.kind)) {
            (None, _) => JobState::Queued,
            (_, Some(PassKind::Pilot)) => JobState::Pilot,
            _ => JobState::Final,
        }
    }
}

impl JobsModel {
    fn active(&mut self, job: &str) -> Result<&mut Job, TransitionError> {
        let j = self.jobs.get_mut(job).ok_or_else(|| TransitionError::UnknownJob(job.to_string()))?;
        if j.state.is_terminal() {
            return Err(TransitionError::Ended { job: job.to_string(), state: j.state.as_str() });
        }
        Ok(j)
    }

    /// Pauses a job (again: nothing changes).
    pub(super) fn pause(&mut self, job: &str, now_ms: u64) -> Result<Changes, TransitionError> {
        if self.sequences.contains_key(job) {
            return self.pause_sequence(job, Some(now_ms), now_ms);
        }
        let j = self.active(job)?;
        let mut changes = Changes::new();
        if j.paused_ms.is_none() {
            j.paused_ms = Some(now_ms);
            touch(&mut changes, job, None);
        }
        Ok(changes)
    }

    /// Resumes a paused job (one that is not paused: nothing changes).
    pub(super) fn resume_paused(&mut self, job: &str, now_ms: u64) -> Result<Changes, TransitionError> {
        if self.sequences.contains_key(job) {
            return self.pause_sequence(job, None, now_ms);
        }
        let j = self.active(job)?;
        let mut changes = Changes::new();
        if let Some(since) = j.paused_ms.take() {
            j.driver.postpone(now_ms.saturating_sub(since) as f64);
            touch(&mut changes, job, None);
        }
        Ok(changes)
    }

    /// Sets a job's priority (ended jobs too: it is only shown then); a job of frames's
    /// frames, planned and to come.
    pub(super) fn set_priority(&mut self, job: &str, priority: i32) -> Result<Changes, TransitionError> {
        if let Some(s) = self.sequences.get_mut(job) {
            s.spec.priority = priority;
            let frames: Vec<String> = s.frame_ids().collect();
            let mut changes = Changes::new();
            touch(&mut changes, job, None);
            for f in &frames {
                if self.jobs.contains_key(f) {
                    join(&mut changes, self.set_priority(f, priority)?);
                }
            }
            return Ok(changes);
        }
        let j = self.jobs.get_mut(job).ok_or_else(|| TransitionError::UnknownJob(job.to_string()))?;
        let mut changes = Changes::new();
        if j.spec.priority != priority {
            j.spec.priority = priority;
            touch(&mut changes, job, None);
        }
        Ok(changes)
    }

    /// Requeues a failed or cancelled job from its last checkpoint, which holds
    /// `tiles[..merged]`. It is not paused afterwards, whatever it was.
    /// Whether job `job` may be requeued: failed or cancelled, and not a frame whose scene
    /// did not load (the same bundle cannot load it again).
    pub fn requeueable(&self, job: &str) -> Result<(), TransitionError> {
        let j = self.jobs.get(job).ok_or_else(|| TransitionError::UnknownJob(job.to_string()))?;
        if !matches!(j.state, JobState::Failed | JobState::Cancelled) {
            return Err(TransitionError::NotRequeueable { job: job.to_string(), state: j.shown_state().as_str() });
        }
        if j.spec.frame.as_ref().is_some_and(|f| f.refused) {
            return Err(TransitionError::SceneRefused(job.to_string()));
        }
        Ok(())
    }

    pub(super) fn requeue(&mut self, job: &str, merged: usize) -> Result<Changes, TransitionError> {
        self.requeueable(job)?;
        let j = self.jobs.get_mut(job).expect("invariant: requeueable found it");
        let mut changes = Changes::new();
        let merged = merged.min(j.merged);
        for i in merged..j.tiles.len() {
            let tile = &mut j.tiles[i];
            let state = match &tile.state {
                TileState::Leased { .. } => {
                    tile.epoch += 1;
                    TileState::Queued
                }
                TileState::Merged => TileState::Accepted,
                other => other.clone(),
            };
            tile.failures = 0;
            j.set_tile_state(i, state);
            touch(&mut changes, job, Some(i));
        }
        j.merged = merged;
        j.worker_failures.clear();
        (j.error, j.last_failure, j.finished_ms, j.paused_ms) = (None, None, None, None);
        j.state = j.running_state();
        touch(&mut changes, job, None);
        Ok(changes)
    }
}
