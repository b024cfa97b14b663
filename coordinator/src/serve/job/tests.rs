//! Tests of the pure job state machine: every transition, plus property tests over arbitrary
//! interleavings of lease, heartbeat, expiry, result and failure events.

use super::model::BarrierAction;
use super::model::LeaseLifetime;
use super::model::calls::Calls;
use super::model::*;
use proptest::prelude::*;
use tessera_common::settings::{IntegratorName, RenderSettings};

const TTL: u64 = 1000;
/// A lifetime long enough never to matter, but in the tests of it.
const LONG: LeaseLifetime = LeaseLifetime { floor_ms: 1 << 40, factor: 8.0 };

fn spec(integrator: IntegratorName, spp: u32, priority: i32) -> JobSpec {
    JobSpec {
        name: "j".into(),
        priority,
        settings: RenderSettings { integrator, spp: Some(spp), seed: Some(7), ..Default::default() },
        width: 128,
        height: 128,
        full_frame: integrator.full_frame(),
        bundle_digest: "digest".into(),
        scene_path: "scene.xml".into(),
        filter: tessera_common::film::filter::FilterKind::Box,
        after: Vec::new(),
        require_tags: Vec::new(),
        frame: None,
        warm: None,
    }
}

/// Merges whatever can be merged, as the service does, and counts merges per tile.
fn merge_all(m: &mut JobsModel, job: &str, merges: &mut Vec<u32>, now: u64) {
    loop {
        let r = m.mergeable(job);
        if r.is_empty() {
            return;
        }
        for i in r.clone() {
            if merges.len() <= i {
                merges.resize(i + 1, 0);
            }
            merges[i] += 1;
        }
        if let (Some(BarrierAction::Optimize), _) = m.merged(job, r.end, now) {
            // the service runs the optimiser here
            m.optimized(job, false, 1.0, true, now).unwrap();
        }
    }
}

#[test]
fn job_runs_queued_final_done_and_merges_in_order() {
    let mut m = JobsModel::default();
    m.submit("a", spec(IntegratorName::Pt, 4, 0), 0).unwrap();
    assert_eq!(m.jobs["a"].state, JobState::Queued);
    assert_eq!(m.jobs["a"].tiles.len(), 4);
    let (leases, _) = m.lease("w1", 4, 10, TTL);
    assert_eq!(leases.len(), 4);
    assert_eq!(m.jobs["a"].state, JobState::Final);
    // results arrive out of order: nothing merges until tile 0 is in
    for l in leases.iter().rev().take(3) {
        assert_eq!(m.result("w1", l, Ok(()), 20).0, ResultOutcome::Accepted);
    }
    assert!(m.mergeable("a").is_empty());
    m.result("w1", &leases[0], Ok(()), 20);
    assert_eq!(m.mergeable("a"), 0..4);
    let (action, _) = m.merged("a", 4, 30);
    assert_eq!(action, Some(BarrierAction::Finish));
    assert_eq!(m.jobs["a"].state, JobState::Done);
    assert_eq!(m.jobs["a"].samples_merged(), 128 * 128 * 4);
}

#[test]
fn expired_lease_requeues_with_next_epoch_and_late_result_is_stale() {
    let mut m = JobsModel::default();
    m.submit("a", spec(IntegratorName::Vcm, 2, 0), 0).unwrap();
    let (l, _) = m.lease("w1", 8, 0, TTL);
    assert_eq!(l.len(), 1, "full-frame jobs lease one tile at a time");
    assert_eq!(m.heartbeat("w1", &l, 900, TTL), vec![]);
    assert!(m.expire(1500, &LONG).is_empty(), "the heartbeat extended the lease");
    let changes = m.expire(1900, &LONG);
    assert_eq!(changes["a"].iter().copied().collect::<Vec<_>>(), vec![0]);
    assert_eq!(m.jobs["a"].tiles[0].epoch, 1);
    assert_eq!(m.result("w1", &l[0], Ok(()), 2000).0, ResultOutcome::Stale);
    assert_eq!(m.heartbeat("w1", &l, 2000, TTL), l, "the old lease is reported lost");
    let (l2, _) = m.lease("w2", 1, 2000, TTL);
    assert_eq!(l2[0], LeaseRef { job: "a".into(), tile: 0, epoch: 1 });
    assert_eq!(m.result("w2", &l2[0], Ok(()), 2100).0, ResultOutcome::Accepted);
    assert_eq!(m.result("w2", &l2[0], Ok(()), 2100).0, ResultOutcome::Duplicate);
}

