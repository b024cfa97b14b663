//! Tests of the EMIS state: restarts, the kept start, settling and the pilot merging after a
//! restart.

use super::*;
use crate::emis::PilotStart;
use crate::emis::cost::CostTerms;
use crate::integrator::observer::WorkTimes;

const SIDE: u32 = 16;

/// One iteration of pilot data in which every pixel has `moment(candidate)`.
fn pilot(state: &EmisState, moment: impl Fn(&Candidate) -> f32) -> PilotData {
    let k = state.candidates.len();
    let mut moments = MomentBuffer::new(SIDE, SIDE, k);
    for (i, sum) in moments.sums.iter_mut().enumerate() {
        *sum = moment(&state.candidates[i % k]);
    }
    moments.iterations = 1;
    let statistics = StatisticsSums { iterations: 1, camera_vertices: 3 * (SIDE * SIDE) as u64, ..Default::default() };
    PilotData { moments, statistics, guides: GuideBuffer::new(SIDE, SIDE) }
}

/// A path-tracing start: path tracing stays while it wins (nothing discarded); the update a
/// bidirectional candidate wins restarts (full set, empty moments and statistics, the
/// image kept from that iteration on) with that candidate's global merge decision.
#[test]
fn a_path_tracing_start_restarts_when_a_bidirectional_candidate_wins() {
    let config = EmisConfig::new(EmisMethod::Vcm);
    let mut state = EmisState::new(config, SIDE, SIDE);
    assert_eq!((state.candidate_set, state.candidates.len()), (CandidateSet::Reduced, 9));
    assert_eq!(state.strategy, Strategy::path_tracing_start(EmisMethod::Vcm));
    let image = vec![[0.5f32; 3]; (SIDE * SIDE) as usize];
    let mut pt_wins = pilot(&state, |c| if c.is_path_tracing() { 1.0 } else { 1e3 });
    // path tracing's probe (costs measured per job), which only the first call runs
    let probe = WorkTimes { path_tracing_vertices: 100, path_tracing_ns: 500, ..Default::default() };
    pt_wins.statistics.times = probe;
    state.absorb(&pt_wins).unwrap();
    let report = state.update(&image, 1, RestartTotal::Samples(64)).clone();
    assert!(report.reduced && !report.restarted, "{report:?}");
    assert_eq!(report.candidates.len(), 9);
    assert_eq!((state.strategy.nu, state.candidate_set, state.kept_from), (0.0, CandidateSet::Reduced, 0));
    assert_eq!(state.moments.iterations, 1, "moments are kept while path tracing stays");
    // merged with the first iteration's moments, the target's mean is 10× lower than pt's
    let target = Candidate { nu: 1.0, connections: 0, merge: true };
    state.absorb(&pilot(&state, |c| if *c == target { 1e-3 } else { 1e4 })).unwrap();
    let report = state.update(&image, 4, RestartTotal::Samples(64)).clone();
    assert!(report.reduced && report.restarted, "{report:?}");
    assert_eq!(
        state.strategy,
        Strategy { nu: 1.0, connections: Connections::Fixed(0), merge: Some(MergeMask::Constant(1.0)) },
        "merging everywhere"
    );
    assert_eq!((state.candidate_set, state.candidates.len(), state.kept_from), (CandidateSet::Full, 51, 4));
    assert_eq!((state.moments.iterations, state.moments.sums.len()), (0, 51 * (SIDE * SIDE) as usize));
    assert!(state.moments.sums.iter().all(|&s| s == 0.0));
    assert_eq!(state.statistics, StatisticsSums { times: probe, ..Default::default() }, "all but the probe restart");
    assert!(state.collecting(), "the update after 16 follows, on the full set");
    let start = state.start.clone().expect("the start is kept");
    assert_eq!((start.image, start.iterations, start.weight), (image.clone(), 4, None));
    state.absorb(&pilot(&state, |c| if c.nu == 0.5 && c.connections == 2 { 1e-3 } else { 1.0 })).unwrap();
    let report = state.update(&image, 16, RestartTotal::Samples(64)).clone();
    assert!(!report.reduced && !report.restarted, "{report:?}");
    // pt's relative variance is about 3, the winner's almost 0: the start weighs little
    let k = state.start.as_ref().and_then(|s| s.weight).expect("the full set's update weighs the start");
    assert!(k > 0.0 && k < 1e-3 && report.start_weight == Some(k), "{k} {report:?}");
    assert_eq!((state.strategy.nu, &state.strategy.connections, state.kept_from), (0.5, &Connections::Fixed(2), 4));
    assert!(matches!(state.strategy.merge, Some(MergeMask::PerPixel(_))));
}

