//! How a job is cut into passes of tiles: pure functions of the job's [`Shape`], the
//! iterations done and the clock, which [`Driver`](super::Driver) applies at its barriers.
//!
//! The cut is what makes a farm render bit-identical to `tessera render`: both run the same
//! driver, so both add the same tile sums to a zeroed film in the same order.
//! * Image-tile integrators (pt): rectangles × the whole sample range of a pass. A pixel's sum
//!   is accumulated sample by sample inside one tile and added once, so the tile size changes
//!   no bit.
//! * Full-frame integrators (lt, bdpt, vcm): the full frame × one iteration per tile.
//! * emis-*: the full frame × `emis::collecting_call`'s calls while collecting moments,
//!   `emis::final_call`'s after.

use super::{Budget, Shape, TileSpec};
use crate::emis::{calls, collecting_call, final_call, iterations_at_pace, seconds_per_iteration, update_pays};
use crate::film::Rect;
use crate::settings::MAX_SPP;

/// The most iterations one pass of a time budget plans. Passes are planned one at a time at
/// barriers, so this only caps what one planning allocates: a 10⁸ s budget at a fast pace
/// asked for a tenth of it, about 10⁹ full-frame tiles, in one pass.
pub const MAX_TIMED_PASS: u32 = 1024;

/// How long a job has rendered, which is what a time budget plans by.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Clock {
    /// Seconds since the job started.
    pub elapsed_s: f64,
    /// Seconds per iteration of the pass that just ended, from its planning to its barrier;
    /// 0 while unknown.
    pub last_pass_s: f64,
}

impl Clock {
    /// The seconds the next iteration is expected to take after `done`: the dearer of the
    /// average and the last pass's. After an EMIS restart from path tracing the average still
    /// holds cheap pt iterations, and a pass planned by it overruns the budget
    /// (docs/decisions/0038-time-budget-after-a-restart.md).
    fn pace(&self, done: u32) -> f64 {
        seconds_per_iteration(self.elapsed_s, done, self.last_pass_s).max(1e-9)
    }
}

/// Iterations the budget allows in total, as far as is known after `done` at `clock` (a time
/// budget's is unknown before the first iteration). A sample budget counts the iterations the
/// film keeps, from `kept_from` on (EMIS: a path-tracing start's iterations are discarded when
/// a bidirectional strategy wins).
pub fn expected_total(shape: &Shape, done: u32, kept_from: u32, clock: Clock) -> u32 {
    match shape.budget {
        Budget::Samples(n) => kept_from.saturating_add(n),
        Budget::Time(budget) if done > 0 && clock.elapsed_s > 0.0 => {
            iterations_at_pace(budget.as_secs_f64(), clock.elapsed_s, done, clock.pace(done))
        }
        Budget::Time(_) => u32::MAX,
    }
}

/// Iterations the next pass may render: the rest of a sample budget, or for a time budget
/// about a tenth of it, never planned past the deadline. 0: finished.
pub(super) fn next_count(shape: &Shape, done: u32, kept_from: u32, clock: Clock) -> u32 {
    match shape.budget {
        Budget::Samples(n) => kept_from.saturating_add(n).saturating_sub(done),
        Budget::Time(budget) => {
            let budget = budget.as_secs_f64();
            let remaining = budget - clock.elapsed_s;
            if remaining <= 0.0 || done == 0 {
                return 0;
            }
            let pace = clock.pace(done);
            // float-to-int casts saturate; the iteration count ends at MAX_SPP
            let fit = (remaining / pace).floor() as u32;
            fit.min(((budget * 0.1 / pace) as u32).max(1)).min(MAX_TIMED_PASS).min(MAX_SPP.saturating_sub(done))
        }
    }
}

/// A planned pass: its tiles in merge order, and whether they collect EMIS moments.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct PassPlan {
    pub(super) tiles: Vec<TileSpec>,
    pub(super) collect: bool,
}

/// A pass from `done` of at most `count` iterations. EMIS collects moments while another
/// update can come within the budget and pay (`emis::update_pays`; `may_collect`: no earlier
/// pass stopped collecting), and then ends the pass at that update, where the barrier runs
/// it; `nu` is the current strategy's light paths per pixel, on which the cut depends.
pub(super) fn plan_from(shape: &Shape, done: u32, count: u32, may_collect: bool, total: u32, nu: f32) -> PassPlan {
    let timed = matches!(shape.budget, Budget::Time(_));
    let end = done.saturating_add(count);
    let full_frame = |samples| TileSpec { rect: Rect::full(shape.width, shape.height), samples };
    let Some(emis) = &shape.emis else { return PassPlan { tiles: pass_tiles(shape, done, end), collect: false } };
    let update = emis.updates.iter().copied().find(|&u| u > done);
    let update = update.filter(|&u| may_collect && update_pays(u, total, timed));
    let end = update.map_or(end, |u| u.min(end));
    let tiles: Vec<TileSpec> = if update.is_some() {
        calls(done..end, |r| collecting_call(r, nu)).into_iter().map(full_frame).collect()
    } else {
        let pixels = shape.width as u64 * shape.height as u64;
        calls(done..end, |r| final_call(r, nu, pixels)).into_iter().map(full_frame).collect()
    };
    PassPlan { tiles, collect: update.is_some() }
}

/// Tiles rendering iterations `begin..end` of every pixel: rectangles × the whole range, or
/// full-frame tiles of one iteration each.
fn pass_tiles(shape: &Shape, begin: u32, end: u32) -> Vec<TileSpec> {
    match shape.tile {
        Some(edge) => Rect::tiles(shape.width, shape.height, edge)
            .into_iter()
            .map(|rect| TileSpec { rect, samples: begin..end })
            .collect(),
        None => {
            (begin..end).map(|i| TileSpec { rect: Rect::full(shape.width, shape.height), samples: i..i + 1 }).collect()
        }
    }
}
