//! The driver's cut of jobs into passes and its barriers, for every kind of job: what makes a
//! farm render and a local one add the same tiles.

use super::*;
use crate::emis::EmisConfig;

/// The kinds of job the cut tells apart.
#[derive(Clone, Copy, Debug)]
enum Kind {
    Pt,
    Lt,
    Vcm,
    Emis,
}

fn shape(kind: Kind, spp: Option<u32>, time_s: Option<f64>) -> Shape {
    let budget = match (spp, time_s) {
        (Some(n), _) => Budget::Samples(n),
        (None, Some(t)) => Budget::Time(Duration::from_secs_f64(t)),
        (None, None) => unreachable!("a budget"),
    };
    let emis = matches!(kind, Kind::Emis)
        .then(|| EmisSchedule { updates: EmisConfig::DEFAULT_UPDATES.to_vec(), initial_nu: 0.0 });
    Shape { width: 130, height: 70, budget, tile: matches!(kind, Kind::Pt).then_some(64), emis }
}

/// A driver at the barrier after `done` iterations, the film keeping those from `kept_from`,
/// whose last pass collected moments (`collected`) with a strategy of `nu`, at `clock`; and the
/// time of that barrier.
fn at(shape: &Shape, done: u32, kept_from: u32, clock: Clock, collected: bool, nu: f32) -> (Driver, f64) {
    let now_ms = 1e6;
    let mut passes = Vec::new();
    let pass = |tiles: Range<usize>, restart, iterations: &Range<u32>| Pass {
        kind: PassKind::Final,
        tiles,
        collect: collected,
        restart,
        nu,
        planned_ms: (clock.last_pass_s > 0.0)
            .then(|| now_ms - clock.last_pass_s * 1000.0 * iterations.len().max(1) as f64),
        iterations: 0..0,
    };
    let mut ranges = Vec::new();
    if kept_from > 0 && kept_from < done {
        ranges = vec![0..kept_from, kept_from..done];
        passes.push(pass(0..1, false, &ranges[0]));
        passes.push(pass(1..2, true, &ranges[1]));
    } else {
        ranges.push(0..done);
        passes.push(pass(0..1, false, &ranges[0]));
    }
    let started = (clock.elapsed_s > 0.0).then(|| now_ms - clock.elapsed_s * 1000.0);
    let tiles = passes.len();
    (Driver::restore(shape.clone(), passes, started, tiles, |tile| ranges[tile].clone()).unwrap(), now_ms)
}

fn clock(elapsed_s: f64) -> Clock {
    Clock { elapsed_s, last_pass_s: 0.0 }
}

/// The next step at a barrier (see [`at`]).
fn after_pass(shape: &Shape, done: u32, kept_from: u32, c: Clock, collected: bool, nu: f32) -> Step {
    let (mut driver, now) = at(shape, done, kept_from, c, collected, nu);
    driver.barrier(now)
}

/// The pass after an update at `done` (a restart there when `kept_from == done`), and whether
/// it collects.
fn pass_after_update(
    shape: &Shape,
    done: u32,
    kept_from: u32,
    c: Clock,
    nu: f32,
    collect: bool,
) -> (Vec<Range<u32>>, bool) {
    let restarted = kept_from == done && done > 0;
    let (mut driver, now) = at(shape, done, if restarted { 0 } else { kept_from }, c, true, 0.0);
    let tiles = driver.updated(restarted, nu, collect, now);
    (tiles.iter().map(|t| t.samples.clone()).collect(), driver.passes().last().unwrap().collect)
}

fn ranges(step: Step) -> (Vec<Range<u32>>, usize) {
    match step {
        Step::Render(tiles) => (tiles.iter().map(|t| t.samples.clone()).collect(), tiles.len()),
        other => panic!("{other:?}"),
    }
}

#[test]
fn pt_covers_every_pixel_once_with_all_samples() {
    let (_, tiles) = Driver::new(shape(Kind::Pt, Some(8), None));
    assert_eq!(tiles.len(), 3 * 2);
    assert_eq!(tiles.iter().map(|t| t.rect.area()).sum::<usize>(), 130 * 70);
    assert!(tiles.iter().all(|t| t.samples == (0..8)));
}

#[test]
fn bidir_is_one_full_frame_iteration_per_tile() {
    let (mut driver, tiles) = Driver::new(shape(Kind::Vcm, Some(3), None));
    assert_eq!(tiles.len(), 3);
    for (i, t) in tiles.iter().enumerate() {
        assert_eq!(t.rect, Rect::full(130, 70));
        assert_eq!(t.samples, i as u32..i as u32 + 1);
    }
    assert_eq!(driver.barrier(1000.0), Step::Finish);
    assert!(
        matches!(Driver::new(shape(Kind::Lt, Some(2), None)).1.as_slice(), [a, b] if a.samples == (0..1) && b.samples == (1..2))
    );
}

