//! How an `emis-*` render's iterations are cut into calls (farm tiles) and which of them
//! record moments: pure functions of iteration numbers, the strategy's ν and the budget, which
//! the job driver (`crate::driver`) cuts passes with.

use std::ops::Range;

/// Iterations one [`render_iterations`](super::render_iterations) call (one farm tile)
/// renders once moments are no longer collected, with a bidirectional strategy, and the fewest
/// [`final_call`] gives path tracing. Why eight: a call is a barrier at which the threads wait for each other; eight
/// make that wait small while a farm still gets one tile per worker out of a pass of a few
/// dozen iterations (docs/decisions/0004-calls-and-recording-of-an-emis-render.md).
pub const FINAL_ITERATIONS_PER_CALL: u32 = 8;

/// The most iterations [`final_call`] gives path tracing in one call.
pub const FINAL_PT_ITERATIONS_MAX: u32 = 64;

/// The camera samples (pixels × iterations) above which [`final_call`] stops growing a path
/// tracing call: about a second of work on two threads, so that progress still moves.
const FINAL_PT_SAMPLES: u64 = 1 << 23;

/// The first call (farm tile) of a pass over the non-empty `iterations` that collects no
/// moments, for a strategy with `nu` light paths per pixel on an image of `pixels`.
/// - A bidirectional strategy: [`FINAL_ITERATIONS_PER_CALL`] iterations.
/// - Path tracing: a sixteenth of the iterations left, between [`FINAL_ITERATIONS_PER_CALL`]
///   and [`FINAL_PT_ITERATIONS_MAX`] (and [`FINAL_PT_SAMPLES`]). `pt` renders a pixel's
///   iterations of a call one after the other, and more of them in a row run faster;
///   shrinking calls keep sixteen farm tiles in every remaining stretch and a short tail
///   (docs/decisions/0004-calls-and-recording-of-an-emis-render.md).
///
/// Like [`collecting_call`], it depends on iteration numbers, the strategy and the image
/// only, so a farm cutting a pass and a local render cutting what is left add the same calls.
pub fn final_call(iterations: Range<u32>, nu: f32, pixels: u64) -> Range<u32> {
    let len = iterations.end - iterations.start;
    let count = if nu > 0.0 {
        FINAL_ITERATIONS_PER_CALL
    } else {
        let by_samples = (FINAL_PT_SAMPLES / pixels.max(1)).min(u32::MAX as u64) as u32;
        (len / 16).min(by_samples).clamp(FINAL_ITERATIONS_PER_CALL, FINAL_PT_ITERATIONS_MAX)
    };
    iterations.start..iterations.end.min(iterations.start + count)
}

/// The pixel-accumulators (pixels × calls) a group of [`traced_together`] may hold at once:
/// each call of a group keeps its own full-frame sums until the group ends, about 36 bytes a
/// pixel, so some 150 MB.
const TRACED_TOGETHER_PIXELS: u64 = 1 << 22;

/// How many of the first path-tracing `calls` (consecutive, as the job driver cut them) a local
/// render traces together, a pixel's iterations of all of them in a row: at least one call,
/// then as many as fit in `target` iterations and [`TRACED_TOGETHER_PIXELS`]. Short calls
/// traced alone give a pixel few samples in a row, which runs slower than `pt`'s passes
/// (docs/decisions/0004-calls-and-recording-of-an-emis-render.md); grouping them keeps the cut,
/// so a farm's tiles still sum the same numbers.
pub fn traced_together(calls: &[Range<u32>], pixels: u64, target: u32) -> usize {
    let most = (TRACED_TOGETHER_PIXELS / pixels.max(1)).max(1) as usize;
    let Some(start) = calls.first().map(|c| c.start) else { return 0 };
    let fits = calls.iter().take(most).take_while(|c| c.end - start <= target).count();
    fits.max(1)
}

/// Whether a collecting call over `iterations` records moments when the current strategy
/// has `nu` light paths per pixel. While path tracing is the strategy, only iteration 0 (the
/// pilot of a path-tracing start), a quarter of the iterations before [`SPARSE_FROM`] (those
/// ≡ 2 mod 4) and an eighth after it (≡ 6 mod 8) do: recording a pt iteration's moments needs
/// the bidirectional integrator's densities of every technique plus the estimator, which
/// costs more than the pt iteration itself and on a scene where pt stays best is pure
/// overhead (docs/decisions/0004-calls-and-recording-of-an-emis-render.md). The updates at
/// 4, 16 and 64 get 1, 4 and 10 iterations of moments on top of the pilot's. With a
/// bidirectional strategy the estimator adds a smaller share and every iteration records.
pub fn collects_moments(nu: f32, iterations: &Range<u32>) -> bool {
    nu > 0.0 || iterations.clone().any(records_under_path_tracing)
}

/// The iteration from which path tracing records an eighth of its iterations, not a quarter:
/// the update there has seen five recordings, and the decision they give rarely moves.
pub const SPARSE_FROM: u32 = 16;

