//! The integrators `emis-bdpt` and `emis-vcm`: efficiency-aware MIS (Grittmann et al. 2022;
//! docs/emis.md) on the bidirectional engine.
//!
//! [`PilotStart::Bidirectional`], the paper's pilot, renders with a fixed strategy
//! (docs/emis.md, decision 5: `emis-vcm` VCM with N = P, c = 1, χ = 1 and correlation-aware
//! weights; `emis-bdpt` BDPT with N = P, c = 1) while a [`MomentEstimator`] records every
//! candidate's second moment per pixel. After iterations 1, 4, 16 and 64 (configurable) the
//! optimiser picks ν, c and the per-pixel merge mask χ from the merged moments, the denoised
//! image and the path statistics; rendering continues with that strategy (moments still
//! collected, each sample with the counts it was drawn with; while that strategy is pt, in a
//! quarter and later an eighth of the iterations, see [`collects_moments`]) until the last
//! update the budget can reach, then without moments. Every iteration, pilot included, stays
//! in the image with equal weight. When path tracing wins, the remaining iterations are
//! rendered by `pt` itself (same integral, faster estimator).
//!
//! [`PilotStart::PathTracing`], the default, starts with path tracing instead (the
//! reference's `OnDemandVcm`; docs/emis.md, decision 5 and checklist 13): its updates choose
//! from a reduced set (ν ∈ {0.5, 1}, c ∈ {0, 1}, merging everywhere or nowhere, pt) while pt
//! wins. The first update a bidirectional candidate wins discards the image so far, restarts
//! the moments for the full set and renders a sample budget's iterations in full after it;
//! the updates that follow keep the schedule (their iteration counts include the discarded
//! ones). A candidate wins that update only by more than the share of the render it
//! discards. Its recording iterations carry a light probe (`integrator::LightProbe`): without
//! it the cost model would know neither the light paths' length nor the photons a merge
//! finds, and price merging as free (docs/decisions/0032-light-probe-and-restart-share.md).
//!
//! The pieces are split so that a farm can run them apart: [`render_iterations`] renders a
//! full-frame iteration range with a [`Strategy`] on any worker; [`EmisState`] (in `state`)
//! merges what workers return and runs the update at each barrier. [`render_emis`] is the
//! local loop over both. Farm and local cut the iterations into the same calls
//! ([`collecting_call`] while collecting, [`final_call`] after that), so they
//! sum the same numbers in the same order and their images are bit-identical.

use super::EmisState;
use super::candidate::{Candidate, CandidateConfig};
use super::cost::{CostConstants, StatisticsSums};
use super::denoise::DenoiseSettings;
use super::estimator::{MomentEstimator, MomentSettings};
use super::guides::{GuideBuffer, GuideCollector};
use super::moments::MomentBuffer;
use super::optimize::{ConnectionScope, FilterSettings};
use crate::film::{Film, Rect, TileAccum};
use crate::integrator::path::connections::Connections;
use crate::integrator::path::merge::{MergeConfig, MergeMask};
use crate::integrator::{Bidir, Integrator, PathSettings, PathTracer, Stop, TileRequest};
use crate::render::{Budget, RenderError, RenderOptions, RenderOutput};
use crate::scene::Scene;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::time::Instant;

/// Iterations one [`render_iterations`] call (one farm tile) renders once moments are no
/// longer collected, with a bidirectional strategy, and the fewest [`final_call`] gives path
/// tracing. Why eight: a call is a barrier at which the threads wait for each other; eight
/// make that wait small while a farm still gets one tile per worker out of a pass of a few
/// dozen iterations (docs/decisions/0004-final-iterations-per-call.md).
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
///   (docs/decisions/0034-longer-path-tracing-calls.md).
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

/// Whether a collecting call over `iterations` records moments when the current strategy
/// has `nu` light paths per pixel. While path tracing is the strategy, only iteration 0 (the
/// pilot of a path-tracing start), a quarter of the iterations before [`SPARSE_FROM`] (those
/// ≡ 2 mod 4) and an eighth after it (≡ 6 mod 8) do: recording a pt iteration's moments needs
/// the bidirectional integrator's densities of every technique plus the estimator, which
/// costs more than the pt iteration itself and on a scene where pt stays best is pure
/// overhead (docs/decisions/0005-recording-under-path-tracing.md,
/// 0033-sparser-recording-under-path-tracing.md). The updates at 4, 16 and 64 get 1, 4 and
/// 10 iterations of moments on top of the pilot's. With a bidirectional strategy the
/// estimator adds a smaller share and every iteration records.
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
///   for the threads (docs/decisions/0006-path-tracing-runs-in-one-call.md).
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