#[test]
fn a_time_budget_adds_passes_until_the_time_is_used() {
    let s = shape(Kind::Pt, None, Some(10.0));
    assert!(Driver::new(s.clone()).1.iter().all(|t| t.samples == (0..1)));
    assert_eq!(ranges(after_pass(&s, 1, 0, clock(0.1), false, 0.0)).0[0], 1..11);
    assert_eq!(after_pass(&s, 50, 0, clock(10.5), false, 0.0), Step::Finish);
}

/// The driver's own clock: started at the first work, the pace of the last pass measured from
/// its planning to the barrier that ends it.
#[test]
fn the_clock_runs_from_the_start_and_times_the_last_pass() {
    let (mut driver, _) = Driver::new(shape(Kind::Pt, None, Some(10.0)));
    driver.start(5_000.0);
    driver.start(6_000.0);
    assert_eq!(driver.started_ms(), Some(5_000.0));
    // one iteration in 0.1 s: a pass of a tenth of the budget, 10 iterations
    let (r, _) = ranges(driver.barrier(5_100.0));
    assert_eq!(r[0], 1..11);
    // those 10 took 5 s: the dearer pace (0.5 s) leaves room for 8 more before the deadline
    let (r, _) = ranges(driver.barrier(10_100.0));
    assert_eq!(r[0], 11..13, "a tenth of the budget at the last pass's 0.5 s an iteration, not the average's 0.46 s");
    assert_eq!(driver.passes().len(), 3);
    assert_eq!(driver.expected_total(12, 10_100.0), 12 + (4.9 / (5.1 / 12.0)) as u32);
}

/// A 10⁸ s budget at a microsecond an iteration: passes stay small, counts never overflow,
/// and the job ends at MAX_SPP iterations (it once planned 10⁹ tiles, or wrapped around to an
/// empty pass and never ended).
#[test]
fn a_huge_time_budget_is_planned_in_bounded_passes_that_end() {
    use crate::settings::MAX_SPP;
    for kind in [Kind::Lt, Kind::Pt, Kind::Emis] {
        let s = shape(kind, None, Some(1e8));
        let mut done = Driver::new(s.clone()).1.last().unwrap().samples.end;
        let mut passes = 0;
        loop {
            let c = Clock { elapsed_s: done as f64 * 1e-6, last_pass_s: 1e-6 };
            match after_pass(&s, done, 0, c, false, 0.0) {
                Step::Render(tiles) => {
                    let end = tiles.iter().map(|t| t.samples.end).max().unwrap();
                    assert!(end > done && end - done <= MAX_TIMED_PASS, "{kind:?}: {done}..{end}");
                    assert!(tiles.len() <= MAX_TIMED_PASS as usize * 6, "{kind:?}: {} tiles", tiles.len());
                    done = end;
                }
                Step::Finish => break,
                Step::Update(_) => unreachable!("no moments collected"),
            }
            passes += 1;
            assert!(passes <= MAX_SPP / MAX_TIMED_PASS + 2, "{kind:?} does not end");
        }
        assert_eq!(done, MAX_SPP, "{kind:?}");
    }
}