/// A restart into a candidate that merges nowhere renders with merging everywhere until
/// the full set's update that follows it (the report says so); at the last update, which
/// no other follows, it keeps the candidate's own global decision. emis-bdpt never merges.
#[test]
fn a_restart_pilots_the_next_update_with_merging_everywhere() {
    let image = vec![[0.5f32; 3]; (SIDE * SIDE) as usize];
    let target = Candidate { nu: 1.0, connections: 1, merge: false };
    let restart = |method: EmisMethod, updates: Vec<u32>| {
        let config = EmisConfig { updates, ..EmisConfig::new(method) };
        let mut state = EmisState::new(config, SIDE, SIDE);
        state.absorb(&pilot(&state, |c| if *c == target { 1e-3 } else { 1e4 })).unwrap();
        let report = state.update(&image, 4, RestartTotal::Samples(1000)).clone();
        assert!(report.restarted, "{report:?}");
        assert_eq!((state.strategy.nu, &state.strategy.connections), (1.0, &Connections::Fixed(1)));
        (state.strategy.merge, report.mean_merge_probability)
    };
    assert_eq!(restart(EmisMethod::Vcm, vec![4, 16]), (Some(MergeMask::Constant(1.0)), 1.0));
    assert_eq!(restart(EmisMethod::Vcm, vec![1, 4]), (Some(MergeMask::Constant(0.0)), 0.0));
    assert_eq!(restart(EmisMethod::Bdpt, vec![4, 16]), (None, 0.0));
}

/// A timed restart whose next update the render would reach but not pay for (fewer
/// iterations after it than before, at the winner's pace: kitchen at 20 s) is one that no
/// update follows. Its winner's own merge decision is rendered to the end, not the merging
/// pilot meant for that update, and nothing more is recorded.
#[test]
fn a_restart_whose_next_update_would_not_pay_renders_its_winner() {
    let image = vec![[0.5f32; 3]; (SIDE * SIDE) as usize];
    let target = Candidate { nu: 1.0, connections: 1, merge: false };
    let config = EmisConfig::new(EmisMethod::Vcm);
    // the winner as `reaches` prices it, merging everywhere, against path tracing
    let sums = StatisticsSums { iterations: 1, camera_vertices: 3 * (SIDE * SIDE) as u64, ..Default::default() };
    let merged = Candidate { merge: true, ..target };
    let terms = CostTerms::of_candidates(
        &config.constants,
        &sums.statistics(SIDE * SIDE),
        &[Candidate::PATH_TRACING, merged],
        SIDE * SIDE,
    );
    let dearer = terms[1].at(1.0) / terms[0].at(0.0);
    assert!(dearer > 1.5, "{dearer}");
    let restart = |pt_pace: u32| {
        let mut state = EmisState::new(config.clone(), SIDE, SIDE);
        state.absorb(&pilot(&state, |c| if *c == target { 1e-3 } else { 1e4 })).unwrap();
        let report = state.update(&image, 1, RestartTotal::Time(pt_pace)).clone();
        assert!(report.restarted, "{report:?}");
        (state.strategy.merge.clone(), state.collecting(), report.mean_merge_probability)
    };
    // about 6 iterations at the winner's pace: the update after 4 comes, but would not pay
    let short = 1 + (5.0 * dearer).round() as u32;
    assert_eq!(restart(short), (Some(MergeMask::Constant(0.0)), false, 0.0));
    // about 12: it pays, so the restart pilots it merging everywhere and records
    let long = 1 + (11.0 * dearer).round() as u32;
    assert_eq!(restart(long), (Some(MergeMask::Constant(1.0)), true, 1.0));
}

