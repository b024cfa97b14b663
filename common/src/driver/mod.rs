//! One job's life as a pure, synchronous state machine: its passes of tiles, the barrier at
//! the end of each pass, time-budget pacing, the EMIS updates it asks for and the restart into
//! the final pass. `tessera render` runs it on a rayon pool (`crate::render`,
//! `crate::emis::render_emis`); the farm's coordinator wraps one per job with leases, epochs
//! and persistence. Both add the same tile sums in the same order because both run this code,
//! which is why a farm render equals a local one bit for bit.
//!
//! Its life: [`Driver::new`] plans the first pass. Its owner renders the pass's tiles and merges
//! them into the film in order; when the last is merged it calls [`Driver::barrier`], which
//! plans the next pass ([`Step::Render`]), asks for an EMIS update ([`Step::Update`], answered
//! by [`Driver::updated`]) or ends the job ([`Step::Finish`]). It takes the time as an argument
//! (`now_ms`, milliseconds on any monotonic origin) and reads no clock.

mod plan;
#[cfg(test)]
mod tests;

pub use plan::{Clock, MAX_TIMED_PASS, expected_total};
use plan::{PassPlan, next_count, plan_from};

use crate::emis::RestartTotal;
use crate::film::Rect;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::time::Duration;

/// How much to render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    /// Exactly this many samples (iterations) per pixel.
    Samples(u32),
    /// Passes until this much wall time is used (at least one sample per pixel).
    Time(Duration),
}

/// What a job renders, as far as cutting it into passes goes.
#[derive(Clone, Debug, PartialEq)]
pub struct Shape {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples or time.
    pub budget: Budget,
    /// Edge of the square tiles of an image-tile integrator; `None`: full-frame tiles.
    pub tile: Option<u32>,
    /// EMIS: when updates may run, and the strategy the job starts with.
    pub emis: Option<EmisSchedule>,
}

/// An EMIS job's updates.
#[derive(Clone, Debug, PartialEq)]
pub struct EmisSchedule {
    /// The iteration counts after which an update may run, ascending.
    pub updates: Vec<u32>,
    /// Light paths per pixel of the strategy the job starts with.
    pub initial_nu: f32,
}

/// What a tile renders: pixels × iterations.
#[derive(Clone, Debug, PartialEq)]
pub struct TileSpec {
    /// Pixels.
    pub rect: Rect,
    /// Sample (iteration) indices.
    pub samples: Range<u32>,
}

impl TileSpec {
    /// Pixel samples the tile contributes.
    pub fn pixel_samples(&self) -> u64 {
        self.rect.area() as u64 * self.samples.len() as u64
    }
}

/// The kind of a pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PassKind {
    /// EMIS pilot: fixed strategy, moments on.
    Pilot,
    /// The chosen strategy.
    Final,
}

/// A planned pass: a contiguous range of tile indices that ends at a barrier.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pass {
    /// Pilot or final.
    pub kind: PassKind,
    /// Its tiles, numbered across the job's passes in merge order.
    pub tiles: Range<usize>,
    /// EMIS: its tiles collect moments for an update at its end.
    pub collect: bool,
    /// EMIS: the film was cleared before this pass (a path-tracing start ended), so the image
    /// keeps only the iterations from here on.
    pub restart: bool,
    /// EMIS: light paths per pixel of the strategy its tiles render (the cut depends on it).
    pub nu: f32,
    /// When it was planned at the barrier before it (`None` for a job's first pass): a time
    /// budget plans the next pass by this pass's pace too.
    pub planned_ms: Option<f64>,
    /// The iterations its tiles cover (derived from the tiles, so not stored).
    #[serde(skip)]
    iterations: Range<u32>,
}

impl Pass {
    /// The iterations its tiles cover.
    pub fn iterations(&self) -> Range<u32> {
        self.iterations.clone()
    }
}

/// What the owner does after a barrier.
#[derive(Clone, Debug, PartialEq)]
pub enum Step {
    /// Render these tiles (a new pass), merged in this order.
    Render(Vec<TileSpec>),
    /// EMIS: run an update on the merged film and moments, then call [`Driver::updated`]; the
    /// argument is how many iterations the job would run in all if the update restarted it.
    Update(RestartTotal),
    /// Nothing left: the job is done.
    Finish,
}

/// One job's passes and pacing (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct Driver {
    shape: Shape,
    passes: Vec<Pass>,
    started_ms: Option<f64>,
}