/// Side of the square tiles in which path tracing renders the iterations it wins. Why small
/// tiles: a call is a barrier, and at its end one thread may still render a last piece while
/// the other waits; 16² tiles keep that tail as short as `pt`'s own render has it
/// (docs/decisions/0007-pt-tiles-in-emis.md).
const PT_TILE: u32 = 16;

/// Denoiser guides are summed in collecting iterations below this count only: they are a
/// per-pixel average of first-hit albedo and normal, converged long before moments are (the
/// reference computes its denoised image once, at the first update). They come from the
/// pilot's own primary vertices, so the limit saves little time; it keeps the guides of a
/// render independent of how long it runs.
pub const GUIDE_ITERATIONS: u32 = 16;

/// Which bidirectional method the candidates come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EmisMethod {
    /// BDPT candidates (no merging): 26.
    Bdpt,
    /// VCM candidates (merging per pixel): 51.
    Vcm,
}

/// How an `emis-*` render starts (docs/emis.md, decision 5). The default, which
/// `RenderSettings` and so `tessera render` and farm jobs carry, is path tracing first: on the
/// nine bench scenes it beat the method's own pilot on every one
/// (docs/decisions/0033-sparser-recording-and-the-path-tracing-start.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PilotStart {
    /// The method's own pilot: VCM (or BDPT) with N = P, c = 1 (and χ = 1), kept in the image.
    Bidirectional,
    /// Path tracing first (the reference's `OnDemandVcm`, docs/emis.md §1.2 and §4): updates
    /// choose from the reduced set ([`CandidateSet::Reduced`]) while path tracing wins. The
    /// first update a bidirectional candidate wins discards the iterations rendered so far
    /// (the image restarts with the new strategy, and a sample budget counts the kept
    /// iterations only) and switches to the full set for the updates that follow.
    #[default]
    PathTracing,
}

/// Which candidates moments are recorded for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CandidateSet {
    /// The method's full set (docs/emis.md, decision 1): 51 for VCM, 26 for BDPT.
    Full,
    /// The path-tracing start's reduced set (see `CandidateConfig::reduced`), decided with
    /// global merging.
    Reduced,
}

/// Everything `emis-*` can be configured with.
#[derive(Clone, Debug, PartialEq)]
pub struct EmisConfig {
    /// BDPT or VCM.
    pub method: EmisMethod,
    /// The candidate set (docs/emis.md, decision 1).
    pub candidates: CandidateConfig,
    /// Optimise after these many iterations (docs/emis.md, decision 5).
    pub updates: Vec<u32>,
    /// Correlation-aware merge weights (pilot and final).
    pub correlation_aware: bool,
    /// The estimator's switches (docs/emis.md, decision 3).
    pub moments: MomentSettings,
    /// Cost heuristic constants (docs/emis.md, decision 8).
    pub constants: CostConstants,
    /// Measure the constants per job from the pilot's work times, `constants` filling in what
    /// they cannot measure.
    pub measured_costs: bool,
    /// Filter radii (docs/emis.md, decision 6).
    pub filters: FilterSettings,
    /// The denoiser (docs/emis.md, decision 7).
    pub denoise: DenoiseSettings,
    /// The denoiser while a path-tracing start is still path tracing: its image is black on
    /// caustics, which only the guided filter's spreading lets speak (decision 0029).
    pub start_denoise: DenoiseSettings,
    /// The pilot: the method's own, or path tracing first.
    pub pilot: PilotStart,
    /// One c for the image or one per pixel (the reduced set's decisions are image-level).
    pub connection_scope: ConnectionScope,
}

impl EmisConfig {
    /// The update schedule of docs/emis.md, decision 5.
    pub const DEFAULT_UPDATES: [u32; 4] = [1, 4, 16, 64];

