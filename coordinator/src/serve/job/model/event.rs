//! The model's one entry point for change: [`JobsModel::apply`] takes an [`Event`] (something
//! a client, a worker, the timer or the service's own IO reported) and returns [`Effects`]:
//! the rows to persist and what the service must do next. The service never steers a job
//! field by field; the IO an effect asks for (merging results into a film, running the EMIS
//! optimiser, writing outputs) ends in another event.
//!
//! ```text
//! Result{..}      → Outcome, Merge{tiles}          (the accepted tiles next in order)
//! Merged{upto}    → PassPlanned | Optimize{..} | WriteOutputs{upto}
//! Optimized{..}   → PassPlanned
//! OutputsWritten  → Ended{Done}
//! ```

use super::TransitionError;
use super::{
    BarrierAction, Changes, JobSpec, JobState, JobsModel, LeaseLifetime, LeaseRef, ResultOutcome, SequenceSpec,
};
use std::ops::Range;
use tessera_common::emis::RestartTotal;

/// Something that happened to the jobs, at the `now_ms` passed with it.
#[derive(Debug)]
pub enum Event<'a> {
    /// A client submitted a job.
    Submit {
        /// Its id.
        id: &'a str,
        /// What to render.
        spec: Box<JobSpec>,
    },
    /// A client submitted a job of many frames (planned later, by [`Event::PlanFrame`]).
    SubmitSequence {
        /// Its id.
        id: &'a str,
        /// What to render.
        spec: Box<SequenceSpec>,
    },
    /// The service loaded frame `index`'s scene: the frame is a job of `spec`, or fails with
    /// `error` when its scene did not load.
    PlanFrame {
        /// The sequence.
        sequence: &'a str,
        /// The frame's position.
        index: usize,
        /// Its job.
        spec: Box<JobSpec>,
        /// Why its scene did not load.
        error: Option<String>,
    },
    /// A worker registered from `host` with `tags`: the leases its earlier process held fail
    /// now.
    Register {
        /// The worker.
        worker: &'a str,
        /// Where it registered from, if known.
        host: Option<String>,
        /// Its tags.
        tags: Vec<String>,
    },
    /// A worker was forgotten (silent, holding nothing).
    Forget {
        /// The worker.
        worker: &'a str,
    },
    /// A worker asks for up to `max_tiles` tiles, each held for `ttl_ms` without a heartbeat.
    Lease {
        /// The worker.
        worker: &'a str,
        /// The most tiles it takes.
        max_tiles: usize,
        /// The lease timeout.
        ttl_ms: u64,
    },
    /// A worker's heartbeat for `leases`.
    Heartbeat {
        /// The worker.
        worker: &'a str,
        /// The leases it holds.
        leases: &'a [LeaseRef],
        /// The lease timeout.
        ttl_ms: u64,
    },
    /// A worker uploaded a result; `verdict` is its validation (done outside the model).
    Result {
        /// The worker.
        worker: &'a str,
        /// Its lease.
        lease: &'a LeaseRef,
        /// `Err(reason)` refuses it.
        verdict: Result<(), String>,
    },
    /// A worker could not render its lease.
    Failure {
        /// The worker.
        worker: &'a str,
        /// Its lease.
        lease: &'a LeaseRef,
        /// Why.
        message: &'a str,
    },
    /// The timer: leases past their deadline or lifetime go back to the queue; when the
    /// coordinator itself stalled for `stalled_ms`, every lease's clock moves on by it first.
    Expire {
        /// How long a lease may live.
        lifetime: LeaseLifetime,
        /// The coordinator's own stall (0: none).
        stalled_ms: u64,
    },
    /// The workers alive now (not empty): jobs that every one of them is blocklisted for fail.
    Strand {
        /// Their ids.
        live: &'a [&'a str],
    },
    /// A job loaded from storage: merge what was accepted after its checkpoint, or run the
    /// update it stopped before.
    Restored {
        /// The job.
        job: &'a str,
    },
    /// A client paused a job: no more leases (see `control.rs`).
    Pause {
        /// The job.
        job: &'a str,
    },
    /// A client resumed a paused job.
    Resume {
        /// The job.
        job: &'a str,
    },
    /// A client changed a job's priority.
    SetPriority {
        /// The job.
        job: &'a str,
        /// Higher runs first.
        priority: i32,
    },
    /// A client requeued a failed or cancelled job, whose last checkpoint holds
    /// `tiles[..merged]` (the service reloaded its film from it).
    Requeue {
        /// The job.
        job: &'a str,
        /// Tiles in the checkpoint.
        merged: usize,
    },
    /// The service merged `tiles[..upto]` into the job's film (after [`Effect::Merge`]).
    Merged {
        /// The job.
        job: &'a str,
        /// The new merge frontier.
        upto: usize,
    },
    /// The optimiser chose `nu` light paths per pixel at an EMIS barrier (after
    /// [`Effect::Optimize`]). `restart`: a path-tracing start ended and the film was cleared;
    /// `collect`: the EMIS state still collects moments.
    Optimized {
        /// The job.
        job: &'a str,
        /// Whether the update restarted the job.
        restart: bool,
        /// Light paths per pixel.
        nu: f32,
        /// Whether the next pass collects moments.
        collect: bool,
    },
    /// A frame's EMIS updates ended on `decision`, which the next frame of its job of frames
    /// starts from (`--warm-start`).
    Decided {
        /// The job.
        job: &'a str,
        /// Its strategy, masks stored.
        decision: Box<super::super::spec::WarmStart>,
    },
    /// A finishing job's outputs are stored (after [`Effect::WriteOutputs`]).
    OutputsWritten {
        /// The job.
        job: &'a str,
    },
    /// A client cancelled a job.
    Cancel {
        /// The job.
        job: &'a str,
    },
    /// The service found an error the job cannot go on with (its data, its update, its outputs).
    Fail {
        /// The job.
        job: &'a str,
        /// Why.
        error: String,
    },
}