impl Driver {
    /// A job of `shape` and its first pass (the pilot for EMIS). A time budget starts with
    /// one iteration, which measures the speed.
    pub fn new(shape: Shape) -> (Driver, Vec<TileSpec>) {
        let nu = shape.emis.as_ref().map_or(0.0, |e| e.initial_nu);
        let count = match shape.budget {
            Budget::Samples(n) => n,
            Budget::Time(_) => 1,
        };
        let total = expected_total(&shape, 0, 0, Clock::default());
        let plan = plan_from(&shape, 0, count, true, total, nu);
        let kind = if shape.emis.is_some() { PassKind::Pilot } else { PassKind::Final };
        let mut driver = Driver { shape, passes: Vec::new(), started_ms: None };
        let tiles = driver.append(kind, plan, false, nu, None);
        (driver, tiles)
    }

    /// A driver rebuilt from stored passes over `tiles` stored tiles, whose iterations
    /// `samples(i)` gives. Refused unless the passes tile the tiles without gaps.
    pub fn restore(
        shape: Shape,
        mut passes: Vec<Pass>,
        started_ms: Option<f64>,
        tiles: usize,
        samples: impl Fn(usize) -> Range<u32>,
    ) -> Result<Driver, String> {
        let mut end = 0;
        for p in &mut passes {
            if p.tiles.start != end || p.tiles.is_empty() {
                return Err(format!("pass of tiles {:?} does not follow tile {end}", p.tiles));
            }
            end = p.tiles.end;
            let (begin, last) =
                p.tiles.clone().map(&samples).fold((u32::MAX, 0), |(b, e), s| (b.min(s.start), e.max(s.end)));
            p.iterations = begin..last;
        }
        if end != tiles {
            return Err(format!("the passes hold {end} tiles, the job {tiles}"));
        }
        Ok(Driver { shape, passes, started_ms })
    }

    /// Starts the clock a time budget counts from, at the first work handed out.
    pub fn start(&mut self, now_ms: f64) {
        self.started_ms.get_or_insert(now_ms);
    }

    /// Moves the clock on by `by_ms` that did not count (the job was paused): a time budget
    /// and the last pass's pace count rendering time only.
    pub fn postpone(&mut self, by_ms: f64) {
        if let Some(t) = &mut self.started_ms {
            *t += by_ms;
        }
        if let Some(t) = self.passes.last_mut().and_then(|p| p.planned_ms.as_mut()) {
            *t += by_ms;
        }
    }

    /// When the clock started.
    pub fn started_ms(&self) -> Option<f64> {
        self.started_ms
    }

    /// The job's shape.
    pub fn shape(&self) -> &Shape {
        &self.shape
    }

    /// The passes planned so far.
    pub fn passes(&self) -> &[Pass] {
        &self.passes
    }

    /// The tiles planned so far.
    pub fn tiles(&self) -> usize {
        self.passes.last().map_or(0, |p| p.tiles.end)
    }

    /// The pass `tile` belongs to.
    pub fn pass_of(&self, tile: usize) -> Option<&Pass> {
        let i = self.passes.partition_point(|p| p.tiles.end <= tile);
        self.passes.get(i).filter(|p| p.tiles.contains(&tile))
    }

    /// Whether `tile` collects EMIS moments.
    pub fn collects(&self, tile: usize) -> bool {
        self.pass_of(tile).is_some_and(|p| p.collect)
    }

    /// EMIS: light paths per pixel of the current strategy (the last pass's).
    pub fn nu(&self) -> f32 {
        self.passes.last().map_or(0.0, |p| p.nu)
    }

    /// Iterations planned so far (all done at a barrier).
    pub fn planned(&self) -> u32 {
        self.passes.last().map_or(0, |p| p.iterations.end)
    }

    /// The first iteration the film keeps: where the last restarting pass begins (0 if none).
    pub fn kept_from(&self) -> u32 {
        self.passes.iter().rev().find(|p| p.restart).map_or(0, |p| p.iterations.start)
    }

    /// The iterations the budget allows in all, after `done` at `now_ms`, at the average pace
    /// so far (`u32::MAX` while unknown): for progress and estimates.
    pub fn expected_total(&self, done: u32, now_ms: f64) -> u32 {
        let clock = Clock { elapsed_s: self.elapsed_s(now_ms), last_pass_s: 0.0 };
        expected_total(&self.shape, done, self.kept_from(), clock)
    }