fn records_under_path_tracing(iteration: u32) -> bool {
    iteration == 0 || if iteration < SPARSE_FROM { iteration % 4 == 2 } else { iteration % 8 == 6 }
}

/// The first call (farm tile) of a collecting pass over the non-empty `iterations` when the
/// current strategy has `nu` light paths per pixel.
/// - A bidirectional strategy records every iteration: calls of up to
///   [`FINAL_ITERATIONS_PER_CALL`] iterations, so that a worker sums that many iterations'
///   moments into one upload (docs/decisions/0019-compact-pilot-data.md).
/// - Under path tracing, one iteration if it records moments ([`collects_moments`]), else the
///   run of iterations up to the next one that does (at most [`FINAL_ITERATIONS_PER_CALL`]):
///   such a run is rendered by `pt` in one call, not one call per iteration, each a barrier
///   for the threads (docs/decisions/0004-calls-and-recording-of-an-emis-render.md).
///
/// The cut depends on iteration numbers and the strategy only, which a farm knows when it
/// plans a pass, so local and farm renders add the same calls.
pub fn collecting_call(iterations: Range<u32>, nu: f32) -> Range<u32> {
    let start = iterations.start;
    let end = if nu > 0.0 {
        iterations.end
    } else if records_under_path_tracing(start) {
        start + 1
    } else {
        (start + 1..iterations.end).find(|&i| records_under_path_tracing(i)).unwrap_or(iterations.end)
    };
    start..end.min(start + FINAL_ITERATIONS_PER_CALL)
}

/// The calls a pass over `iterations` is cut into: `first` gives the first call of what is
/// left (e.g. `|r| final_call(r, nu, pixels)`), until nothing is.
pub fn calls(iterations: Range<u32>, first: impl Fn(Range<u32>) -> Range<u32>) -> Vec<Range<u32>> {
    let mut out = Vec::new();
    let mut begin = iterations.start;
    while begin < iterations.end {
        let call = first(begin..iterations.end);
        assert!(call.start == begin && call.end > begin, "invariant: a call starts what is left");
        begin = call.end;
        out.push(call);
    }
    out
}

/// How many iterations a render would run in all if an update restarted it from a
/// path-tracing start.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RestartTotal {
    /// A sample budget: exactly this many (the budget's N after those so far).
    Samples(u32),
    /// A time budget: this many at the pace so far (`u32::MAX` while unknown); a dearer
    /// strategy after the restart runs fewer.
    Time(u32),
}

impl RestartTotal {
    /// The iterations at the pace so far.
    pub fn at_current_pace(self) -> u32 {
        match self {
            RestartTotal::Samples(n) | RestartTotal::Time(n) => n,
        }
    }

    /// The iterations a strategy `dearer` times as costly per iteration as the current one
    /// would reach after `done`.
    pub fn at_cost_ratio(self, done: u32, dearer: f64) -> f64 {
        match self {
            RestartTotal::Samples(n) => n as f64,
            RestartTotal::Time(n) => done as f64 + n.saturating_sub(done) as f64 / dearer.max(1e-9),
        }
    }

    /// Whether the update after `update` iterations would pay ([`update_pays`]) in a render of
    /// `total` iterations (of [`RestartTotal::at_cost_ratio`], say) under this budget: the
    /// rule the render loop and a farm's plan apply when they decide to collect for it.
    pub fn pays(self, update: u32, total: f64) -> bool {
        // only whole iterations run
        let whole = total.clamp(0.0, u32::MAX as f64) as u32;
        update_pays(update, whole, matches!(self, RestartTotal::Time(_)))
    }
}

/// Whether moments are worth collecting for the update after `update` iterations of a render
/// expected to run `total` (`timed`: under a time budget), whatever the current strategy.
/// - Only an update that iterations follow can change anything.
/// - Under a time budget, an update also needs at least as many iterations after it as before
///   it. Its recordings cost time the iterations after it must win back: under path tracing a
///   recording costs more than the pt iteration it replaces, and a late switch has a short
///   rest to gain on (docs/decisions/0035-updates-a-short-render-skips.md); a bidirectional
///   strategy records every iteration at up to a third more, and an update that governs only
///   a short tail cannot repay it (docs/decisions/0035-updates-a-short-render-skips.md).
/// - A sample budget collects for any update before its end: a restart renders all the
///   budget's iterations after the update, which then governs at least as many as precede it.
pub fn update_pays(update: u32, total: u32, timed: bool) -> bool {
    update < total && (!timed || update.saturating_mul(2) <= total)
}

/// The seconds a timed render expects its next iteration to take, after `done` iterations in
/// `elapsed` seconds whose last call took `last_call` seconds per iteration: the dearer of the
/// two. After a path-tracing start restarts into a bidirectional strategy the average holds
/// cheap pt iterations, and calls planned by it overran the budget
/// (docs/decisions/0038-time-budget-after-a-restart.md).
pub fn seconds_per_iteration(elapsed: f64, done: u32, last_call: f64) -> f64 {
    (elapsed / done.max(1) as f64).max(last_call)
}

