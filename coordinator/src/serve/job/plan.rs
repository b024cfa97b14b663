//! How a job is cut into tiles and passes: the canonical decomposition that makes a farm
//! render bit-identical to `tessera render`.
//!
//! Local rendering (`tessera_common::render`) adds tile sums into a zeroed film. With a sample
//! budget, image-tile integrators (pt) render every tile's whole sample range in one pass: each
//! pixel's sum is accumulated sample by sample inside one tile and added once to a zero, so the
//! tile size does not change a single bit. Full-frame integrators (lt, bdpt, vcm) render one
//! iteration per pass and add the passes in iteration order. The farm therefore uses
//! * pt: [`TILE_SIZE`]² rectangles × the whole range `[0, spp)`, any merge order;
//! * lt, bdpt, vcm: the full frame × `[i, i + 1)` per tile, merged in iteration order;
//! * emis-*: the full frame × the calls `render_emis` makes (`emis::collecting_call` while
//!   collecting moments, `emis::final_call` after), merged in iteration order.
//!
//! Tiles are numbered in merge order across passes, and the coordinator merges strictly in
//! that order (holding results that arrive early), so the film gets the same additions in the
//! same order as locally: bit-for-bit equality, not just equality within rounding.
//!
//! Time budgets have no local bit-exact twin (local passes depend on wall time too); they plan
//! one pass at a time at the barrier that ends the previous one, by the dearer of the average
//! pace and the last pass's ([`Clock`]), as `render_emis` plans its calls.

use super::spec::{JobSpec, TileSpec};
use tessera_common::emis::{
    Strategy, calls, collecting_call, final_call, iterations_at_pace, seconds_per_iteration, update_pays,
};
use tessera_common::film::Rect;
use tessera_common::settings::MAX_SPP;

/// Edge of the rectangles of image-tile integrators.
pub const TILE_SIZE: u32 = 64;

/// The most iterations one pass of a time budget plans. Passes are planned one at a time at
/// barriers, so this only caps what one planning allocates: a 10⁸ s budget at a fast pace
/// asked for a tenth of it, about 10⁹ full-frame tiles, in one pass.
pub const MAX_TIMED_PASS: u32 = 1024;

/// A pass to append: its tiles, and whether they collect EMIS moments.
#[derive(Clone, Debug, PartialEq)]
pub struct PassPlan {
    /// The tiles, in merge order.
    pub tiles: Vec<TileSpec>,
    /// EMIS: the tiles record moments, statistics and guides for an update at the pass's end.
    pub collect: bool,
}

/// What a job does when a pass has been merged completely (a barrier).
#[derive(Clone, Debug, PartialEq)]
pub enum BarrierAction {
    /// Render this as the next pass, with the current strategy.
    NextPass(PassPlan),
    /// EMIS: an update is due. The coordinator runs the optimiser on the merged image and
    /// moments, then calls `JobsModel::optimized` with [`pass_after_update`].
    Optimize,
    /// Nothing left: the job is done.
    Finish,
}

fn is_emis(spec: &JobSpec) -> bool {
    spec.settings.integrator.emis_method().is_some()
}

/// Light paths per pixel of the strategy an EMIS job starts with (0 for other integrators).
pub fn initial_nu(spec: &JobSpec) -> f32 {
    spec.settings.integrator.emis_method().map_or(0.0, |m| Strategy::initial(m, spec.settings.emis_pilot).nu)
}

/// How long a job has rendered, which is what a time budget plans by.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Clock {
    /// Seconds since the job's first lease.
    pub elapsed_s: f64,
    /// Seconds per iteration of the pass that just ended, from its planning to its barrier;
    /// 0 while unknown.
    pub last_pass_s: f64,
}

impl Clock {
    /// The seconds the next iteration is expected to take after `spp_done`: the dearer of the
    /// average and the last pass's. After an EMIS restart from path tracing the average still
    /// holds cheap pt iterations, and a pass planned by it overruns the budget
    /// (docs/decisions/0038-time-budget-after-a-restart.md).
    fn pace(&self, spp_done: u32) -> f64 {
        seconds_per_iteration(self.elapsed_s, spp_done, self.last_pass_s).max(1e-9)
    }
}