/// A worker that heartbeats but never returns loses its tile at the lease's lifetime: the
/// floor before anything is measured, then `factor` times the slowest measured rate, doubled
/// at each earlier failure of the tile.
#[test]
fn a_lease_held_past_its_lifetime_is_requeued_despite_heartbeats() {
    let life = LeaseLifetime { floor_ms: 5 * TTL, factor: 4.0 };
    let mut m = JobsModel::default();
    m.submit("a", spec(IntegratorName::Pt, 1, 0), 0).unwrap();
    let (stuck, _) = m.lease("stuck", 1, 0, TTL);
    let mut now = 0;
    while m.heartbeat("stuck", &stuck, now, TTL).is_empty() {
        assert!(now < 5 * TTL, "held past the floor");
        now += TTL / 2;
        m.expire(now, &life);
    }
    assert_eq!(now, 5 * TTL, "lost at the floor, not before");
    assert_eq!((m.jobs["a"].tiles[0].epoch, m.jobs["a"].worker_failures["stuck"]), (1, 1));
    // "fast" takes tiles 0 and 1; tile 1 (64² pixels × 1 sample) comes back after 2 s
    let (l, _) = m.lease("fast", 2, now, TTL);
    assert_eq!((l[0].tile, l[1].tile), (0, 1));
    m.result("fast", &l[1], Ok(()), now + 2000);
    let rate = m.jobs["a"].slowest_ms_per_sample.unwrap();
    let samples = m.jobs["a"].tiles[1].spec.pixel_samples() as f64;
    assert!((rate * samples - 2000.0).abs() < 1e-6, "{rate}");
    assert_eq!(life.of(&m.jobs["a"], 2), 8000, "4 × 2 s, above the 5 s floor");
    assert_eq!(life.of(&m.jobs["a"], 0), 16_000, "tile 0 failed once: twice as long");
    // tile 0's second holder heartbeats but never returns it: cut off 16 s after its lease
    m.heartbeat("fast", &l[..1], now + 15_900, TTL);
    assert!(m.expire(now + 15_900, &life).is_empty());
    assert!(!m.expire(now + 16_000, &life).is_empty());
    assert_eq!(m.heartbeat("fast", &l[..1], now + 16_000, TTL), l[..1], "told to abandon it");
}

/// When the coordinator stalled, its leases' clocks move on by the stall: nothing expires for it.
#[test]
fn postponed_leases_do_not_expire_for_the_coordinators_stall() {
    let life = LeaseLifetime { floor_ms: 2 * TTL, factor: 4.0 };
    let mut m = JobsModel::default();
    m.submit("a", spec(IntegratorName::Pt, 1, 0), 0).unwrap();
    let (l, _) = m.lease("w", 1, 0, TTL);
    m.postpone_leases(10 * TTL);
    assert!(m.expire(10 * TTL + TTL / 2, &life).is_empty());
    assert_eq!(m.heartbeat("w", &l, 10 * TTL + TTL / 2, TTL), vec![]);
    assert!(!m.expire(12 * TTL, &life).is_empty(), "the lifetime still holds after the stall");
}

#[test]
fn refused_result_requeues_and_repeat_offender_is_blocklisted() {
    let mut m = JobsModel::default();
    m.submit("a", spec(IntegratorName::Pt, 1, 0), 0).unwrap();
    for round in 0..BLOCKLIST_AFTER_FAILURES {
        let (l, _) = m.lease("bad", 1, 0, TTL);
        assert_eq!(l.len(), 1, "round {round}");
        let (outcome, _) = m.result("bad", &l[0], Err("sum is NaN".into()), 0);
        assert_eq!(outcome, ResultOutcome::Refused("sum is NaN".into()));
        assert_eq!(m.jobs["a"].tiles[l[0].tile].state, TileState::Queued);
    }
    assert!(m.jobs["a"].is_blocklisted("bad"));
    assert!(m.lease("bad", 1, 0, TTL).0.is_empty());
    assert_eq!(m.lease("good", 1, 0, TTL).0.len(), 1);
}