/// A path-tracing start switches only to a candidate that beats path tracing by more than
/// the share of the render a restart discards: 1.5× better is worth discarding 1 of 64
/// iterations, not 16 of 20. A restart that an update of the full set follows (after 4 of
/// 17, the next update after 16) discards nothing, and 1.05× better is enough; under a
/// time budget of 17 iterations at pt's pace the dearer winner would not reach 16.
#[test]
fn a_restart_must_win_back_the_iterations_it_discards() {
    let config = EmisConfig::new(EmisMethod::Vcm);
    let image = vec![[0.5f32; 3]; (SIDE * SIDE) as usize];
    let target = Candidate { nu: 1.0, connections: 0, merge: false };
    use RestartTotal::{Samples, Time};
    for (iteration, total, better, restarts) in [
        (1, Samples(64), 1.5, true),
        (16, Samples(64), 1.5, true),
        (16, Samples(20), 1.5, false),
        (16, Samples(16), 1.5, false),
        (4, Samples(17), 1.05, true),
        (16, Samples(64), 1.05, false),
        (4, Time(17), 1.05, false),
        (4, Time(u32::MAX), 1.05, true),
    ] {
        let mut state = EmisState::new(config.clone(), SIDE, SIDE);
        // the target's moment × cost is `better` times lower than path tracing's
        let (pt_cost, target_cost) = {
            // the statistics of `pilot`: three camera vertices per pixel
            let sums =
                StatisticsSums { iterations: 1, camera_vertices: 3 * (SIDE * SIDE) as u64, ..Default::default() };
            let s = sums.statistics(SIDE * SIDE);
            let terms = crate::emis::cost::CostTerms::of_candidates(
                &config.constants,
                &s,
                &[Candidate::PATH_TRACING, target],
                SIDE * SIDE,
            );
            (terms[0].at(0.0), terms[1].at(0.0))
        };
        // the time-budget case needs 4 + 13 · pt / target ≤ 16
        assert!(target_cost / pt_cost > 1.1, "{target_cost} {pt_cost}");
        let moment = |c: &Candidate| match c {
            c if c.is_path_tracing() => 1.0,
            c if *c == target => (pt_cost / target_cost / better) as f32,
            _ => 1e3,
        };
        state.absorb(&pilot(&state, moment)).unwrap();
        let report = state.update(&image, iteration, total).clone();
        assert_eq!(report.restarted, restarts, "update after {iteration} of {total:?}: {report:?}");
        assert_eq!(state.strategy.nu > 0.0, restarts);
    }
}

/// A path-tracing start settles on path tracing when it wins two updates in a row by the
/// margin: not after a narrow win (every bidirectional candidate 1.05× path tracing's
/// moment × cost, over the iterations so far), nor after one clear win (1000×), nor on
/// one recorded iteration, and never with an infinite margin.
#[test]
fn path_tracing_settles_after_two_clear_wins_in_a_row() {
    let config = EmisConfig::new(EmisMethod::Vcm);
    let image = vec![[0.5f32; 3]; (SIDE * SIDE) as usize];
    // one iteration in which path tracing's moment is `pt` and every other candidate's
    // moment × cost is `other` times path tracing's cost
    let iteration_of = |state: &EmisState, pt: f64, other: f64| {
        let sums = StatisticsSums { iterations: 1, camera_vertices: 3 * (SIDE * SIDE) as u64, ..Default::default() };
        let statistics = sums.statistics(SIDE * SIDE);
        let terms = CostTerms::of_candidates(&config.constants, &statistics, &state.candidates, SIDE * SIDE);
        let pt_cost = terms[state.candidates.iter().position(Candidate::is_path_tracing).unwrap()].at(0.0);
        let moments: Vec<f32> = (terms.iter().zip(&state.candidates))
            .map(|(t, c)| if c.is_path_tracing() { pt } else { other * pt_cost / t.at(c.merge as u8 as f64) })
            .map(|m| m as f32)
            .collect();
        let mut data = pilot(state, |_| 0.0);
        let k = moments.len();
        data.moments.sums.iter_mut().enumerate().for_each(|(i, s)| *s = moments[i % k]);
        data
    };
    // the margins each update sees over the iterations so far: path tracing's moment grows
    // a thousandfold per update, so a later update can undo an earlier clear win
    let run = |config: &EmisConfig, margins: &[f64]| {
        let mut state = EmisState::new(config.clone(), SIDE, SIDE);
        let (mut pt_sum, mut other_sum) = (0.0, 0.0);
        for (i, (&margin, iteration)) in margins.iter().zip([1, 4, 16]).enumerate() {
            if !state.collecting() {
                break;
            }
            let pt = 1e3f64.powi(i as i32);
            let other = margin * (pt_sum + pt) - other_sum;
            (pt_sum, other_sum) = (pt_sum + pt, other_sum + other);
            state.absorb(&iteration_of(&state, pt, other)).unwrap();
            let report = state.update(&image, iteration, RestartTotal::Samples(1000)).clone();
            let seen = report.path_tracing_margin();
            assert!((seen / margin - 1.0).abs() < 0.01, "{margins:?}: {seen} {report:?}");
            assert_eq!(report.settled, !state.collecting(), "{margins:?}: {report:?}");
            if report.settled {
                assert_eq!(state.next_update(), None);
                return Some(iteration);
            }
        }
        None
    };
    for (margins, settles_at) in
        [([1e3, 1e3, 1e3], Some(4)), ([1.05, 1e3, 1e3], Some(16)), ([1e3, 1.05, 1e3], None), ([1.05, 1.05, 1.05], None)]
    {
        assert_eq!(run(&config, &margins), settles_at, "{margins:?}");
    }
    let never = EmisConfig { settle_margin: f64::INFINITY, ..config.clone() };
    assert_eq!(run(&never, &[1e3, 1e3, 1e3]), None);
    // updates after 1 and 2 see the same single recording (iteration 1 records nothing)
    let mut state = EmisState::new(EmisConfig { updates: vec![1, 2, 4], ..config.clone() }, SIDE, SIDE);
    state.absorb(&iteration_of(&state, 1.0, 1e3)).unwrap();
    assert!(!state.update(&image, 1, RestartTotal::Samples(1000)).settled);
    assert!(!state.update(&image, 2, RestartTotal::Samples(1000)).settled);
    state.absorb(&iteration_of(&state, 1.0, 1e3)).unwrap();
    assert!(state.update(&image, 4, RestartTotal::Samples(1000)).settled);
}

