//! Tests of the job controls in the pure model: pause, resume, priority and requeue.

use super::model::calls::Calls;
use super::model::*;
use tessera_common::settings::{IntegratorName, RenderSettings};

const TTL: u64 = 1000;

fn spec(spp: u32, priority: i32, time_s: Option<f64>) -> JobSpec {
    let settings = RenderSettings { integrator: IntegratorName::Pt, spp: Some(spp), time_s, ..Default::default() };
    JobSpec { priority, settings, ..JobSpec::bare("j", IntegratorName::Pt, Some(spp), 128, 128) }
}

/// A paused job hands out nothing, shows `paused`, and its leased tiles still count; resumed,
/// it goes on. Ended jobs cannot be paused.
#[test]
fn a_paused_job_leases_nothing_until_resumed_and_keeps_its_leased_work() {
    let mut m = JobsModel::default();
    m.submit("a", spec(1, 0, None), 0).unwrap();
    let (held, _) = m.lease("w", 1, 1, TTL);
    assert_eq!(held.len(), 1);
    assert!(!m.pause("a", 2).unwrap().is_empty());
    assert!(m.pause("a", 3).unwrap().is_empty(), "pausing twice changes nothing");
    assert_eq!(m.jobs["a"].shown_state(), JobState::Paused);
    assert!(m.lease("w", 4, 4, TTL).0.is_empty());
    assert_eq!(m.result("w", &held[0], Ok(()), 5).0, ResultOutcome::Accepted, "leased work is kept");
    m.resume("a", 6).unwrap();
    assert_eq!(m.jobs["a"].shown_state(), JobState::Final);
    assert_eq!(m.lease("w", 4, 7, TTL).0.len(), 3);
    m.cancel("a", 8).unwrap();
    assert!(matches!(m.pause("a", 9), Err(TransitionError::Ended { .. })));
}

/// Resuming moves a time budget's clock on by the pause: the pause is not spent.
#[test]
fn a_pause_does_not_spend_a_time_budget() {
    let mut m = JobsModel::default();
    m.submit("a", spec(1, 0, Some(10.0)), 0).unwrap();
    m.lease("w", 1, 1_000, TTL);
    m.pause("a", 2_000).unwrap();
    m.resume("a", 7_000).unwrap();
    assert_eq!(m.jobs["a"].driver.started_ms(), Some(6_000.0));
}

/// A new priority reorders the queue: the next lease goes to the job that now ranks first.
#[test]
fn a_priority_change_reorders_the_queue() {
    let mut m = JobsModel::default();
    m.submit("a", spec(1, 5, None), 0).unwrap();
    m.submit("b", spec(1, 0, None), 0).unwrap();
    assert_eq!(m.lease("w", 1, 1, TTL).0[0].job, "a");
    m.set_priority("b", 9).unwrap();
    assert_eq!(m.lease("w", 1, 2, TTL).0[0].job, "b");
    assert_eq!(m.jobs["b"].spec.priority, 9);
}

/// Requeueing a cancelled job runs it on from its checkpoint: merged tiles after it merge
/// again, leased ones go back to the queue with a new epoch (their late results are stale),
/// failures are forgotten. A done job cannot be requeued.
#[test]
fn requeue_runs_a_cancelled_job_on_from_its_checkpoint() {
    let mut m = JobsModel::default();
    m.submit("a", spec(1, 0, None), 0).unwrap();
    let (leases, _) = m.lease("w", 4, 1, TTL);
    for l in &leases[..3] {
        m.result("w", l, Ok(()), 2);
    }
    m.merged("a", 3, 3);
    m.report_failure("w", &leases[3], "boom", 3);
    let (retry, _) = m.lease("w", 1, 4, TTL);
    m.cancel("a", 5).unwrap();
    m.requeue("a", 1, 6).unwrap();
    let job = &m.jobs["a"];
    assert_eq!((job.state, job.merged, job.finished_ms), (JobState::Final, 1, None));
    assert_eq!(job.tiles[1].state, TileState::Accepted, "merged after the checkpoint: merges again");
    assert_eq!((job.tiles[3].state.clone(), job.tiles[3].failures), (TileState::Queued, 0));
    assert!(job.worker_failures.is_empty());
    assert_eq!(m.mergeable("a"), 1..3);
    assert_eq!(m.result("w", &retry[0], Ok(()), 7).0, ResultOutcome::Stale);
    m.merged("a", 3, 8);
    let (last, _) = m.lease("w", 4, 9, TTL);
    m.result("w", &last[0], Ok(()), 10);
    m.merged("a", 4, 11);
    assert_eq!(m.jobs["a"].state, JobState::Done);
    assert!(matches!(m.requeue("a", 4, 12), Err(TransitionError::NotRequeueable { state: "done", .. })));
}

