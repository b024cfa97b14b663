//! The model's events as the method calls tests read best: each applies one [`Event`] and
//! answers with what the effects say, so the tests drive the model as the service does. A
//! merge that finishes a job also applies [`Event::OutputsWritten`], as the service does once
//! the outputs are stored.

use super::{
    BarrierAction, Changes, Effect, Event, JobSpec, JobsModel, LeaseLifetime, LeaseRef, ResultOutcome, TransitionError,
};
use std::ops::Range;

/// One method per event.
pub(crate) trait Calls {
    fn submit(&mut self, id: &str, spec: JobSpec, now_ms: u64) -> Result<Changes, TransitionError>;
    fn lease(&mut self, worker: &str, max_tiles: usize, now_ms: u64, ttl_ms: u64) -> (Vec<LeaseRef>, Changes);
    fn heartbeat(&mut self, worker: &str, leases: &[LeaseRef], now_ms: u64, ttl_ms: u64) -> Vec<LeaseRef>;
    fn result(
        &mut self,
        worker: &str,
        lease: &LeaseRef,
        verdict: Result<(), String>,
        now_ms: u64,
    ) -> (ResultOutcome, Changes);
    fn report_failure(&mut self, worker: &str, lease: &LeaseRef, message: &str, now_ms: u64) -> Changes;
    /// The tiles the last accepted result of `job` made mergeable.
    fn mergeable(&self, job: &str) -> Range<usize>;
    fn merged(&mut self, job: &str, upto: usize, now_ms: u64) -> (Option<BarrierAction>, Changes);
    fn optimized(
        &mut self,
        job: &str,
        restart: bool,
        nu: f32,
        collect: bool,
        now_ms: u64,
    ) -> Result<Changes, TransitionError>;
    fn cancel(&mut self, job: &str, now_ms: u64) -> Result<Changes, TransitionError>;
    fn fail(&mut self, job: &str, error: String, now_ms: u64) -> Changes;
    fn expire(&mut self, now_ms: u64, lifetime: &LeaseLifetime) -> Changes;
    fn fail_stranded(&mut self, live: &[&str], now_ms: u64) -> (Vec<String>, Changes);
    fn postpone_leases(&mut self, by_ms: u64);
    fn pause(&mut self, job: &str, now_ms: u64) -> Result<Changes, TransitionError>;
    fn resume(&mut self, job: &str, now_ms: u64) -> Result<Changes, TransitionError>;
    fn set_priority(&mut self, job: &str, priority: i32) -> Result<Changes, TransitionError>;
    /// Requeues from a checkpoint of `tiles[..merged]`, then merges and finishes as the
    /// service would (without outputs: they are written at once).
    fn requeue(&mut self, job: &str, merged: usize, now_ms: u64) -> Result<Changes, TransitionError>;
}

impl Calls for JobsModel {
    fn submit(&mut self, id: &str, spec: JobSpec, now_ms: u64) -> Result<Changes, TransitionError> {
        self.apply(Event::Submit { id, spec: Box::new(spec) }, now_ms).map(|e| e.changes)
    }

    fn lease(&mut self, worker: &str, max_tiles: usize, now_ms: u64, ttl_ms: u64) -> (Vec<LeaseRef>, Changes) {
        let e = self.apply(Event::Lease { worker, max_tiles, ttl_ms }, now_ms).expect("leasing is never refused");
        (e.leases().cloned().collect(), e.changes)
    }

    fn heartbeat(&mut self, worker: &str, leases: &[LeaseRef], now_ms: u64, ttl_ms: u64) -> Vec<LeaseRef> {
        let e = self.apply(Event::Heartbeat { worker, leases, ttl_ms }, now_ms).expect("never refused");
        assert!(e.changes.is_empty(), "heartbeats persist nothing");
        e.leases().cloned().collect()
    }

    fn result(
        &mut self,
        worker: &str,
        lease: &LeaseRef,
        verdict: Result<(), String>,
        now_ms: u64,
    ) -> (ResultOutcome, Changes) {
        let e = self.apply(Event::Result { worker, lease, verdict }, now_ms).expect("never refused");
        (e.outcome().cloned().expect("a result has an outcome"), e.changes)
    }