impl From<f64> for Clock {
    /// A clock of `elapsed_s` seconds whose last pass's pace is unknown.
    fn from(elapsed_s: f64) -> Self {
        Clock { elapsed_s, last_pass_s: 0.0 }
    }
}

/// Iterations the budget allows in total, as far as is known after `spp_done` at `clock`
/// (a time budget's is unknown before the first iteration). A sample budget counts the
/// iterations the film keeps, from `kept_from` on (EMIS: a path-tracing start's iterations are
/// discarded when a bidirectional strategy wins).
pub fn expected_total(spec: &JobSpec, spp_done: u32, kept_from: u32, clock: impl Into<Clock>) -> u32 {
    let clock = clock.into();
    match (spec.settings.spp, spec.settings.time_s) {
        (Some(n), _) => kept_from + n,
        (None, Some(budget)) if spp_done > 0 && clock.elapsed_s > 0.0 => {
            iterations_at_pace(budget, clock.elapsed_s, spp_done, clock.pace(spp_done))
        }
        _ => u32::MAX,
    }
}

/// Iterations the next pass may render: the rest of a sample budget, or for a time budget
/// about a tenth of it, never planned past the deadline (as locally). 0: finished.
fn next_count(spec: &JobSpec, spp_done: u32, kept_from: u32, clock: Clock) -> u32 {
    match (spec.settings.spp, spec.settings.time_s) {
        (Some(n), _) => (kept_from + n).saturating_sub(spp_done),
        (None, Some(budget)) => {
            let remaining = budget - clock.elapsed_s;
            if remaining <= 0.0 || spp_done == 0 {
                return 0;
            }
            let pace = clock.pace(spp_done);
            // float-to-int casts saturate; the iteration count ends at MAX_SPP
            let fit = (remaining / pace).floor() as u32;
            fit.min(((budget * 0.1 / pace) as u32).max(1)).min(MAX_TIMED_PASS).min(MAX_SPP.saturating_sub(spp_done))
        }
        (None, None) => 0,
    }
}

/// A pass from `spp_done` of at most `count` iterations. EMIS collects moments while another
/// update can come within the budget and pay (`emis::update_pays`; `may_collect`: no earlier
/// pass stopped collecting), and then ends the pass at that update, where the barrier runs
/// it; `nu` is the current strategy's light paths per pixel, on which the cut of a pass
/// depends.
fn plan_from(spec: &JobSpec, spp_done: u32, count: u32, may_collect: bool, total: u32, nu: f32) -> PassPlan {
    let timed = spec.settings.spp.is_none();
    let update = spec.settings.emis_updates.iter().copied().find(|&u| u > spp_done);
    let update = update.filter(|&u| may_collect && is_emis(spec) && update_pays(u, total, timed));
    let end = spp_done.saturating_add(count);
    let end = update.map_or(end, |u| u.min(end));
    let collect = update.is_some();
    let full_frame = |samples| TileSpec { rect: Rect::full(spec.width, spec.height), samples };
    let tiles = if collect {
        // the calls `render_emis` makes: `collecting_call` while collecting, `final_call` after
        calls(spp_done..end, |r| collecting_call(r, nu)).into_iter().map(full_frame).collect()
    } else if is_emis(spec) {
        let pixels = spec.width as u64 * spec.height as u64;
        calls(spp_done..end, |r| final_call(r, nu, pixels)).into_iter().map(full_frame).collect()
    } else {
        pass_tiles(spec, spp_done, end - spp_done)
    };
    PassPlan { tiles, collect }
}

/// The first pass (the pilot for EMIS). A time budget starts with one iteration to measure
/// the speed.
pub fn first_pass(spec: &JobSpec) -> PassPlan {
    let count = spec.settings.spp.unwrap_or(1);
    plan_from(spec, 0, count, true, expected_total(spec, 0, 0, Clock::default()), initial_nu(spec))
}

/// Tiles rendering samples `[begin, begin + count)` of every pixel; full-frame tiles take one
/// iteration each.
pub fn pass_tiles(spec: &JobSpec, begin: u32, count: u32) -> Vec<TileSpec> {
    let count = count.min(u32::MAX - begin);
    if spec.full_frame {
        (begin..begin + count)
            .map(|i| TileSpec { rect: Rect::full(spec.width, spec.height), samples: i..i + 1 })
            .collect()
    } else {
        Rect::tiles(spec.width, spec.height, TILE_SIZE)
            .into_iter()
            .map(|rect| TileSpec { rect, samples: begin..begin + count })
            .collect()
    }
}