    /// The paper's configuration of `method`, with the method's own pilot
    /// ([`PilotStart::Bidirectional`], what the decision tests and benches study); a render's
    /// settings choose the pilot (`RenderSettings::emis_pilot`, [`PilotStart::default`]).
    pub fn new(method: EmisMethod) -> Self {
        EmisConfig {
            method,
            candidates: match method {
                EmisMethod::Bdpt => CandidateConfig::bdpt(),
                EmisMethod::Vcm => CandidateConfig::vcm(),
            },
            updates: Self::DEFAULT_UPDATES.to_vec(),
            correlation_aware: true,
            moments: MomentSettings::default(),
            constants: CostConstants::default(),
            measured_costs: false,
            filters: FilterSettings::default(),
            denoise: DenoiseSettings::default(),
            start_denoise: DenoiseSettings::GUIDED,
            pilot: PilotStart::Bidirectional,
            connection_scope: ConnectionScope::default(),
        }
    }

    /// Whether the updates of `set` read the denoiser's guides: only the guided filter does,
    /// so pilots that feed the default Ī leave them out of their data and uploads.
    pub fn records_guides(&self, set: CandidateSet) -> bool {
        self.denoise_of(set).levels > 0
    }

    /// The denoiser of the updates of `set`: [`EmisConfig::start_denoise`] for the
    /// path-tracing start's reduced set, [`EmisConfig::denoise`] otherwise.
    pub fn denoise_of(&self, set: CandidateSet) -> &DenoiseSettings {
        match set {
            CandidateSet::Reduced => &self.start_denoise,
            CandidateSet::Full => &self.denoise,
        }
    }

    /// The candidates of `set`, in moment-buffer order.
    pub fn candidates_of(&self, set: CandidateSet) -> Vec<Candidate> {
        match set {
            CandidateSet::Full => self.candidates.candidates(),
            CandidateSet::Reduced => self.candidates.reduced().candidates(),
        }
    }

    /// The integrator's name.
    pub fn name(&self) -> &'static str {
        match self.method {
            EmisMethod::Bdpt => "emis-bdpt",
            EmisMethod::Vcm => "emis-vcm",
        }
    }
}

/// The counts one pass renders with.
#[derive(Clone, Debug, PartialEq)]
pub struct Strategy {
    /// Light paths per pixel per iteration (0: path tracing).
    pub nu: f32,
    /// Connections per camera vertex, for the image or per pixel.
    pub connections: Connections,
    /// Per-pixel merge probability (`None`: no merging, BDPT).
    pub merge: Option<MergeMask>,
}

impl Strategy {
    /// Pure path tracing (rendered by the `pt` integrator when no moments are collected).
    pub fn path_tracing() -> Self {
        Strategy { nu: 0.0, connections: Connections::Fixed(0), merge: None }
    }

    /// Path tracing as the start of `method`: rendered by the VCM engine with χ = 0 for
    /// `emis-vcm`, so that collecting iterations carry the merge densities the estimator
    /// needs for the merging candidates.
    pub fn path_tracing_start(method: EmisMethod) -> Self {
        Strategy {
            merge: match method {
                EmisMethod::Bdpt => None,
                EmisMethod::Vcm => Some(MergeMask::Constant(0.0)),
            },
            ..Self::path_tracing()
        }
    }

    /// The strategy a render with `pilot` starts with: [`Strategy::pilot`] or
    /// [`Strategy::path_tracing_start`].
    pub fn initial(method: EmisMethod, pilot: PilotStart) -> Self {
        match pilot {
            PilotStart::Bidirectional => Self::pilot(method),
            PilotStart::PathTracing => Self::path_tracing_start(method),
        }
    }

    /// The pilot strategy of docs/emis.md, decision 5 ([`PilotStart::Bidirectional`]).
    pub fn pilot(method: EmisMethod) -> Self {
        Strategy {
            nu: 1.0,
            connections: Connections::Fixed(1),
            merge: match method {
                EmisMethod::Bdpt => None,
                EmisMethod::Vcm => Some(MergeMask::Constant(1.0)),
            },
        }
    }