/// What the service must do after an event, besides persisting [`Effects::changes`].
#[derive(Clone, Debug, PartialEq)]
pub enum Effect {
    /// Hand this lease to the worker that asked ([`Event::Lease`]).
    Leased(LeaseRef),
    /// Tell the worker this lease is no longer its own ([`Event::Heartbeat`]).
    Lost(LeaseRef),
    /// What became of an uploaded result ([`Event::Result`]).
    Outcome(ResultOutcome),
    /// Merge the results of these accepted tiles into the job's film in order, then apply
    /// [`Event::Merged`].
    Merge {
        /// The job.
        job: String,
        /// Tiles from the merge frontier on.
        tiles: Range<usize>,
    },
    /// The job's next pass is planned: its tiles are queued.
    PassPlanned {
        /// The job.
        job: String,
    },
    /// Run the EMIS update on the film of `iterations` merged iterations, then apply
    /// [`Event::Optimized`].
    Optimize {
        /// The job.
        job: String,
        /// Samples per pixel merged.
        iterations: u32,
        /// The iterations the job would run in all if the update restarted it.
        restart_total: RestartTotal,
    },
    /// Every tile is merged: write the outputs of the film of `tiles[..upto]`, then apply
    /// [`Event::OutputsWritten`].
    WriteOutputs {
        /// The job.
        job: String,
        /// Its tiles.
        upto: usize,
    },
    /// The job ended (done, failed with its `error`, or cancelled): free what it held.
    Ended {
        /// The job.
        job: String,
        /// Its final state.
        state: JobState,
    },
}

/// What an event changed ([`Changes`], to persist before anyone is answered) and what follows.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Effects {
    /// The rows to persist.
    pub changes: Changes,
    /// What the service does next, in order.
    pub then: Vec<Effect>,
}

impl Effects {
    fn of(changes: Changes) -> Effects {
        Effects { changes, then: Vec::new() }
    }