/// The passes and barriers of an EMIS job with a sample budget: updates after 1 and 4 (16 is
/// not reached within 12), moments collected up to the last reachable update only.
#[test]
fn emis_passes_end_at_the_updates_the_budget_reaches() {
    let s = shape(Kind::Emis, Some(12), None);
    let (_, first) = Driver::new(s.clone());
    assert_eq!(first.len(), 1);
    assert!(Driver::new(s.clone()).0.passes()[0].collect);
    assert!(matches!(after_pass(&s, 1, 0, clock(1.0), true, 0.0), Step::Update(RestartTotal::Samples(13))));
    let (second, collect) = pass_after_update(&s, 1, 0, clock(1.0), 0.0, true);
    assert_eq!((second[0].start, second.len(), collect), (1, 3, true));
    assert!(matches!(after_pass(&s, 4, 0, clock(1.0), true, 0.0), Step::Update(_)));
    // after the last update the pass is cut into calls of FINAL_ITERATIONS_PER_CALL
    assert_eq!(pass_after_update(&s, 4, 0, clock(1.0), 0.0, true), (vec![4..12], false));
    // a collecting pass: a call per iteration that records under path tracing (0 and
    // ≡ 2 mod 4 before 16), one per run between them
    let s42 = shape(Kind::Emis, Some(42), None);
    let collecting = pass_after_update(&s42, 4, 0, clock(1.0), 0.0, true);
    assert_eq!(collecting, (vec![4..6, 6..7, 7..10, 10..11, 11..14, 14..15, 15..16], true));
    // from SPARSE_FROM (16) on, every eighth iteration records (≡ 6 mod 8)
    let s100 = shape(Kind::Emis, Some(100), None);
    let (sparse, collect) = pass_after_update(&s100, 16, 0, clock(1.0), 0.0, true);
    assert_eq!(sparse[..5], [16..22, 22..23, 23..30, 30..31, 31..38]);
    assert_eq!(sparse[sparse.len() - 2..], [62..63, 63..64]);
    assert!(collect);
    assert_eq!(pass_after_update(&s42, 16, 0, clock(1.0), 0.0, true), (vec![16..24, 24..32, 32..40, 40..42], false));
    // path tracing settled at 4: no more moments, path tracing's final calls
    let (settled, collect) = pass_after_update(&s100, 4, 0, clock(1.0), 0.0, false);
    assert_eq!((collect, settled[0].clone()), (false, 4..12));
    // a bidirectional strategy records every iteration: calls of up to eight iterations
    // (one upload each), cut at the update
    let s80 = shape(Kind::Emis, Some(80), None);
    assert_eq!(pass_after_update(&s80, 4, 0, clock(1.0), 0.5, true).0, [4..12, 12..16]);
    let (bidir, _) = pass_after_update(&s80, 16, 0, clock(1.0), 1.0, true);
    assert_eq!(bidir.len(), 6);
    assert!(bidir.iter().all(|r| r.len() == 8));
    assert_eq!(after_pass(&s, 12, 0, clock(1.0), false, 0.0), Step::Finish);
    // a budget that ends at an update point runs no update there, and collects nothing for it
    let s4 = shape(Kind::Emis, Some(4), None);
    assert_eq!(pass_after_update(&s4, 1, 0, clock(1.0), 0.0, true), (vec![1..4], false));
    let one = Driver::new(shape(Kind::Emis, Some(1), None)).0;
    assert!(!one.passes()[0].collect);
    // other integrators never collect
    assert!(!Driver::new(shape(Kind::Vcm, Some(12), None)).0.passes()[0].collect);
}

/// After the last update path tracing's calls take a sixteenth of what is left, from 64 down
/// to 8; a bidirectional strategy keeps calls of 8.
#[test]
fn path_tracing_after_the_last_update_runs_in_shrinking_calls() {
    let s = shape(Kind::Emis, Some(400), None);
    assert!(matches!(after_pass(&s, 64, 0, clock(1.0), true, 0.0), Step::Update(_)));
    let (pt, collect) = pass_after_update(&s, 64, 0, clock(1.0), 0.0, true);
    assert!(!collect);
    // 336 left: 21, then 315 left: 19, ...
    assert_eq!(pt[..2], [64..85, 85..104]);
    assert!(pt.windows(2).all(|w| w[0].end == w[1].start && w[0].len() >= w[1].len()));
    assert_eq!((pt[0].start, pt.last().unwrap().end), (64, 400));
    // the tail: calls of 8, the last one the rest
    assert_eq!((pt[pt.len() - 2].len(), pt.last().unwrap().len()), (8, 5));
    assert!(pt.len() >= 16 && pt.len() < 42, "{}", pt.len());
    let long = pass_after_update(&shape(Kind::Emis, Some(4000), None), 64, 0, clock(1.0), 0.0, true);
    assert_eq!(long.0[0], 64..128);
    let (bidir, _) = pass_after_update(&s, 64, 0, clock(1.0), 0.5, true);
    assert_eq!(bidir.len(), 42);
    assert!(bidir[..41].iter().all(|r| r.len() == 8));
}

/// A time budget collects for an update only with at least as many iterations after it as
/// before (`emis::update_pays`): after 4 of about 22 iterations the update at 16 is skipped,
/// after 4 of 40 it is not, under path tracing and a bidirectional strategy alike.
#[test]
fn a_short_timed_render_skips_a_late_update() {
    let s = shape(Kind::Emis, None, Some(20.0));
    let (short, collect) = pass_after_update(&s, 4, 0, clock(3.6), 0.0, true);
    assert!(!collect);
    assert!(short.iter().all(|r| r.start >= 4));
    let (long, collect) = pass_after_update(&s, 4, 0, clock(2.0), 0.0, true);
    assert!(collect);
    assert!(long.last().unwrap().end <= 16);
    assert!(!pass_after_update(&s, 4, 0, clock(3.6), 0.5, true).1);
    assert!(pass_after_update(&s, 4, 0, clock(2.0), 0.5, true).1);
}