/// A worker token holder on one host registering afresh before each failure it reports
/// cannot fail a job alone: its host is blocklisted, and a worker elsewhere renders the tile.
/// Failures from a second host still fail a job that fails everywhere.
#[test]
fn one_host_cannot_fail_a_job_alone_even_by_registering_afresh() {
    let mut m = JobsModel::default();
    m.submit("a", spec(IntegratorName::Bdpt, 1, 0), 0).unwrap();
    let mut lies = 0;
    for k in 0..3 * MAX_TILE_FAILURES {
        let liar = format!("liar{k}");
        m.hosts.insert(liar.clone(), "10.0.0.66".into());
        let (l, _) = m.lease(&liar, 1, 0, TTL);
        if l.is_empty() {
            break;
        }
        m.report_failure(&liar, &l[0], "fake", 0);
        lies += 1;
    }
    assert_eq!(lies, HOST_BLOCKLIST_AFTER_FAILURES, "the host is blocklisted for the job");
    assert_ne!(m.jobs["a"].state, JobState::Failed);
    let liars: Vec<String> = (0..lies).map(|k| format!("liar{k}")).collect();
    let (stranded, _) = m.fail_stranded(&liars.iter().map(String::as_str).collect::<Vec<_>>(), 0);
    assert!(stranded.is_empty(), "no liar failed three times itself: the job waits for another host");
    m.hosts.insert("honest".into(), "10.0.0.7".into());
    let (l, _) = m.lease("honest", 1, 0, TTL);
    assert_eq!(l.len(), 1, "a worker on another host gets the tile");
    // it fails too: the tile is broken everywhere, which hosts beside the liar's now show
    m.report_failure("honest", &l[0], "really broken", 0);
    assert_ne!(m.jobs["a"].state, JobState::Failed, "the liar's failures count three at most");
    for k in 0..MAX_FAILURES_PER_HOST - 1 {
        let w = format!("second{k}");
        m.hosts.insert(w.clone(), "10.0.0.8".into());
        let (l, _) = m.lease(&w, 1, 0, TTL);
        m.report_failure(&w, &l[0], "really broken", 0);
    }
    assert_eq!(m.jobs["a"].state, JobState::Failed, "other hosts' failures fail it");
}

#[test]
fn tile_failing_too_often_fails_the_job() {
    let mut m = JobsModel::default();
    m.submit("a", spec(IntegratorName::Bdpt, 1, 0), 0).unwrap();
    for k in 0..MAX_TILE_FAILURES {
        let (l, _) = m.lease(&format!("w{k}"), 1, 0, TTL);
        m.report_failure(&format!("w{k}"), &l[0], "scene failed to load", 0);
    }
    assert_eq!(m.jobs["a"].state, JobState::Failed);
    assert!(m.jobs["a"].error.as_deref().unwrap().contains("scene failed to load"));
    assert!(m.lease("w9", 1, 0, TTL).0.is_empty());
}

#[test]
fn priorities_order_jobs_then_submission_order() {
    let mut m = JobsModel::default();
    m.submit("low", spec(IntegratorName::Pt, 1, 0), 0).unwrap();
    m.submit("high", spec(IntegratorName::Pt, 1, 5), 1).unwrap();
    m.submit("high2", spec(IntegratorName::Pt, 1, 5), 2).unwrap();
    assert!(m.lease("w", 4, 0, TTL).0.iter().all(|l| l.job == "high"));
    assert!(m.lease("w", 4, 0, TTL).0.iter().all(|l| l.job == "high2"));
    assert!(m.lease("w", 4, 0, TTL).0.iter().all(|l| l.job == "low"));
}

#[test]
fn cancel_stops_dispatch_and_makes_results_stale() {
    let mut m = JobsModel::default();
    m.submit("a", spec(IntegratorName::Pt, 1, 0), 0).unwrap();
    let (l, _) = m.lease("w", 1, 0, TTL);
    m.cancel("a", 1).unwrap();
    assert_eq!(m.jobs["a"].state, JobState::Cancelled);
    assert!(m.lease("w", 4, 2, TTL).0.is_empty());
    assert_eq!(m.result("w", &l[0], Ok(()), 3).0, ResultOutcome::Stale);
    assert!(m.mergeable("a").is_empty());
    assert!(m.cancel("nope", 0).is_err());
}