    /// The bidirectional integrator rendering with this strategy.
    pub fn integrator(&self, settings: PathSettings, correlation_aware: bool) -> Bidir {
        let bidir = match &self.merge {
            None => Bidir::bdpt(settings, self.nu, 0),
            Some(mask) => Bidir::vcm(settings, self.nu, 0, MergeConfig { mask: mask.clone(), correlation_aware }),
        };
        bidir.with_connections(self.connections.clone())
    }
}

/// What a pilot range returns besides the image: all mergeable by addition.
#[derive(Clone, Debug, PartialEq)]
pub struct PilotData {
    /// Moment sums of every candidate.
    pub moments: MomentBuffer,
    /// Path statistics.
    pub statistics: StatisticsSums,
    /// Denoiser guides.
    pub guides: GuideBuffer,
}

/// Renders the full-frame `iterations` with `strategy`; with `collect`, also the moments of
/// that set's candidates, the statistics and (where [`EmisConfig::records_guides`]) the guides
/// of those iterations, if [`collects_moments`] says so (the pilot data is `Some` exactly
/// then). Deterministic for any thread count.
pub fn render_iterations(
    scene: &Scene,
    settings: PathSettings,
    config: &EmisConfig,
    strategy: &Strategy,
    seed: u64,
    iterations: Range<u32>,
    collect: Option<CandidateSet>,
) -> (TileAccum, Option<PilotData>) {
    render_iterations_until(scene, settings, config, strategy, seed, iterations, collect, &Stop::default())
}

/// [`render_iterations`], given up when `stop` is requested (the result is then incomplete).
#[allow(clippy::too_many_arguments)]
pub fn render_iterations_until(
    scene: &Scene,
    settings: PathSettings,
    config: &EmisConfig,
    strategy: &Strategy,
    seed: u64,
    iterations: Range<u32>,
    collect: Option<CandidateSet>,
    stop: &Stop,
) -> (TileAccum, Option<PilotData>) {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let rect = Rect::full(w, h);
    let mut accum = TileAccum::new(rect, &scene.film);
    let request = TileRequest::new(rect, iterations.clone(), seed).stoppable(stop.clone());
    let collect = collect.filter(|_| collects_moments(strategy.nu, &iterations));
    if collect.is_none() && strategy.nu == 0.0 {
        // path tracing won: render it with `pt` (the same integral, the fastest estimator of
        // it), in small square tiles in parallel, placed in order, so deterministic
        let pt = PathTracer { settings };
        let tiles: Vec<TileAccum> = {
            use rayon::prelude::*;
            Rect::tiles(w, h, PT_TILE)
                .into_par_iter()
                .map(|rect| {
                    let mut tile = TileAccum::new(rect, &scene.film);
                    let request = TileRequest::new(rect, iterations.clone(), seed).stoppable(stop.clone());
                    pt.render_tile(scene, &request, &mut tile);
                    tile
                })
                .collect()
        };
        for tile in &tiles {
            accum.add(tile);
        }
        return (accum, None);
    }
    let integrator = strategy.integrator(settings, config.correlation_aware);
    let Some(set) = collect else {
        integrator.render_tile(scene, &request, &mut accum);
        return (accum, None);
    };
    let candidates = config.candidates_of(set);
    let estimator = MomentEstimator::new(w, h, &candidates, config.moments);
    let guided = if config.records_guides(set) {
        iterations.start.min(GUIDE_ITERATIONS)..iterations.end.min(GUIDE_ITERATIONS)
    } else {
        0..0
    };
    let guides = GuideCollector::new(w, h, guided);
    // under path tracing a light probe measures what the cost model needs of light paths
    integrator.with_probe().with_observer((&estimator, &guides)).render_tile(scene, &request, &mut accum);
    let (mut moments, statistics) = estimator.into_snapshot();
    moments.round_for_wire();
    (accum, Some(PilotData { moments, statistics, guides: guides.into_buffer() }))
}

/// A finished `emis-*` render.
pub struct EmisOutput {
    /// Image, time and iterations.
    pub render: RenderOutput,
    /// Moments, decisions and reports.
    pub state: EmisState,
}