/// The bidirectional pilot (`EmisConfig::own_pilot`) never restarts, even when its first
/// update chooses a bidirectional strategy.
#[test]
fn the_bidirectional_pilot_never_restarts() {
    let mut state = EmisState::new(EmisConfig::own_pilot(EmisMethod::Bdpt), SIDE, SIDE);
    assert_eq!((state.candidate_set, state.candidates.len()), (CandidateSet::Full, 26));
    state.absorb(&pilot(&state, |c| if c.nu == 2.0 && c.connections == 1 { 1e-3 } else { 1.0 })).unwrap();
    let report = state.update(&vec![[0.5f32; 3]; (SIDE * SIDE) as usize], 1, RestartTotal::Samples(64)).clone();
    assert!(!report.reduced && !report.restarted);
    assert_eq!((state.strategy.nu, state.kept_from, state.moments.iterations), (2.0, 0, 1));
}

/// A warm start begins with the strategy it was handed and decides from the full set (an
/// update restarts nothing); a path-tracing decision under the path-tracing start starts as
/// that start does, and under the method's own pilot is kept.
#[test]
fn a_warm_start_begins_with_the_strategy_it_was_handed() {
    let decided = Strategy { nu: 0.5, connections: Connections::Fixed(2), merge: Some(MergeMask::Constant(0.25)) };
    let config = EmisConfig {
        pilot: PilotStart::PathTracing,
        warm_start: Some(decided.clone()),
        ..EmisConfig::own_pilot(EmisMethod::Vcm)
    };
    let mut state = EmisState::new(config.clone(), SIDE, SIDE);
    assert_eq!((&state.strategy, state.candidate_set, state.candidates.len()), (&decided, CandidateSet::Full, 51));
    state.absorb(&pilot(&state, |c| if c.nu == 0.5 { 1e-3 } else { 1.0 })).unwrap();
    let image = vec![[0.5f32; 3]; (SIDE * SIDE) as usize];
    let report = state.update(&image, 1, RestartTotal::Samples(64)).clone();
    assert!(!report.reduced && !report.restarted, "{report:?}");
    assert_eq!((state.kept_from, state.start.is_none(), state.strategy.nu), (0, true, 0.5));
    let pt = Strategy::path_tracing();
    let cold = EmisState::new(EmisConfig { warm_start: Some(pt.clone()), ..config.clone() }, SIDE, SIDE);
    assert_eq!(cold.strategy, Strategy::path_tracing_start(EmisMethod::Vcm));
    assert_eq!(cold.candidate_set, CandidateSet::Reduced);
    let own = EmisConfig { warm_start: Some(pt.clone()), pilot: PilotStart::Bidirectional, ..config };
    let kept = EmisState::new(own, SIDE, SIDE);
    assert_eq!((kept.strategy, kept.candidate_set), (pt, CandidateSet::Full));
}