#[test]
fn time_budget_plans_passes_at_barriers() {
    let mut m = JobsModel::default();
    let mut s = spec(IntegratorName::Pt, 1, 0);
    s.settings.spp = None;
    s.settings.time_s = Some(1.0);
    m.submit("a", s, 0).unwrap();
    let (l, _) = m.lease("w", 8, 0, TTL);
    for x in &l {
        m.result("w", x, Ok(()), 10);
    }
    let (action, changes) = m.merged("a", 4, 10);
    assert!(matches!(action, Some(BarrierAction::NextPass)));
    assert_eq!(m.jobs["a"].passes().len(), 2);
    assert_eq!(changes["a"].len(), 8, "the merged tiles and the new pass's tiles");
    assert_eq!(m.jobs["a"].tiles[4].spec.samples.start, 1);
}

/// A timed EMIS job plans by the dearer of the average pace and its last pass's: after a
/// cheap path-tracing start (4 iterations in 30 ms) restarts into VCM, one iteration of 1.9 s
/// measures the new pace, and the pass after it gets 3 iterations (a tenth of 60 s at 1.9 s
/// each), not the 11 up to the update at 16 that the average of 0.38 s would give.
#[test]
fn a_timed_emis_job_paces_the_pass_after_a_restart_by_its_last_pass() {
    let mut m = JobsModel::default();
    let mut s = spec(IntegratorName::EmisVcm, 1, 0);
    (s.settings.spp, s.settings.time_s) = (None, Some(60.0));
    m.submit("a", s, 0).unwrap();
    // leases, renders and merges everything planned, finishing at `now`
    let step = |m: &mut JobsModel, now: u64| {
        for l in m.lease("w", 64, now, TTL).0 {
            m.result("w", &l, Ok(()), now);
        }
        let r = m.mergeable("a");
        m.merged("a", r.end, now).0
    };
    let mut now = 0;
    while m.jobs["a"].spp_merged() < 4 {
        now += 10;
        if let Some(BarrierAction::Optimize) = step(&mut m, now) {
            // the update after 1 keeps path tracing; the one after 4 restarts into VCM
            let restart = m.jobs["a"].spp_merged() == 4;
            m.optimized("a", restart, if restart { 1.0 } else { 0.0 }, true, now).unwrap();
        }
    }
    assert_eq!((now, m.jobs["a"].kept_from()), (40, 4));
    let ranges = |m: &JobsModel| {
        let pass = m.jobs["a"].passes().last().unwrap().tiles.clone();
        m.jobs["a"].tiles[pass].iter().map(|t| t.spec.samples.clone()).collect::<Vec<_>>()
    };
    assert_eq!(ranges(&m), [4..5]);
    assert_eq!(m.jobs["a"].passes().last().unwrap().planned_ms, Some(40.0));
    assert!(matches!(step(&mut m, 1940), Some(BarrierAction::NextPass)));
    assert_eq!(ranges(&m), [5..8]);
}

#[test]
fn emis_job_runs_pilot_optimizing_final_with_a_pass_per_update() {
    let mut m = JobsModel::default();
    m.submit("a", spec(IntegratorName::EmisVcm, 6, 0), 0).unwrap();
    assert_eq!(m.optimized("a", false, 1.0, true, 0), Err(TransitionError::NotOptimizing("a".into())));
    let job = &m.jobs["a"];
    assert_eq!((job.passes().len(), job.passes()[0].kind, job.collects(0)), (1, PassKind::Pilot, true));
    let (l, _) = m.lease("w", 8, 0, TTL);
    assert_eq!((l.len(), m.jobs["a"].state), (1, JobState::Pilot));
    m.result("w", &l[0], Ok(()), 1);
    let (action, _) = m.merged("a", 1, 1);
    assert_eq!(action, Some(BarrierAction::Optimize));
    assert_eq!(m.jobs["a"].state, JobState::Optimizing);
    assert!(m.lease("w", 8, 1, TTL).0.is_empty(), "nothing to render while optimising");
    m.optimized("a", false, 1.0, true, 2).unwrap();
    let job = &m.jobs["a"];
    assert_eq!(job.state, JobState::Final);
    // a bidirectional strategy (ν = 1) records every iteration: iterations 1..4 in one tile
    assert_eq!((job.passes()[1].tiles.clone(), job.passes()[1].collect, job.passes()[1].nu), (1..2, true, 1.0));
    assert_eq!(job.tiles[1].spec.samples, 1..4);
    let mut merges = vec![1];
    for _ in 0..10 {
        for l in m.lease("w", 8, 3, TTL).0 {
            m.result("w", &l, Ok(()), 3);
        }
        merge_all(&mut m, "a", &mut merges, 3);
    }
    let job = &m.jobs["a"];
    assert_eq!(job.state, JobState::Done);
    assert_eq!(
        job.passes().iter().map(|p| (p.tiles.clone(), p.collect)).collect::<Vec<_>>(),
        // the final iterations 4..6 are one tile (FINAL_ITERATIONS_PER_CALL)
        [(0..1, true), (1..2, true), (2..3, false)]
    );
}