    /// The iterations the job would run in all if an update at this barrier restarted it: a
    /// sample budget's N after those done, else what the budget expects.
    pub fn restart_total(&self, now_ms: f64) -> RestartTotal {
        let done = self.planned();
        match self.shape.budget {
            Budget::Samples(n) => RestartTotal::Samples(done.saturating_add(n)),
            Budget::Time(_) => {
                RestartTotal::Time(expected_total(&self.shape, done, self.kept_from(), self.clock(now_ms)))
            }
        }
    }

    /// Whether [`Driver::barrier`] at `now_ms` would finish the job (without planning).
    pub fn finishes(&self, now_ms: f64) -> bool {
        matches!(self.decide(now_ms), Decision::Finish)
    }

    /// The barrier at the end of a pass, once every planned tile is merged: plans the next
    /// pass, asks for an EMIS update, or finishes. An update is due when the pass collected up
    /// to an update point and iterations remain to use it.
    pub fn barrier(&mut self, now_ms: f64) -> Step {
        match self.decide(now_ms) {
            Decision::Update => Step::Update(self.restart_total(now_ms)),
            Decision::Finish => Step::Finish,
            Decision::Next { count, total } => {
                let (done, nu, collected) = (self.planned(), self.nu(), self.passes.last().is_some_and(|p| p.collect));
                let plan = plan_from(&self.shape, done, count, collected, total, nu);
                Step::Render(self.append(PassKind::Final, plan, false, nu, Some(now_ms)))
            }
        }
    }

    /// The pass after an EMIS update that chose a strategy with `nu` light paths per pixel.
    /// `restarted`: the update ended a path-tracing start and the owner cleared the film, so a
    /// sample budget counts from here on. `collect`: the EMIS state still collects moments (a
    /// path-tracing start that settled collects no more). Under a time budget the pass is one
    /// iteration, which measures the new strategy's pace before a longer pass is planned by it.
    pub fn updated(&mut self, restarted: bool, nu: f32, collect: bool, now_ms: f64) -> Vec<TileSpec> {
        let done = self.planned();
        let kept_from = if restarted { done } else { self.kept_from() };
        let clock = self.clock(now_ms);
        let total = expected_total(&self.shape, done, kept_from, clock);
        let count = match self.shape.budget {
            Budget::Time(_) => 1,
            Budget::Samples(_) => next_count(&self.shape, done, kept_from, clock).max(1),
        };
        let plan = plan_from(&self.shape, done, count, collect, total, nu);
        self.append(PassKind::Final, plan, restarted, nu, Some(now_ms))
    }

    fn decide(&self, now_ms: f64) -> Decision {
        let (done, kept_from, clock) = (self.planned(), self.kept_from(), self.clock(now_ms));
        let total = expected_total(&self.shape, done, kept_from, clock);
        let collected = self.passes.last().is_some_and(|p| p.collect);
        let at_update = self.shape.emis.as_ref().is_some_and(|e| e.updates.contains(&done));
        if collected && at_update && done < total {
            return Decision::Update;
        }
        match next_count(&self.shape, done, kept_from, clock) {
            0 => Decision::Finish,
            count => Decision::Next { count, total },
        }
    }

    fn elapsed_s(&self, now_ms: f64) -> f64 {
        (now_ms - self.started_ms.unwrap_or(now_ms)).max(0.0) / 1000.0
    }

    /// How long the job has rendered at `now_ms`, and the pace of its last pass if that pass
    /// was planned at a barrier (called at a barrier, when it is merged).
    fn clock(&self, now_ms: f64) -> Clock {
        let last_pass_s = self
            .passes
            .last()
            .and_then(|p| Some((now_ms - p.planned_ms?).max(0.0) / 1000.0 / p.iterations.len().max(1) as f64))
            .unwrap_or(0.0);
        Clock { elapsed_s: self.elapsed_s(now_ms), last_pass_s }
    }

    fn append(&mut self, kind: PassKind, plan: PassPlan, restart: bool, nu: f32, now_ms: Option<f64>) -> Vec<TileSpec> {
        let start = self.tiles();
        let begin = plan.tiles.iter().map(|t| t.samples.start).min().unwrap_or(self.planned());
        let end = plan.tiles.iter().map(|t| t.samples.end).max().unwrap_or(begin);
        self.passes.push(Pass {
            kind,
            tiles: start..start + plan.tiles.len(),
            collect: plan.collect,
            restart,
            nu,
            planned_ms: now_ms,
            iterations: begin..end,
        });
        plan.tiles
    }
}

enum Decision {
    Update,
    Next { count: u32, total: u32 },
    Finish,
}