    /// The outcome of a result ([`Event::Result`] always has one).
    pub fn outcome(&self) -> Option<&ResultOutcome> {
        self.then.iter().find_map(|e| if let Effect::Outcome(o) = e { Some(o) } else { None })
    }

    /// The leases handed out or lost.
    pub fn leases(&self) -> impl Iterator<Item = &LeaseRef> {
        self.then.iter().filter_map(|e| match e {
            Effect::Leased(l) | Effect::Lost(l) => Some(l),
            _ => None,
        })
    }

    /// The jobs that ended, with their state.
    pub fn ended(&self) -> impl Iterator<Item = (&str, JobState)> {
        self.then.iter().filter_map(|e| match e {
            Effect::Ended { job, state } => Some((job.as_str(), *state)),
            _ => None,
        })
    }

    /// Adds `other`'s changes and effects after this one's.
    pub fn extend(&mut self, other: Effects) {
        super::join(&mut self.changes, other.changes);
        self.then.extend(other.then);
    }
}

impl JobsModel {
    /// Applies `event` at `now_ms`. Only jobs that had not ended are ever changed, so a job
    /// the event changed that has ended now ended by it: [`Effect::Ended`] says so.
    pub fn apply(&mut self, event: Event<'_>, now_ms: u64) -> Result<Effects, TransitionError> {
        let mut effects = match event {
            Event::Submit { id, spec } => Effects::of(self.submit(id, *spec, now_ms)?),
            Event::SubmitSequence { id, spec } => Effects::of(self.submit_sequence(id, *spec, now_ms)?),
            Event::PlanFrame { sequence, index, spec, error } => {
                Effects::of(self.plan_frame(sequence, index, *spec, error, now_ms)?)
            }
            Event::Register { worker, host, tags } => self.register(worker, host, tags, now_ms),
            Event::Forget { worker } => {
                self.hosts.remove(worker);
                self.tags.remove(worker);
                Effects::default()
            }
            Event::Lease { worker, max_tiles, ttl_ms } => {
                let (leases, changes) = self.lease(worker, max_tiles, now_ms, ttl_ms);
                Effects { changes, then: leases.into_iter().map(Effect::Leased).collect() }
            }
            Event::Heartbeat { worker, leases, ttl_ms } => {
                let lost = self.heartbeat(worker, leases, now_ms, ttl_ms);
                Effects { changes: Changes::new(), then: lost.into_iter().map(Effect::Lost).collect() }
            }
            Event::Result { worker, lease, verdict } => self.on_result(worker, lease, verdict, now_ms),
            Event::Failure { worker, lease, message } => {
                Effects::of(self.report_failure(worker, lease, message, now_ms))
            }
            Event::Expire { lifetime, stalled_ms } => {
                if stalled_ms > 0 {
                    self.postpone_leases(stalled_ms);
                }
                Effects::of(self.expire(now_ms, &lifetime))
            }
            Event::Strand { live } => Effects::of(self.fail_stranded(live, now_ms).1),
            Event::Restored { job } => self.restored(job, now_ms),
            Event::Pause { job } => Effects::of(self.pause(job, now_ms)?),
            Event::Resume { job } => Effects::of(self.resume_paused(job, now_ms)?),
            Event::SetPriority { job, priority } => Effects::of(self.set_priority(job, priority)?),
            Event::Requeue { job, .. } if self.sequences.contains_key(job) => Effects::of(self.resume_planning(job)?),
            Event::Requeue { job, merged } => {
                let mut effects = Effects::of(self.requeue(job, merged)?);
                effects.extend(self.restored(job, now_ms));
                effects
            }
            Event::Merged { job, upto } => self.on_merged(job, upto, now_ms),
            Event::Optimized { job, restart, nu, collect } => {
                let changes = self.optimized(job, restart, nu, collect, now_ms)?;
                Effects { changes, then: vec![Effect::PassPlanned { job: job.to_string() }] }
            }
            Event::Decided { job, decision } => Effects::of(self.decided(job, *decision)?),
            Event::OutputsWritten { job } => Effects::of(self.outputs_written(job, now_ms)?),
            Event::Cancel { job } if self.sequences.contains_key(job) => {
                Effects::of(self.cancel_sequence(job, now_ms)?)
            }
            Event::Cancel { job } => Effects::of(self.cancel(job, now_ms)?),
            Event::Fail { job, error } => Effects::of(self.fail(job, error, now_ms)),
        };
        for job in effects.changes.keys() {
            if let Some(j) = self.jobs.get(job).filter(|j| j.state.is_terminal()) {
                effects.then.push(Effect::Ended { job: job.clone(), state: j.state });
            }
        }
        Ok(effects)
    }