/// What to do at the barrier after a pass. `spp_done` samples per pixel are merged (the film
/// keeps those from `kept_from` on), `clock` says how long rendering took, and `collected`
/// says whether the pass collected moments; `nu` is the current strategy's.
/// An EMIS update is due when the pass collected up to an update point and iterations remain
/// to use it (as `render_emis` decides locally).
pub fn after_pass(
    spec: &JobSpec,
    spp_done: u32,
    kept_from: u32,
    clock: impl Into<Clock>,
    collected: bool,
    nu: f32,
) -> BarrierAction {
    let clock = clock.into();
    let total = expected_total(spec, spp_done, kept_from, clock);
    if collected && spec.settings.emis_updates.contains(&spp_done) && spp_done < total {
        return BarrierAction::Optimize;
    }
    match next_count(spec, spp_done, kept_from, clock) {
        0 => BarrierAction::Finish,
        count => BarrierAction::NextPass(plan_from(spec, spp_done, count, collected, total, nu)),
    }
}

/// The pass after an EMIS update at `spp_done` that chose a strategy with `nu` light paths
/// per pixel (at least one iteration: the update was run because iterations remain;
/// `kept_from` is `spp_done` if the update restarted the film). Under a time budget that pass
/// is one iteration, which measures the new strategy's pace before a longer pass is planned
/// by it, as `render_emis` does locally. `may_collect`: the update left the EMIS state
/// collecting (a path-tracing start that settled collects no more).
pub fn pass_after_update(
    spec: &JobSpec,
    spp_done: u32,
    kept_from: u32,
    clock: impl Into<Clock>,
    nu: f32,
    may_collect: bool,
) -> PassPlan {
    let clock = clock.into();
    let total = expected_total(spec, spp_done, kept_from, clock);
    let count = if spec.settings.spp.is_none() { 1 } else { next_count(spec, spp_done, kept_from, clock).max(1) };
    plan_from(spec, spp_done, count, may_collect, total, nu)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tessera_common::settings::{IntegratorName, RenderSettings};

    fn spec(integrator: IntegratorName, spp: Option<u32>, time_s: Option<f64>) -> JobSpec {
        JobSpec {
            name: "t".into(),
            priority: 0,
            settings: RenderSettings { integrator, spp, time_s, seed: Some(1), ..Default::default() },
            width: 130,
            height: 70,
            full_frame: integrator.full_frame(),
            bundle_digest: "d".into(),
            scene_path: "scene.xml".into(),
            filter: tessera_common::film::filter::FilterKind::Box,
        }
    }

    #[test]
    fn plan_pt_covers_every_pixel_once_with_all_samples() {
        let tiles = first_pass(&spec(IntegratorName::Pt, Some(8), None)).tiles;
        assert_eq!(tiles.len(), 3 * 2);
        assert_eq!(tiles.iter().map(|t| t.rect.area()).sum::<usize>(), 130 * 70);
        assert!(tiles.iter().all(|t| t.samples == (0..8)));
    }

    #[test]
    fn plan_bidir_is_one_full_frame_iteration_per_tile() {
        let tiles = first_pass(&spec(IntegratorName::Vcm, Some(3), None)).tiles;
        assert_eq!(tiles.len(), 3);
        for (i, t) in tiles.iter().enumerate() {
            assert_eq!(t.rect, Rect::full(130, 70));
            assert_eq!(t.samples, i as u32..i as u32 + 1);
        }
        assert_eq!(after_pass(&spec(IntegratorName::Vcm, Some(3), None), 3, 0, 1.0, false, 0.0), BarrierAction::Finish);
    }

    #[test]
    fn plan_time_budget_adds_passes_until_the_time_is_used() {
        let s = spec(IntegratorName::Pt, None, Some(10.0));
        assert!(first_pass(&s).tiles.iter().all(|t| t.samples == (0..1)));
        match after_pass(&s, 1, 0, 0.1, false, 0.0) {
            BarrierAction::NextPass(p) => assert_eq!(p.tiles[0].samples, 1..11),
            other => panic!("{other:?}"),
        }
        assert_eq!(after_pass(&s, 50, 0, 10.5, false, 0.0), BarrierAction::Finish);
    }

    /// A 10⁸ s budget at a microsecond an iteration: passes stay small, counts never
    /// overflow, and the job ends at MAX_SPP iterations (it once planned 10⁹ tiles, or
    /// wrapped around to an empty pass and never ended).
    #[test]
    fn plan_a_huge_time_budget_in_bounded_passes_that_end() {
        for integrator in [IntegratorName::Lt, IntegratorName::Pt, IntegratorName::EmisVcm] {
            let s = spec(integrator, None, Some(1e8));
            let mut done = first_pass(&s).tiles.last().unwrap().samples.end;
            let mut passes = 0;
            loop {
                let clock = Clock { elapsed_s: done as f64 * 1e-6, last_pass_s: 1e-6 };
                match after_pass(&s, done, 0, clock, false, 0.0) {
                    BarrierAction::NextPass(p) => {
                        let end = p.tiles.iter().map(|t| t.samples.end).max().unwrap();
                        assert!(end > done && end - done <= MAX_TIMED_PASS, "{integrator:?}: {done}..{end}");
                        assert!(
                            p.tiles.len() <= MAX_TIMED_PASS as usize * 6,
                            "{integrator:?}: {} tiles",
                            p.tiles.len()
                        );
                        done = end;
                    }
                    BarrierAction::Finish => break,
                    BarrierAction::Optimize => unreachable!("no moments collected"),
                }
                passes += 1;
                assert!(passes <= MAX_SPP / MAX_TIMED_PASS + 2, "{integrator:?} does not end");
            }
            assert_eq!(done, MAX_SPP, "{integrator:?}");
        }
    }

    /// The passes and barriers of an EMIS job with a sample budget, as `render_emis` does
    /// locally: updates after 1 and 4 (16 is not reached within 12), moments collected up to
    /// the last reachable update only.
    #[test]
    fn plan_emis_passes_end_at_the_updates_the_budget_reaches() {
        let s = spec(IntegratorName::EmisVcm, Some(12), None);
        let first = first_pass(&s);
        assert_eq!(first.tiles.len(), 1);
        assert!(first.collect);
        assert_eq!(after_pass(&s, 1, 0, 1.0, true, 0.0), BarrierAction::Optimize);
        let second = pass_after_update(&s, 1, 0, 1.0, 0.0, true);
        assert_eq!((second.tiles.first().unwrap().samples.start, second.tiles.len(), second.collect), (1, 3, true));
        assert_eq!(after_pass(&s, 4, 0, 1.0, true, 0.0), BarrierAction::Optimize);
        let third = pass_after_update(&s, 4, 0, 1.0, 0.0, true);
        // after the last update the pass is cut into calls of FINAL_ITERATIONS_PER_CALL
        assert_eq!(third.collect, false);
        let ranges: Vec<_> = third.tiles.iter().map(|t| t.samples.clone()).collect();
        assert_eq!(ranges, [4..12]);
        // a collecting pass: a call per iteration that records under path tracing (0 and
        // ≡ 2 mod 4 before 16), one per run between them
        let collecting = pass_after_update(&spec(IntegratorName::EmisVcm, Some(42), None), 4, 0, 1.0, 0.0, true);
        let ranges: Vec<_> = collecting.tiles.iter().map(|t| t.samples.clone()).collect();
        assert_eq!(ranges, [4..6, 6..7, 7..10, 10..11, 11..14, 14..15, 15..16]);
        assert!(collecting.collect);
        // from SPARSE_FROM (16) on, every eighth iteration records (≡ 6 mod 8)
        let sparse = pass_after_update(&spec(IntegratorName::EmisVcm, Some(100), None), 16, 0, 1.0, 0.0, true);
        let ranges: Vec<_> = sparse.tiles.iter().map(|t| t.samples.clone()).collect();
        assert_eq!(ranges[..5], [16..22, 22..23, 23..30, 30..31, 31..38]);
        assert_eq!(ranges[ranges.len() - 2..], [62..63, 63..64]);
        assert!(sparse.collect);
        let long = pass_after_update(&spec(IntegratorName::EmisVcm, Some(42), None), 16, 0, 1.0, 0.0, true);
        let ranges: Vec<_> = long.tiles.iter().map(|t| t.samples.clone()).collect();
        assert_eq!(ranges, [16..24, 24..32, 32..40, 40..42]);
        // path tracing settled at 4: no more moments, path tracing's final calls
        let settled = pass_after_update(&spec(IntegratorName::EmisVcm, Some(100), None), 4, 0, 1.0, 0.0, false);
        let ranges: Vec<_> = settled.tiles.iter().map(|t| t.samples.clone()).collect();
        assert_eq!((settled.collect, ranges[0].clone()), (false, 4..12));
        // a bidirectional strategy records every iteration: calls of up to eight iterations
        // (one upload each), cut at the update
        let bidir = pass_after_update(&spec(IntegratorName::EmisVcm, Some(80), None), 4, 0, 1.0, 0.5, true);
        let ranges: Vec<_> = bidir.tiles.iter().map(|t| t.samples.clone()).collect();
        assert_eq!(ranges, [4..12, 12..16]);
        let bidir = pass_after_update(&spec(IntegratorName::EmisVcm, Some(80), None), 16, 0, 1.0, 1.0, true);
        assert_eq!(bidir.tiles.len(), 6);
        assert!(bidir.tiles.iter().all(|t| t.samples.len() == 8));
        assert_eq!(after_pass(&s, 12, 0, 1.0, false, 0.0), BarrierAction::Finish);
        // a budget that ends at an update point runs no update there, and collects nothing
        // for it
        let s = spec(IntegratorName::EmisBdpt, Some(4), None);
        let after = pass_after_update(&s, 1, 0, 1.0, 0.0, true);
        assert!(!after.collect);
        assert_eq!(after.tiles.iter().map(|t| t.samples.clone()).collect::<Vec<_>>(), [1..4]);
        let one = first_pass(&spec(IntegratorName::EmisVcm, Some(1), None));
        assert!(!one.collect);
        // other integrators never collect
        assert!(!first_pass(&spec(IntegratorName::Vcm, Some(12), None)).collect);
    }

    /// After the last update path tracing's calls take a sixteenth of what is left, from 64
    /// down to 8, as `render_emis` cuts them; a bidirectional strategy keeps calls of 8.
    #[test]
    fn plan_path_tracing_after_the_last_update_in_shrinking_calls() {
        let s = spec(IntegratorName::EmisVcm, Some(400), None);
        assert_eq!(after_pass(&s, 64, 0, 1.0, true, 0.0), BarrierAction::Optimize);
        let pt = pass_after_update(&s, 64, 0, 1.0, 0.0, true);
        assert!(!pt.collect);
        let ranges: Vec<_> = pt.tiles.iter().map(|t| t.samples.clone()).collect();
        // 336 left: 21, then 315 left: 19, ...
        assert_eq!(ranges[..2], [64..85, 85..104]);
        assert!(ranges.windows(2).all(|w| w[0].end == w[1].start && w[0].len() >= w[1].len()));
        assert_eq!((ranges[0].start, ranges.last().unwrap().end), (64, 400));
        // the tail: calls of 8, the last one the rest
        assert_eq!((ranges[ranges.len() - 2].len(), ranges.last().unwrap().len()), (8, 5));
        assert!(ranges.len() >= 16 && ranges.len() < 42, "{}", ranges.len());
        let long = pass_after_update(&spec(IntegratorName::EmisVcm, Some(4000), None), 64, 0, 1.0, 0.0, true);
        assert_eq!(long.tiles[0].samples, 64..128);
        let bidir = pass_after_update(&s, 64, 0, 1.0, 0.5, true);
        assert_eq!(bidir.tiles.len(), 42);
        assert!(bidir.tiles[..41].iter().all(|t| t.samples.len() == 8));
    }

    /// A time budget collects for an update only with at least as many iterations after it as
    /// before (`emis::update_pays`), as `render_emis` does: after 4 of about 22 iterations the
    /// update at 16 is skipped, after 4 of 40 it is not, under path tracing and a
    /// bidirectional strategy alike.
    #[test]
    fn plan_a_short_timed_render_skips_a_late_update() {
        let s = spec(IntegratorName::EmisVcm, None, Some(20.0));
        let short = pass_after_update(&s, 4, 0, 3.6, 0.0, true);
        assert!(!short.collect);
        assert!(short.tiles.iter().all(|t| t.samples.start >= 4));
        let long = pass_after_update(&s, 4, 0, 2.0, 0.0, true);
        assert!(long.collect);
        assert!(long.tiles.last().unwrap().samples.end <= 16);
        assert!(!pass_after_update(&s, 4, 0, 3.6, 0.5, true).collect);
        assert!(pass_after_update(&s, 4, 0, 2.0, 0.5, true).collect);
    }

    /// A time budget plans a pass by the dearer of the average pace and the last pass's: after
    /// a restart from path tracing (4 pt iterations in 1 s), one VCM iteration measures the new
    /// pace first, and the 2 s it took, not the 0.6 s average, plans the pass after it. By the
    /// average the job would collect for the update at 16, which it cannot reach.
    #[test]
    fn plan_a_timed_pass_by_the_dearer_of_the_average_and_the_last_pace() {
        let s = spec(IntegratorName::EmisVcm, None, Some(20.0));
        let first = pass_after_update(&s, 4, 4, 1.0, 1.0, true);
        assert_eq!(first.tiles.iter().map(|t| t.samples.clone()).collect::<Vec<_>>(), [4..5]);
        let next = |clock: Clock| match after_pass(&s, 5, 4, clock, first.collect, 1.0) {
            BarrierAction::NextPass(p) => (p.tiles.iter().map(|t| t.samples.clone()).collect::<Vec<_>>(), p.collect),
            other => panic!("{other:?}"),
        };
        assert_eq!(next(Clock { elapsed_s: 3.0, last_pass_s: 2.0 }), (vec![5..6], false));
        assert_eq!(next(Clock::from(3.0)), (vec![5..8], true));
        assert_eq!(expected_total(&s, 5, 4, Clock { elapsed_s: 3.0, last_pass_s: 2.0 }), 13);
        assert_eq!(expected_total(&s, 5, 4, 3.0), 33);
        // a last pass cheaper than the average does not shorten the estimate
        assert_eq!(expected_total(&s, 5, 4, Clock { elapsed_s: 3.0, last_pass_s: 0.1 }), 33);
        // a sample budget ignores the clock
        let n = spec(IntegratorName::EmisVcm, Some(40), None);
        assert_eq!(pass_after_update(&n, 4, 4, Clock { elapsed_s: 3.0, last_pass_s: 2.0 }, 1.0, true).tiles.len(), 2);
    }

    /// A path-tracing start discarded at the update after iteration 1: the sample budget
    /// counts the 12 iterations the film keeps, 1..13, and the update schedule stays on the
    /// iteration count (the next update after 4).
    #[test]
    fn plan_after_a_restart_renders_the_whole_budget_into_the_new_film() {
        let s = spec(IntegratorName::EmisVcm, Some(12), None);
        let second = pass_after_update(&s, 1, 1, 1.0, 0.0, true);
        let ranges: Vec<_> = second.tiles.iter().map(|t| t.samples.clone()).collect();
        assert_eq!((ranges, second.collect), (vec![1..2, 2..3, 3..4], true));
        assert_eq!(after_pass(&s, 4, 1, 1.0, true, 0.0), BarrierAction::Optimize);
        let third = pass_after_update(&s, 4, 1, 1.0, 0.0, true);
        assert_eq!(third.tiles.iter().map(|t| t.samples.clone()).collect::<Vec<_>>(), [4..12, 12..13]);
        assert!(matches!(after_pass(&s, 12, 1, 1.0, false, 0.0), BarrierAction::NextPass(_)));
        assert_eq!(after_pass(&s, 13, 1, 1.0, false, 0.0), BarrierAction::Finish);
        // a time budget is wall time, whatever was discarded
        let t = spec(IntegratorName::EmisVcm, None, Some(10.0));
        assert_eq!(after_pass(&t, 40, 1, 10.5, false, 0.0), BarrierAction::Finish);
    }
}