#[test]
fn progress_never_falls_when_an_update_discards_a_path_tracing_start() {
    let mut m = JobsModel::default();
    m.submit("a", spec(IntegratorName::EmisVcm, 6, 0), 0).unwrap();
    let (mut shown, mut barriers) = (vec![0.0], 0);
    for _ in 0..20 {
        for l in m.lease("w", 1, 3, TTL).0 {
            m.result("w", &l, Ok(()), 3);
            shown.push(super::view::JobView::of(&m.jobs["a"], 3).progress);
        }
        loop {
            let r = m.mergeable("a");
            if r.is_empty() {
                break;
            }
            let action = m.merged("a", r.end, 3).0;
            shown.push(super::view::JobView::of(&m.jobs["a"], 3).progress);
            if let Some(BarrierAction::Optimize) = action {
                barriers += 1;
                // the second update ends the path-tracing start, as the service's EMIS state says
                m.optimized("a", barriers == 2, 1.0, true, 3).unwrap();
                shown.push(super::view::JobView::of(&m.jobs["a"], 3).progress);
            }
        }
    }
    let job = &m.jobs["a"];
    assert_eq!(job.state, JobState::Done);
    assert!(job.passes().iter().any(|p| p.restart) && job.kept_from() > 0, "{:?}", job.passes());
    assert!(shown.windows(2).all(|w| w[1] >= w[0]), "progress fell: {shown:?}");
    assert!(shown.iter().rev().nth(1).is_some_and(|&p| p < 1.0), "{shown:?}");
    assert_eq!(shown.last(), Some(&1.0));
}

/// One step of a random schedule.
#[derive(Clone, Debug)]
enum Action {
    Lease {
        worker: usize,
        max: usize,
    },
    Heartbeat {
        worker: usize,
    },
    Advance {
        ms: u64,
    },
    Result {
        pick: usize,
        valid: bool,
        wrong_worker: bool,
    },
    Fail {
        pick: usize,
    },
    Pause,
    Resume,
    /// Cancel, then requeue from a checkpoint of at most `keep` tiles.
    CancelRequeue {
        keep: usize,
    },
}