/// A time budget plans a pass by the dearer of the average pace and the last pass's: after a
/// restart from path tracing (4 pt iterations in 1 s), one VCM iteration measures the new pace
/// first, and the 2 s it took, not the 0.6 s average, plans the pass after it. By the average
/// the job would collect for the update at 16, which it cannot reach.
#[test]
fn a_timed_pass_is_planned_by_the_dearer_of_the_average_and_the_last_pace() {
    let s = shape(Kind::Emis, None, Some(20.0));
    assert_eq!(pass_after_update(&s, 4, 4, clock(1.0), 1.0, true).0, [4..5]);
    let next = |c: Clock| ranges(after_pass(&s, 5, 4, c, true, 1.0)).0;
    let (mut driver, now) = at(&s, 5, 4, Clock { elapsed_s: 3.0, last_pass_s: 2.0 }, true, 1.0);
    assert_eq!(driver.barrier(now), Step::Render(vec![TileSpec { rect: Rect::full(130, 70), samples: 5..6 }]));
    assert!(!driver.passes().last().unwrap().collect);
    assert_eq!(next(clock(3.0)), [5..8]);
    let (mut driver, now) = at(&s, 5, 4, clock(3.0), true, 1.0);
    driver.barrier(now);
    assert!(driver.passes().last().unwrap().collect);
    let total = |c| {
        let (d, now) = at(&s, 5, 4, c, true, 1.0);
        match d.restart_total(now) {
            RestartTotal::Time(n) => n,
            other => panic!("{other:?}"),
        }
    };
    assert_eq!(total(Clock { elapsed_s: 3.0, last_pass_s: 2.0 }), 13);
    assert_eq!(total(clock(3.0)), 33);
    // a last pass cheaper than the average does not shorten the estimate
    assert_eq!(total(Clock { elapsed_s: 3.0, last_pass_s: 0.1 }), 33);
    // a sample budget ignores the clock
    let n = shape(Kind::Emis, Some(40), None);
    assert_eq!(pass_after_update(&n, 4, 4, Clock { elapsed_s: 3.0, last_pass_s: 2.0 }, 1.0, true).0.len(), 2);
}

/// A path-tracing start discarded at the update after iteration 1: the sample budget counts
/// the 12 iterations the film keeps, 1..13, and the update schedule stays on the iteration
/// count (the next update after 4).
#[test]
fn after_a_restart_the_whole_budget_goes_into_the_new_film() {
    let s = shape(Kind::Emis, Some(12), None);
    assert_eq!(pass_after_update(&s, 1, 1, clock(1.0), 0.0, true), (vec![1..2, 2..3, 3..4], true));
    assert!(matches!(after_pass(&s, 4, 1, clock(1.0), true, 0.0), Step::Update(RestartTotal::Samples(16))));
    assert_eq!(pass_after_update(&s, 4, 1, clock(1.0), 0.0, true).0, [4..12, 12..13]);
    assert!(matches!(after_pass(&s, 12, 1, clock(1.0), false, 0.0), Step::Render(_)));
    assert_eq!(after_pass(&s, 13, 1, clock(1.0), false, 0.0), Step::Finish);
    // a time budget is wall time, whatever was discarded
    let t = shape(Kind::Emis, None, Some(10.0));
    assert_eq!(after_pass(&t, 40, 1, clock(10.5), false, 0.0), Step::Finish);
}

/// A whole EMIS job driven barrier by barrier, as its owners run it: every iteration planned
/// once, in order, the updates asked for at 1, 4 and 16, and the job finished at its budget.
#[test]
fn an_emis_job_runs_from_pilot_to_finish() {
    let (mut driver, mut tiles) = Driver::new(shape(Kind::Emis, Some(40), None));
    let (mut next, mut updates) = (0, Vec::new());
    for barrier in 0.. {
        assert!(barrier < 100, "the job ends");
        for t in &tiles {
            assert_eq!(t.samples.start, next);
            next = t.samples.end;
        }
        tiles = match driver.barrier(barrier as f64) {
            Step::Render(t) => t,
            Step::Update(_) => {
                updates.push(next);
                driver.updated(false, 0.0, true, barrier as f64)
            }
            Step::Finish => break,
        };
    }
    assert_eq!((next, updates), (40, vec![1, 4, 16]));
    assert!(driver.finishes(1e9));
}

/// Stored passes come back with their iterations from the tiles, and passes that do not tile
/// the tiles are refused.
#[test]
fn a_restored_driver_takes_its_iterations_from_the_tiles_and_refuses_gaps() {
    let (driver, tiles) = Driver::new(shape(Kind::Emis, Some(40), None));
    let samples = |i: usize| tiles[i].samples.clone();
    let passes = driver.passes().to_vec();
    let back = Driver::restore(driver.shape().clone(), passes.clone(), None, tiles.len(), samples).unwrap();
    assert_eq!(back, driver);
    assert!(Driver::restore(driver.shape().clone(), passes.clone(), None, tiles.len() + 1, samples).is_err());
    let mut gap = passes;
    gap[0].tiles.start = 1;
    assert!(Driver::restore(driver.shape().clone(), gap, None, tiles.len(), samples).unwrap_err().contains("follow"));
}