/// A job cancelled with every tile in its checkpoint runs the barrier the cancel cut off when
/// requeued: here the last one, so its outputs are asked for.
#[test]
fn requeue_with_every_tile_checkpointed_runs_the_barrier() {
    let mut m = JobsModel::default();
    m.submit("a", spec(1, 0, None), 0).unwrap();
    for l in m.lease("w", 4, 1, TTL).0 {
        m.result("w", &l, Ok(()), 2);
    }
    let e = m.apply(Event::Merged { job: "a", upto: 4 }, 3).unwrap();
    assert_eq!(e.then, vec![Effect::WriteOutputs { job: "a".into(), upto: 4 }]);
    m.cancel("a", 4).unwrap();
    let e = m.apply(Event::Requeue { job: "a", merged: 4 }, 5).unwrap();
    assert_eq!(e.then, vec![Effect::WriteOutputs { job: "a".into(), upto: 4 }]);
    assert_eq!(m.jobs["a"].state, JobState::Finishing);
}

/// A job is found by its id or a unique prefix of at least six characters; a shorter or
/// shared prefix is not enough.
#[test]
fn jobs_are_found_by_a_unique_prefix_of_six_or_more() {
    let mut m = JobsModel::default();
    for id in ["abcdef12-1", "abcdef34-2", "abc"] {
        m.submit(id, spec(1, 0, None), 0).unwrap();
    }
    assert_eq!(m.resolve("abcdef12"), Ok("abcdef12-1"));
    assert_eq!(m.resolve("abc"), Ok("abc"), "an id is itself, however short");
    assert_eq!(m.resolve("abcdef"), Err(TransitionError::AmbiguousPrefix { prefix: "abcdef".into(), count: 2 }));
    assert_eq!(m.resolve("abcd"), Err(TransitionError::UnknownJob("abcd".into())), "too short to be a prefix");
    assert_eq!(m.resolve("abcdef9"), Err(TransitionError::UnknownJob("abcdef9".into())));
}

/// A job that waits for others is not leased until they are done; one that failed blocks it
/// (and, down the chain, the jobs waiting for it) until it is requeued and done.
#[test]
fn a_job_after_others_starts_when_they_are_done_and_is_blocked_when_one_fails() {
    let mut m = JobsModel::default();
    m.submit("a", spec(1, 0, None), 0).unwrap();
    m.submit("b", JobSpec { after: vec!["a".into()], ..spec(1, 9, None) }, 0).unwrap();
    m.submit("c", JobSpec { after: vec!["b".into()], ..spec(1, 9, None) }, 0).unwrap();
    let waiting = |m: &JobsModel, id: &str| m.waiting(&m.jobs[id]);
    assert_eq!(waiting(&m, "b"), Some(Waiting::For("a".into())));
    let (first, _) = m.lease("w", 4, 1, TTL);
    assert!(first.iter().all(|l| l.job == "a"), "b and c rank higher but wait");
    m.cancel("a", 2).unwrap();
    assert_eq!(waiting(&m, "b"), Some(Waiting::Blocked { job: "a".into(), why: "was cancelled" }));
    assert_eq!(waiting(&m, "c"), Some(Waiting::Blocked { job: "b".into(), why: "is blocked" }));
    assert!(m.lease("w", 4, 3, TTL).0.is_empty());
    m.requeue("a", 0, 4).unwrap();
    assert_eq!(waiting(&m, "c"), Some(Waiting::For("b".into())));
    for l in m.lease("w", 4, 5, TTL).0 {
        assert_eq!(l.job, "a");
        m.result("w", &l, Ok(()), 6);
    }
    m.merged("a", 4, 7);
    assert_eq!((m.jobs["a"].state, waiting(&m, "b")), (JobState::Done, None));
    assert_eq!(m.lease("w", 1, 8, TTL).0[0].job, "b");
}

/// A job that requires tags is leased only to workers with all of them; workers without them
/// neither get it nor strand it (it waits), and a tagged worker blocklisted for it does.
#[test]
fn required_tags_pick_the_workers_and_a_job_nobody_serves_waits() {
    let mut m = JobsModel::default();
    let tags = |t: &[&str]| t.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    for (w, t) in [("plain", tags(&[])), ("big", tags(&["big", "fast"]))] {
        m.apply(Event::Register { worker: w, host: None, tags: t }, 0).unwrap();
    }
    m.submit("a", JobSpec { require_tags: tags(&["big"]), ..spec(1, 0, None) }, 0).unwrap();
    assert!(m.lease("plain", 4, 1, TTL).0.is_empty());
    assert!(m.fail_stranded(&["plain"], 2).0.is_empty(), "nobody can serve it: it waits");
    assert_eq!(m.lease("big", 1, 3, TTL).0.len(), 1);
    m.apply(Event::Register { worker: "big", host: None, tags: vec![] }, 4).unwrap();
    assert!(m.lease("big", 4, 5, TTL).0.is_empty(), "re-registered without its tags");
}