fn action() -> impl Strategy<Value = Action> {
    prop_oneof![
        (0..3usize, 1..4usize).prop_map(|(worker, max)| Action::Lease { worker, max }),
        (0..3usize).prop_map(|worker| Action::Heartbeat { worker }),
        (0..1500u64).prop_map(|ms| Action::Advance { ms }),
        (0..64usize, proptest::bool::weighted(0.85), proptest::bool::weighted(0.05))
            .prop_map(|(pick, valid, wrong_worker)| Action::Result { pick, valid, wrong_worker }),
        (0..64usize).prop_map(|pick| Action::Fail { pick }),
        Just(Action::Pause),
        Just(Action::Resume),
        (0..64usize).prop_map(|keep| Action::CancelRequeue { keep }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    /// Under any interleaving, with pauses, resumes and requeues from a checkpoint, each tile
    /// is accepted at most once, merged exactly once when the job completes (once more after
    /// a requeue whose checkpoint did not hold it), a paused job hands out nothing, epochs never go back, and the merged prefix is exactly the merged
    /// tiles; the same workers, well-behaved from then on, finish the job or see it fail with
    /// a reason (a tile failed too often, or every one of them is blocklisted).
    // long: one scenario, its interleaving then the invariants over the state it left
    #[test]
    fn exactly_once_merge_under_arbitrary_interleavings(
        events in proptest::collection::vec(action(), 1..120),
        full_frame in any::<bool>(),
        emis in any::<bool>(),
        spp in 1..6u32,
    ) {
        let integrator = match (full_frame, emis) {
            (false, _) => IntegratorName::Pt,
            (true, false) => IntegratorName::Vcm,
            (true, true) => IntegratorName::EmisVcm,
        };
        let mut m = JobsModel::default();
        m.submit("j", spec(integrator, spp, 0), 0).unwrap();
        let mut now = 0u64;
        let mut issued: Vec<(String, LeaseRef)> = Vec::new();
        let mut merges = Vec::new();
        let mut accepted = std::collections::HashMap::<usize, u32>::new();
        let mut epochs: Vec<u64> = m.jobs["j"].tiles.iter().map(|t| t.epoch).collect();
        for e in events {
            match e {
                Action::Lease { worker, max } => {
                    let w = format!("w{worker}");
                    let blocked = m.jobs["j"].is_blocklisted(&w);
                    let paused = m.jobs["j"].paused_ms.is_some();
                    let (leases, _) = m.lease(&w, max, now, TTL);
                    prop_assert!(!blocked || leases.is_empty(), "a blocklisted worker got a lease");
                    prop_assert!(!paused || leases.is_empty(), "a paused job handed out a tile");
                    issued.extend(leases.into_iter().map(|l| (w.clone(), l)));
                }
                Action::Heartbeat { worker } => {
                    let w = format!("w{worker}");
                    let mine: Vec<LeaseRef> = issued.iter().filter(|(x, _)| *x == w).map(|(_, l)| l.clone()).collect();
                    m.heartbeat(&w, &mine, now, TTL);
                }
                Action::Advance { ms } => {
                    now += ms;
                    m.expire(now, &LONG);
                }
                Action::Result { pick, valid, wrong_worker } if !issued.is_empty() => {
                    let (w, l) = issued[pick % issued.len()].clone();
                    let w = if wrong_worker { "intruder".to_string() } else { w };
                    let verdict = if valid { Ok(()) } else { Err("bad".to_string()) };
                    let (outcome, _) = m.result(&w, &l, verdict, now);
                    if outcome == ResultOutcome::Accepted {
                        *accepted.entry(l.tile).or_default() += 1;
                        prop_assert_eq!(m.jobs["j"].tiles[l.tile].epoch, l.epoch);
                    }
                }
                Action::Fail { pick } if !issued.is_empty() => {
                    let (w, l) = issued[pick % issued.len()].clone();
                    m.report_failure(&w, &l, "failed", now);
                }
                Action::Pause => {
                    let _ = m.pause("j", now);
                }
                Action::Resume => {
                    let _ = m.resume("j", now);
                }
                Action::CancelRequeue { keep } => {
                    let merged = m.jobs["j"].merged;
                    let keep = keep.min(merged);
                    let _ = m.cancel("j", now);
                    if m.requeue("j", keep, now).is_ok() {
                        // the film went back to the checkpoint: those tiles merge again
                        for n in &mut merges[keep..merged] {
                            *n -= 1;
                        }
                    }
                }
                _ => {}
            }
            merge_all(&mut m, "j", &mut merges, now);
            let job = &m.jobs["j"];
            for (i, t) in job.tiles.iter().enumerate() {
                prop_assert!(t.epoch >= epochs.get(i).copied().unwrap_or(0), "epoch went back");
                prop_assert_eq!(t.state == TileState::Merged, i < job.merged);
            }
            epochs = job.tiles.iter().map(|t| t.epoch).collect();
            let mut rebuilt = job.clone();
            rebuilt.reindex();
            prop_assert_eq!(&rebuilt.index, &job.index, "the ready-tile index drifted");
            prop_assert!(accepted.values().all(|&n| n == 1), "a tile was accepted twice");
            prop_assert!(merges.iter().all(|&n| n <= 1), "a tile was merged twice");
        }
        // the same workers drive the job to completion after all leases lapse: it ends done,
        // or failed because a tile failed too often or every worker is blocklisted for it
        now += 10 * TTL;
        m.expire(now, &LONG);
        let _ = m.resume("j", now);
        let workers = ["w0", "w1", "w2"];
        for _ in 0..1000 {
            let mut leased = false;
            for w in workers {
                for l in m.lease(w, 4, now, TTL).0 {
                    leased = true;
                    prop_assert_eq!(m.result(w, &l, Ok(()), now).0, ResultOutcome::Accepted);
                }
                merge_all(&mut m, "j", &mut merges, now);
            }
            if !leased {
                m.fail_stranded(&workers, now);
                break;
            }
        }
        let job = &m.jobs["j"];
        match job.state {
            JobState::Failed => {
                let blocklisted = workers.iter().all(|w| job.is_blocklisted(w));
                let failed_tile = job.tiles.iter().any(|t| t.failures >= MAX_TILE_FAILURES);
                prop_assert!(blocklisted || failed_tile, "failed for no reason: {:?}", job.error);
                prop_assert!(workers.iter().all(|w| m.lease(w, 4, now, TTL).0.is_empty()));
            }
            _ => {
                prop_assert_eq!(job.state, JobState::Done);
                prop_assert_eq!(merges.len(), job.tiles.len());
                prop_assert!(merges.iter().all(|&n| n == 1));
                prop_assert_eq!(job.samples_merged(), 128 * 128 * spp as u64);
            }
        }
    }
}

/// A stalled first tile bounds what can pile up behind it: 1080p full-frame vcm results
/// (66 MB each) are leased no further than the window past the merge frontier, and the window
/// moves on once the frontier does.
#[test]
fn leases_stay_within_a_window_past_the_merge_frontier() {
    let mut m = JobsModel::default();
    let mut s = spec(IntegratorName::Vcm, 64, 0);
    (s.width, s.height) = (1920, 1080);
    m.submit("a", s, 0).unwrap();
    let window = m.jobs["a"].leasable();
    assert_eq!(window.start, 0);
    assert!((MIN_LEASE_WINDOW..=16).contains(&window.len()), "{window:?}");
    assert!(m.jobs["a"].tiles.len() > window.len());
    let mut leases = Vec::new();
    for _ in 0..m.jobs["a"].tiles.len() {
        leases.extend(m.lease("w1", 1, 10, TTL).0);
    }
    assert_eq!(leases.len(), window.len(), "no lease past the window");
    // every tile but the stalled first one arrives and waits
    for l in &leases[1..] {
        assert_eq!(m.result("w1", l, Ok(()), 20).0, ResultOutcome::Accepted);
    }
    assert!(m.lease("w2", 1, 30, TTL).0.is_empty(), "the window is full while tile 0 stalls");
    m.result("w1", &leases[0], Ok(()), 40);
    let mut merges = Vec::new();
    merge_all(&mut m, "a", &mut merges, 50);
    assert_eq!(m.jobs["a"].merged, window.len());
    let next = m.lease("w2", 1, 60, TTL).0;
    assert_eq!(next.iter().map(|l| l.tile).collect::<Vec<_>>(), [window.len()], "the window moved");
}

/// The last merge leaves a job finishing, not done: nothing more is leased, the outputs are
/// asked for, and only their arrival ends the job; a job cancelled meanwhile refuses them.
#[test]
fn last_merge_asks_for_outputs_and_only_their_arrival_ends_the_job() {
    let mut m = JobsModel::default();
    for id in ["a", "b"] {
        m.submit(id, spec(IntegratorName::Pt, 1, 0), 0).unwrap();
        let (leases, _) = m.lease("w", 4, 1, TTL);
        assert_eq!(leases.len(), 4);
        for l in leases.iter().rev() {
            let e = m.apply(Event::Result { worker: "w", lease: l, verdict: Ok(()) }, 2).unwrap();
            let merge = (l.tile == 0).then(|| Effect::Merge { job: id.into(), tiles: 0..4 });
            assert_eq!(e.then.get(1), merge.as_ref(), "only the frontier's tile makes tiles mergeable");
        }
        let e = m.apply(Event::Merged { job: id, upto: 4 }, 3).unwrap();
        assert_eq!(e.then, vec![Effect::WriteOutputs { job: id.into(), upto: 4 }]);
        assert_eq!((m.jobs[id].state, m.jobs[id].state.as_str()), (JobState::Finishing, "final"));
    }
    assert!(m.lease("w", 4, 4, TTL).0.is_empty());
    let e = m.apply(Event::OutputsWritten { job: "a" }, 5).unwrap();
    assert_eq!(e.then, vec![Effect::Ended { job: "a".into(), state: JobState::Done }]);
    assert_eq!(m.jobs["a"].finished_ms, Some(5));
    let e = m.apply(Event::Cancel { job: "b" }, 5).unwrap();
    assert_eq!(e.then, vec![Effect::Ended { job: "b".into(), state: JobState::Cancelled }]);
    assert_eq!(m.apply(Event::OutputsWritten { job: "b" }, 6), Err(TransitionError::NotFinishing("b".into())));
}