/// Renders `scene` locally with `emis-*` on the caller's pool (`opts.threads`): collecting
/// iterations in the calls of [`collecting_call`], updates at the configured barriers, then
/// the rest in the calls of [`final_call`]. `progress(done, total)` counts
/// pixel-iterations.
pub fn render_emis(
    scene: &Scene,
    settings: PathSettings,
    config: &EmisConfig,
    opts: &RenderOptions,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<EmisOutput, RenderError> {
    let pool = crate::render::thread_pool(opts.threads)?;
    let (w, h) = (scene.camera.width, scene.camera.height);
    let pixels = w as u64 * h as u64;
    let mut state = EmisState::new(config.clone(), w, h);
    let mut film = Film::new(&scene.film);
    let start = Instant::now();
    let mut done = 0u32;
    // iterations the budget allows at the rate so far (unknown before the first); a sample
    // budget counts the iterations the image keeps, from `kept_from` (after a path-tracing
    // start was discarded) on
    let expected_total = |done: u32, kept_from: u32| match opts.budget {
        Budget::Samples(n) => kept_from + n,
        Budget::Time(_) if done == 0 => u32::MAX,
        Budget::Time(t) => ((t.as_secs_f64() / (start.elapsed().as_secs_f64() / done as f64)) as u32).max(done),
    };
    loop {
        let more = match opts.budget {
            Budget::Samples(n) => done < state.kept_from + n,
            Budget::Time(t) => {
                done == 0
                    || start.elapsed().as_secs_f64() + start.elapsed().as_secs_f64() / done as f64 <= t.as_secs_f64()
            }
        };
        if !more {
            break;
        }
        // moments are only worth collecting while another update can still come
        if state.next_update().is_none_or(|u| u >= expected_total(done, state.kept_from)) {
            state.stop_collecting();
        }
        let collect = state.collecting().then_some(state.candidate_set);
        let left = match opts.budget {
            Budget::Samples(n) => state.kept_from + n - done,
            Budget::Time(_) if done == 0 => 1,
            Budget::Time(t) => {
                let per_iteration = start.elapsed().as_secs_f64() / done as f64;
                ((t.as_secs_f64() - start.elapsed().as_secs_f64()) / per_iteration).floor().max(1.0) as u32
            }
        };
        let count = match state.next_update().filter(|_| collect.is_some()) {
            // a collecting pass ends at the next update, which is within a sample budget
            Some(update) => collecting_call(done..update.max(done + 1), state.strategy.nu).len() as u32,
            None => final_call(done..done + left, state.strategy.nu, pixels).len() as u32,
        }
        .min(left);
        let (accum, pilot) = pool.install(|| {
            render_iterations(scene, settings, config, &state.strategy, opts.seed, done..done + count, collect)
        });
        film.merge_tile(&accum);
        if let Some(p) = pilot {
            state.absorb(&p).expect("invariant: a local pilot has the state's shape");
        }
        done += count;
        let total = expected_total(done, state.kept_from);
        progress(done as u64 * pixels, total as u64 * pixels);
        // an update is only worth it if iterations remain to use it
        // a restart now would render a sample budget's N iterations after the ones so far
        let restart_total = if let Budget::Samples(n) = opts.budget { done.saturating_add(n) } else { total };
        if state.update_due(done)
            && done < total
            && pool.install(|| state.update(&film.average(), done, restart_total)).restarted
        {
            film = Film::new(&scene.film);
        }
    }
    Ok(EmisOutput { render: RenderOutput { film, elapsed: start.elapsed(), spp: done - state.kept_from }, state })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The calls a pass over `iterations` is cut into.
    fn cut(iterations: Range<u32>, nu: f32, pixels: u64) -> Vec<Range<u32>> {
        let mut calls = vec![];
        let mut begin = iterations.start;
        while begin < iterations.end {
            let call = final_call(begin..iterations.end, nu, pixels);
            begin = call.end;
            calls.push(call);
        }
        calls
    }

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
            let calls = cut(range.clone(), nu, small);
            assert_eq!((calls[0].start, calls.last().unwrap().end), (range.start, range.end));
            assert!(calls.windows(2).all(|w| w[0].end == w[1].start && w[0].len() >= w[1].len()), "{calls:?}");
            assert!(calls.iter().all(|c| c.len() <= FINAL_PT_ITERATIONS_MAX as usize));
            // sixteen or more farm tiles in every pass long enough for them
            assert!(calls.len() >= 16.min(range.len().div_ceil(8)), "{calls:?}");
        }
    }
}