/// The iterations a time budget of `budget` seconds allows in all, after `done` in `elapsed`
/// seconds, at `pace` seconds per iteration from now on ([`seconds_per_iteration`]).
pub fn iterations_at_pace(budget: f64, elapsed: f64, done: u32, pace: f64) -> u32 {
    let left = (budget - elapsed).max(0.0) / pace;
    done.saturating_add(left.min(u32::MAX as f64) as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn path_tracing_calls_take_a_sixteenth_of_what_is_left_within_limits() {
        let small = 256 * 256;
        assert_eq!(final_call(64..400, 0.0, small), 64..85);
        assert_eq!(final_call(64..4000, 0.0, small), 64..128);
        assert_eq!(final_call(64..100, 0.0, small), 64..72);
        assert_eq!(final_call(64..67, 0.0, small), 64..67);
        // the sample cap: 2²³ / (640 × 480) = 27; 1080p gets the fewest
        assert_eq!(final_call(0..4000, 0.0, 640 * 480), 0..27);
        assert_eq!(final_call(0..4000, 0.0, 1920 * 1080), 0..8);
        // a bidirectional strategy keeps eight
        assert_eq!(final_call(64..4000, 0.5, small), 64..72);
        for (range, nu) in [(64..400, 0.0), (7..2000, 0.0), (0..1, 0.0), (64..400, 1.0)] {
            let calls = calls(range.clone(), |r| final_call(r, nu, small));
            assert_eq!((calls[0].start, calls.last().unwrap().end), (range.start, range.end));
            assert!(calls.windows(2).all(|w| w[0].end == w[1].start && w[0].len() >= w[1].len()), "{calls:?}");
            assert!(calls.iter().all(|c| c.len() <= FINAL_PT_ITERATIONS_MAX as usize));
            // sixteen or more farm tiles in every pass long enough for them
            assert!(calls.len() >= 16.min(range.len().div_ceil(8)), "{calls:?}");
        }
    }

    #[test]
    fn calls_traced_together_are_the_cut_s_first_calls_within_the_target() {
        let small = 256 * 256;
        let cut = calls(4..1200, |r| final_call(r, 0.0, small));
        let n = traced_together(&cut, small, 200);
        assert!(n >= 2 && cut[n - 1].end - 4 <= 200, "{:?}", &cut[..n]);
        assert!(cut[n].end - 4 > 200, "as many as fit: {:?}", &cut[..n]);
        // one call even when it alone passes the target; the memory bound at 1080p
        assert_eq!(traced_together(&cut, small, 3), 1);
        let hd = calls(0..4000, |r| final_call(r, 0.0, 1920 * 1080));
        assert_eq!(&hd[..traced_together(&hd, 1920 * 1080, 400)], [0..8, 8..16]);
        assert_eq!(traced_together(&[10..12], small, 100), 1);
        assert_eq!(traced_together(&[], small, 100), 0);
    }

    #[test]
    fn collecting_calls_under_path_tracing_end_at_each_recording() {
        let cut = calls(0..24, |r| collecting_call(r, 0.0));
        assert_eq!(cut, [0..1, 1..2, 2..3, 3..6, 6..7, 7..10, 10..11, 11..14, 14..15, 15..22, 22..23, 23..24]);
        assert_eq!(calls(3..20, |r| collecting_call(r, 1.0)), [3..11, 11..19, 19..20]);
    }

    #[test]
    fn a_dearer_last_call_sets_the_pace() {
        // one pt iteration of 0.5 s, then three bidirectional ones of 3 s each
        assert_eq!(seconds_per_iteration(9.5, 4, 3.0), 3.0);
        // a cheap last call does not undo the pilot's and updates' share of the average
        assert_eq!(seconds_per_iteration(10.0, 4, 1.0), 2.5);
        assert_eq!(seconds_per_iteration(0.0, 0, 0.0), 0.0);
    }

    #[test]
    fn a_time_budget_allows_what_is_left_at_the_pace() {
        assert_eq!(iterations_at_pace(20.0, 8.0, 4, 2.0), 10);
        assert_eq!(iterations_at_pace(20.0, 21.0, 4, 2.0), 4);
        assert_eq!(iterations_at_pace(20.0, 8.0, 4, 1e-30), u32::MAX);
    }

    #[test]
    fn a_short_timed_render_skips_an_update_in_its_second_half() {
        // 23 iterations in 20 s (living-room on a slow host): 16 is too late, 4 is not
        assert!(update_pays(4, 23, true) && !update_pays(16, 23, true));
        assert!(update_pays(16, 32, true) && !update_pays(64, 127, true));
        // a sample budget collects for any update before the end; a timed bidirectional
        // strategy needs the same rest as path tracing (kitchen at 20 s: 4 of about 6)
        assert!(update_pays(16, 17, false));
        assert!(!update_pays(4, 6, true) && update_pays(4, 8, true));
        assert!(!update_pays(16, 16, true) && !update_pays(16, 16, false));
    }
}