    fn report_failure(&mut self, worker: &str, lease: &LeaseRef, message: &str, now_ms: u64) -> Changes {
        self.apply(Event::Failure { worker, lease, message }, now_ms).expect("never refused").changes
    }

    fn mergeable(&self, job: &str) -> Range<usize> {
        let mut m = self.clone();
        match m.apply(Event::Restored { job }, 0).expect("never refused").then.first() {
            Some(Effect::Merge { tiles, .. }) => tiles.clone(),
            _ => self.jobs.get(job).map_or(0..0, |j| j.merged..j.merged),
        }
    }

    fn merged(&mut self, job: &str, upto: usize, now_ms: u64) -> (Option<BarrierAction>, Changes) {
        let mut e = self.apply(Event::Merged { job, upto }, now_ms).expect("never refused");
        let action = e.then.iter().find_map(|e| match e {
            Effect::PassPlanned { .. } => Some(BarrierAction::NextPass),
            Effect::Optimize { .. } => Some(BarrierAction::Optimize),
            Effect::WriteOutputs { .. } => Some(BarrierAction::Finish),
            _ => None,
        });
        if action == Some(BarrierAction::Finish) {
            // the service writes the outputs here
            e.extend(self.apply(Event::OutputsWritten { job }, now_ms).expect("a finishing job takes its outputs"));
        }
        (action, e.changes)
    }

    fn optimized(
        &mut self,
        job: &str,
        restart: bool,
        nu: f32,
        collect: bool,
        now_ms: u64,
    ) -> Result<Changes, TransitionError> {
        self.apply(Event::Optimized { job, restart, nu, collect }, now_ms).map(|e| e.changes)
    }

    fn cancel(&mut self, job: &str, now_ms: u64) -> Result<Changes, TransitionError> {
        self.apply(Event::Cancel { job }, now_ms).map(|e| e.changes)
    }

    fn fail(&mut self, job: &str, error: String, now_ms: u64) -> Changes {
        self.apply(Event::Fail { job, error }, now_ms).expect("never refused").changes
    }

    fn expire(&mut self, now_ms: u64, lifetime: &LeaseLifetime) -> Changes {
        self.apply(Event::Expire { lifetime: *lifetime, stalled_ms: 0 }, now_ms).expect("never refused").changes
    }

    fn fail_stranded(&mut self, live: &[&str], now_ms: u64) -> (Vec<String>, Changes) {
        let e = self.apply(Event::Strand { live }, now_ms).expect("never refused");
        (e.ended().map(|(j, _)| j.to_string()).collect(), e.changes)
    }

    fn pause(&mut self, job: &str, now_ms: u64) -> Result<Changes, TransitionError> {
        self.apply(Event::Pause { job }, now_ms).map(|e| e.changes)
    }

    fn resume(&mut self, job: &str, now_ms: u64) -> Result<Changes, TransitionError> {
        self.apply(Event::Resume { job }, now_ms).map(|e| e.changes)
    }

    fn set_priority(&mut self, job: &str, priority: i32) -> Result<Changes, TransitionError> {
        self.apply(Event::SetPriority { job, priority }, 0).map(|e| e.changes)
    }

    fn requeue(&mut self, job: &str, merged: usize, now_ms: u64) -> Result<Changes, TransitionError> {
        let e = self.apply(Event::Requeue { job, merged }, now_ms)?;
        if e.then.iter().any(|e| matches!(e, Effect::WriteOutputs { .. })) {
            self.apply(Event::OutputsWritten { job }, now_ms)?;
        }
        Ok(e.changes)
    }

    fn postpone_leases(&mut self, by_ms: u64) {
        // a stall with nothing due: only the postponement shows
        let lifetime = LeaseLifetime { floor_ms: u64::MAX / 4, factor: 0.0 };
        let e = self.apply(Event::Expire { lifetime, stalled_ms: by_ms }, 0).expect("never refused");
        assert!(e.changes.is_empty(), "nothing expires at time 0");
    }
}