    /// A worker (re-)registered: the leases its earlier process held go back to the queue,
    /// each counted as a failure, as their expiry would have.
    fn register(&mut self, worker: &str, host: Option<String>, tags: Vec<String>, now_ms: u64) -> Effects {
        let mut effects = Effects::default();
        for lease in self.leases_of(worker) {
            effects.extend(Effects::of(self.report_failure(worker, &lease, "the worker restarted", now_ms)));
        }
        match host {
            Some(host) => self.hosts.insert(worker.to_string(), host),
            None => self.hosts.remove(worker),
        };
        match tags.is_empty() {
            true => self.tags.remove(worker),
            false => self.tags.insert(worker.to_string(), tags.into_iter().collect()),
        };
        effects
    }

    fn on_result(&mut self, worker: &str, lease: &LeaseRef, verdict: Result<(), String>, now_ms: u64) -> Effects {
        let (outcome, changes) = self.result(worker, lease, verdict, now_ms);
        let accepted = outcome == ResultOutcome::Accepted;
        let mut effects = Effects { changes, then: vec![Effect::Outcome(outcome)] };
        if accepted {
            effects.then.extend(self.merge_effect(&lease.job));
        }
        effects
    }

    /// The accepted tiles next in merge order, if any.
    fn merge_effect(&self, job: &str) -> Option<Effect> {
        let tiles = self.mergeable(job);
        (!tiles.is_empty()).then(|| Effect::Merge { job: job.to_string(), tiles })
    }

    fn restored(&mut self, job: &str, now_ms: u64) -> Effects {
        let mut effects = Effects::default();
        effects.then.extend(self.merge_effect(job));
        let Some(j) = self.jobs.get(job) else { return effects };
        let all_merged = !j.state.is_terminal() && j.merged == j.tiles.len();
        if j.state == JobState::Optimizing {
            // stopped between a barrier and its update (all its tiles merged)
            effects.then.push(self.optimize_effect(job, now_ms));
        } else if effects.then.is_empty() && all_merged {
            // requeued with every tile in its checkpoint: the barrier the cancel cut off
            let upto = j.merged;
            effects.extend(self.on_merged(job, upto, now_ms));
        }
        effects
    }

    fn optimize_effect(&self, job: &str, now_ms: u64) -> Effect {
        let j = &self.jobs[job];
        Effect::Optimize {
            job: job.to_string(),
            iterations: j.spp_merged(),
            restart_total: j.driver.restart_total(now_ms as f64),
        }
    }

    fn on_merged(&mut self, job: &str, upto: usize, now_ms: u64) -> Effects {
        let (action, changes) = self.merged(job, upto, now_ms);
        let mut effects = Effects::of(changes);
        let job_id = job.to_string();
        effects.then.extend(match action {
            None => None,
            Some(BarrierAction::NextPass) => Some(Effect::PassPlanned { job: job_id }),
            Some(BarrierAction::Optimize) => Some(self.optimize_effect(job, now_ms)),
            Some(BarrierAction::Finish) => Some(Effect::WriteOutputs { job: job_id, upto }),
        });
        effects
    }
}
