//! The integrators `emis-bdpt` and `emis-vcm`: efficiency-aware MIS (Grittmann et al. 2022;
//! docs/emis.md) on the bidirectional engine.
//!
//! [`PilotStart::Bidirectional`], the paper's pilot, renders with a fixed strategy
//! (docs/emis.md, D5: `emis-vcm` VCM with N = P, c = 1, χ = 1 and correlation-aware
//! weights; `emis-bdpt` BDPT with N = P, c = 1) while a [`MomentEstimator`] records every
//! candidate's second moment per pixel. After iterations 1, 4, 16 and 64 (configurable) the
//! optimiser picks ν, c and the per-pixel merge mask χ from the merged moments, the denoised
//! image and the path statistics; rendering continues with that strategy (moments still
//! collected, each sample with the counts it was drawn with; while that strategy is pt, in a
//! quarter and later an eighth of the iterations, see [`collects_moments`]) until the last
//! update the budget can reach and that pays ([`update_pays`]), then without moments. Every
//! iteration, pilot included, stays in the image with equal weight. When path tracing wins,
//! the remaining iterations are rendered by `pt` itself (same integral, faster estimator).
//!
//! [`PilotStart::PathTracing`], the default, starts with path tracing instead (the
//! reference's `OnDemandVcm`; docs/emis.md, D5 and checklist 13): its updates choose
//! from a reduced set (ν ∈ {0.5, 1}, c ∈ {0, 1}, merging everywhere or nowhere, pt) while pt
//! wins. The first update a bidirectional candidate wins starts a new image, keeping the
//! old one aside (`EmisState::start`, combined by the weight the next update estimates),
//! restarts the moments for the full set and renders a sample budget's iterations in full
//! after it; the updates that follow keep the schedule (their iteration counts include the
//! start's). When no update would follow to weigh the start, the restart discards it, and a
//! candidate wins only by more than the share of the render it discards
//! (docs/decisions/0032-light-probe-and-restart-share.md). The pt start's recording
//! iterations carry a light probe (`integrator::LightProbe`): without
//! it the cost model would know neither the light paths' length nor the photons a merge
//! finds, and price merging as free (docs/decisions/0032-light-probe-and-restart-share.md).
//!
//! The pieces are split so that a farm can run them apart: [`render_iterations`] renders a
//! full-frame iteration range with a [`Strategy`] on any worker; [`EmisState`] (in `state`)
//! merges what workers return and runs the update at each barrier. When is decided by the job
//! driver (`crate::driver`), which [`render_emis`] runs locally and the coordinator on the
//! farm, so both sum the same numbers in the same order and their images are bit-identical.

use super::EmisState;
use super::candidate::{Candidate, CandidateConfig};
use super::cost::{CostConstants, StatisticsSums};
use super::denoise::DenoiseSettings;
use super::estimator::MomentEstimator;
use super::guides::{GuideBuffer, GuideCollector};
use super::moments::MomentBuffer;
use super::optimize::{ConnectionScope, FilterSettings};
use super::schedule::{collects_moments, traced_together};
use crate::driver::{Driver, EmisSchedule, Shape, Step};
use crate::film::{Film, Rect, TileAccum};
use crate::integrator::path::connections::Connections;
use crate::integrator::path::light_cache::CacheMemory;
use crate::integrator::path::merge::{MergeConfig, MergeMask};
use crate::integrator::{Bidir, Integrator, PathSettings, PathTracer, Stop, TileRequest};
use crate::render::{RenderError, RenderOptions, RenderOutput, ms_since};
use crate::scene::Scene;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::sync::Arc;
use std::time::Instant;

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

/// How an `emis-*` render starts (docs/emis.md, D5). The default, which
/// `RenderSettings` and so `tessera render` and farm jobs carry, is path tracing first: on the
/// nine bench scenes it beat the method's own pilot on every one
/// (docs/decisions/0032-light-probe-and-restart-share.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum PilotStart {
    /// The method's own pilot: VCM (or BDPT) with N = P, c = 1 (and χ = 1), kept in the image.
    #[cfg_attr(
        feature = "clap",
        value(help = "The method's own pilot: VCM (BDPT) with N = P, c = 1 (χ = 1), kept in the image")
    )]
    Bidirectional,
    /// Path tracing first (the reference's `OnDemandVcm`, docs/emis.md §1.2 and §4): updates
    /// choose from the reduced set ([`CandidateSet::Reduced`]) while path tracing wins. The
    /// first update a bidirectional candidate wins sets the iterations rendered so far aside
    /// (the film restarts with the new strategy, a sample budget counts its iterations only,
    /// and the start rejoins the image by a weight the next update estimates) and switches to
    /// the full set for the updates that follow.
    #[default]
    #[cfg_attr(
        feature = "clap",
        value(help = "Path tracing, choosing from a reduced candidate set until a bidirectional one wins")
    )]
    PathTracing,
}

impl PilotStart {
    /// Whether a render with this pilot warm-started from a strategy of `nu` light paths
    /// starts from it: always but from path tracing under the path-tracing start, which
    /// starts as that start does (its reduced set, which a path-tracing decision came from).
    pub fn takes_warm(self, nu: f32) -> bool {
        nu > 0.0 || self == PilotStart::Bidirectional
    }
}

/// Which candidates moments are recorded for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CandidateSet {
    /// The method's full set (docs/emis.md, D1): 51 for VCM, 26 for BDPT.
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
    /// The candidate set (docs/emis.md, D1).
    pub candidates: CandidateConfig,
    /// Optimise after these many iterations (docs/emis.md, D5).
    pub updates: Vec<u32>,
    /// Correlation-aware merge weights (pilot and final).
    pub correlation_aware: bool,
    /// Cost heuristic constants (docs/emis.md, D8).
    pub constants: CostConstants,
    /// Measure the constants per job from the pilot's work times, `constants` filling in what
    /// they cannot measure.
    pub measured_costs: bool,
    /// Filter radii (docs/emis.md, D6).
    pub filters: FilterSettings,
    /// The denoiser (docs/emis.md, D7).
    pub denoise: DenoiseSettings,
    /// The denoiser while a path-tracing start is still path tracing: its image is black on
    /// caustics, which only the guided filter's spreading lets speak (decision 0029).
    pub start_denoise: DenoiseSettings,
    /// The pilot: the method's own, or path tracing first.
    pub pilot: PilotStart,
    /// One c for the image or one per pixel (the reduced set's decisions are image-level).
    pub connection_scope: ConnectionScope,
    /// A path-tracing start settles on path tracing, collecting no more moments and running
    /// no more updates, once path tracing won two updates in a row with every bidirectional
    /// candidate's moment × cost at least this many times its own, the second on
    /// [`super::SETTLE_RECORDINGS`] recorded iterations or more (infinity: never).
    pub settle_margin: f64,
    /// A full-set update keeps the (ν, c) being rendered unless the lowest score is a dearer
    /// candidate's or lower by more than this / √(recorded iterations) of it (0: always the
    /// lowest score).
    pub incumbent_margin: f64,
    /// Start from this strategy instead of the pilot's, deciding from the full set at once:
    /// frame N+1 of a camera move starting from frame N's decision (`--warm-start`). A
    /// path-tracing decision under [`PilotStart::PathTracing`] starts as that pilot does.
    pub warm_start: Option<Strategy>,
}

impl EmisConfig {
    /// The update schedule of docs/emis.md, D5.
    pub const DEFAULT_UPDATES: [u32; 4] = [1, 4, 16, 64];

    /// The default [`EmisConfig::settle_margin`]: where path tracing won after 1 and 4
    /// iterations by 10 % or more, the later updates chose it too, and their recordings cost
    /// a few per cent of the render (docs/decisions/0041-path-tracing-settles.md).
    pub const SETTLE_MARGIN: f64 = 1.1;

    /// The default [`EmisConfig::incumbent_margin`] (docs/decisions/0046-incumbent-margin.md).
    pub const INCUMBENT_MARGIN: f64 = 0.25;

    /// The paper's configuration of `method` with the default pilot ([`PilotStart::default`],
    /// path tracing first), as `tessera render` and farm jobs run it unless their settings
    /// choose another (`RenderSettings::emis_pilot`).
    pub fn new(method: EmisMethod) -> Self {
        EmisConfig {
            method,
            candidates: match method {
                EmisMethod::Bdpt => CandidateConfig::bdpt(),
                EmisMethod::Vcm => CandidateConfig::vcm(),
            },
            updates: Self::DEFAULT_UPDATES.to_vec(),
            correlation_aware: true,
            constants: CostConstants::default(),
            measured_costs: false,
            filters: FilterSettings::default(),
            denoise: DenoiseSettings::default(),
            start_denoise: DenoiseSettings::GUIDED_HALF,
            pilot: PilotStart::default(),
            connection_scope: ConnectionScope::default(),
            settle_margin: Self::SETTLE_MARGIN,
            incumbent_margin: Self::INCUMBENT_MARGIN,
            warm_start: None,
        }
    }

    /// The strategy a render starts with and the candidates its first updates choose from:
    /// [`EmisConfig::warm_start`] with the full set, else the pilot's.
    pub fn initial(&self) -> (Strategy, CandidateSet) {
        match &self.warm_start {
            Some(s) if self.pilot.takes_warm(s.nu) => (s.clone(), CandidateSet::Full),
            _ => match self.pilot {
                PilotStart::Bidirectional => (Strategy::pilot(self.method), CandidateSet::Full),
                PilotStart::PathTracing => (Strategy::path_tracing_start(self.method), CandidateSet::Reduced),
            },
        }
    }

    /// [`EmisConfig::new`] with the method's own pilot ([`PilotStart::Bidirectional`]), which
    /// the benches and most decision tests study: its updates judge the full candidate set from
    /// the first iteration on.
    pub fn own_pilot(method: EmisMethod) -> Self {
        EmisConfig { pilot: PilotStart::Bidirectional, ..Self::new(method) }
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

    /// The pilot strategy of docs/emis.md, D5 ([`PilotStart::Bidirectional`]).
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
    let memory = Arc::default();
    render_iterations_until(scene, settings, config, strategy, seed, iterations, collect, &Stop::default(), &memory)
}

/// [`render_iterations`], given up when `stop` is requested (the result is then incomplete),
/// tracing light caches into `memory`, which a render's successive calls share.
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
    memory: &Arc<CacheMemory>,
) -> (TileAccum, Option<PilotData>) {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let rect = Rect::full(w, h);
    let collect = collect.filter(|_| collects_moments(strategy.nu, &iterations));
    if collect.is_none() && strategy.nu == 0.0 {
        // path tracing won: render it with `pt` (the same integral, the fastest estimator of
        // it), in small square tiles in parallel, placed in order, so deterministic
        let mut accum = None;
        path_trace(scene, settings, seed, std::slice::from_ref(&iterations), stop, |a| accum = Some(a));
        return (accum.expect("invariant: one run gives one accumulator"), None);
    }
    let mut accum = TileAccum::new(rect, &scene.film);
    let request = TileRequest::new(rect, iterations.clone(), seed).stoppable(stop.clone());
    let integrator = strategy.integrator(settings, config.correlation_aware).with_memory(memory.clone());
    let Some(set) = collect else {
        integrator.render_tile(scene, &request, &mut accum);
        return (accum, None);
    };
    let candidates = config.candidates_of(set);
    let estimator = MomentEstimator::new(w, h, &candidates).timed(config.measured_costs);
    let guided = if config.records_guides(set) {
        iterations.start.min(GUIDE_ITERATIONS)..iterations.end.min(GUIDE_ITERATIONS)
    } else {
        0..0
    };
    let guides = GuideCollector::new(w, h, guided);
    // under path tracing a light probe measures what the cost model needs of light paths
    integrator.with_probe().with_observer((&estimator, &guides)).render_tile(scene, &request, &mut accum);
    let (mut moments, mut statistics) = estimator.into_snapshot();
    if config.measured_costs && iterations.start == 0 && statistics.iterations > 0 {
        // the job's first call times path tracing too, which no pilot renders otherwise: the
        // `pt` integrator on iteration 0 once more, its image discarded
        let ns = path_trace(scene, settings, seed, &[0..1], stop, drop);
        statistics.times.path_tracing_ns += ns;
        statistics.times.path_tracing_vertices += statistics.camera_vertices / statistics.iterations;
    }
    moments.round_for_wire();
    (accum, Some(PilotData { moments, statistics, guides: guides.into_buffer() }))
}

/// The consecutive iteration ranges `runs` rendered by the `pt` integrator in [`PT_TILE`]
/// squares in parallel, a pixel's iterations of all runs in a row. Each run is summed into
/// its own full-frame accumulator, tiles added in order as if it were rendered alone, and
/// handed to `sink` in run order. Returns the tiles' times summed (nanoseconds of one thread).
fn path_trace(
    scene: &Scene,
    settings: PathSettings,
    seed: u64,
    runs: &[Range<u32>],
    stop: &Stop,
    mut sink: impl FnMut(TileAccum),
) -> u64 {
    use rayon::prelude::*;
    let pt = PathTracer { settings };
    let (w, h) = (scene.camera.width, scene.camera.height);
    let tiles: Vec<(Vec<TileAccum>, u64)> = Rect::tiles(w, h, PT_TILE)
        .into_par_iter()
        .map(|rect| {
            let start = Instant::now();
            let mut accums: Vec<TileAccum> = runs.iter().map(|_| TileAccum::new(rect, &scene.film)).collect();
            pt.render_runs(scene, rect, seed, runs, stop, &mut accums);
            (accums, start.elapsed().as_nanos() as u64)
        })
        .collect();
    let ns = tiles.iter().map(|t| t.1).sum();
    // each run's tiles are dropped as they are summed
    let mut tiles: Vec<_> = tiles.into_iter().map(|t| t.0.into_iter()).collect();
    for _ in runs {
        let mut accum = TileAccum::new(Rect::full(w, h), &scene.film);
        for tile in &mut tiles {
            accum.add(&tile.next().expect("invariant: one accumulator per run"));
        }
        sink(accum);
    }
    ns
}

/// A finished `emis-*` render.
pub struct EmisOutput {
    /// Image, time and iterations.
    pub render: RenderOutput,
    /// Moments, decisions and reports.
    pub state: EmisState,
}

/// The driver's shape of a local `emis-*` render of `scene` with `opts`.
pub fn shape(scene: &Scene, config: &EmisConfig, opts: &RenderOptions) -> Shape {
    let initial_nu = config.initial().0.nu;
    let emis = Some(EmisSchedule { updates: config.updates.clone(), initial_nu });
    Shape { width: scene.camera.width, height: scene.camera.height, budget: opts.budget, tile: None, emis }
}

/// Renders `scene` locally with `emis-*` on the caller's pool (`opts.threads`), running the
/// job [`Driver`]: each pass's calls in order (path tracing's several at a time once it
/// collects no moments, see [`traced_together`]), the updates it asks for at its barriers.
/// `progress(done, total)` counts pixel-iterations.
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
    let (stop, memory) = (Stop::default(), Arc::<CacheMemory>::default());
    let start = Instant::now();
    let (mut driver, mut tiles) = Driver::new(shape(scene, config, opts));
    driver.start(0.0);
    loop {
        let collect = driver.passes().last().is_some_and(|p| p.collect).then_some(state.candidate_set);
        let calls: Vec<Range<u32>> = tiles.iter().map(|t| t.samples.clone()).collect();
        let mut next = 0;
        while next < calls.len() {
            let done = calls[next].start;
            next += if collect.is_none() && state.strategy.nu == 0.0 {
                // path tracing has settled: trace a pixel's iterations of several calls in a
                // row, each call still summed alone and added in order, as a farm adds them
                let tenth = driver.expected_total(done, ms_since(start)).saturating_sub(driver.kept_from()) / 10;
                let group = &calls[next..next + traced_together(&calls[next..], pixels, tenth)];
                pool.install(|| path_trace(scene, settings, opts.seed, group, &stop, |a| film.merge_tile(&a)));
                group.len()
            } else {
                let (accum, pilot) = pool.install(|| {
                    let (strategy, call) = (&state.strategy, calls[next].clone());
                    render_iterations_until(scene, settings, config, strategy, opts.seed, call, collect, &stop, &memory)
                });
                film.merge_tile(&accum);
                if let Some(p) = pilot {
                    state.absorb(&p).expect("invariant: a local pilot has the state's shape");
                }
                1
            };
            let done = calls[next - 1].end;
            progress(done as u64 * pixels, driver.expected_total(done, ms_since(start)).max(done) as u64 * pixels);
        }
        tiles = match driver.barrier(ms_since(start)) {
            Step::Render(next) => next,
            Step::Finish => break,
            Step::Update(restart_total) => {
                let done = driver.planned();
                let restarted = pool.install(|| state.update(&film.average(), done, restart_total)).restarted;
                if restarted {
                    film = Film::new(&scene.film);
                }
                driver.updated(restarted, state.strategy.nu, state.collecting(), ms_since(start))
            }
        };
    }
    let spp = driver.planned() - driver.kept_from();
    Ok(EmisOutput { render: RenderOutput { film, elapsed: start.elapsed(), spp }, state })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Calls traced together sum to the same bits as each call traced alone: with a Gaussian
    /// filter, whose tiles overlap, and on one thread and two.
    #[test]
    fn runs_traced_together_sum_like_runs_traced_alone() {
        use crate::film::FilmSpec;
        use crate::film::filter::{Filter, FilterKind};
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/scene.xml");
        let mut scene = Scene::load(&path).expect("scene loads");
        scene.film = FilmSpec::new(scene.camera.width, scene.camera.height, Filter::new(FilterKind::DEFAULT));
        let settings = PathSettings::from_scene(&scene, None);
        let runs = [3..5, 5..6, 6..9];
        let stop = Stop::default();
        let alone: Vec<TileAccum> = runs
            .iter()
            .flat_map(|run| {
                let mut out = Vec::new();
                path_trace(&scene, settings, 9, std::slice::from_ref(run), &stop, |a| out.push(a));
                out
            })
            .collect();
        for threads in [1, 2] {
            let pool = crate::render::thread_pool(threads).unwrap();
            let mut together = Vec::new();
            pool.install(|| path_trace(&scene, settings, 9, &runs, &stop, |a| together.push(a)));
            assert_eq!(together.len(), runs.len());
            for (a, b) in alone.iter().zip(&together) {
                assert_eq!((a.bounds, &a.count), (b.bounds, &b.count));
                assert!(a.sum.iter().flatten().any(|&v| v > 0.0), "the runs saw light");
                let bits = |t: &TileAccum| t.sum.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(a), bits(b), "{threads} threads");
                let weights =
                    |t: &TileAccum| t.weight.as_ref().map(|w| w.iter().map(|v| v.to_bits()).collect::<Vec<_>>());
                assert_eq!(weights(a), weights(b));
                assert!(a.weight.is_some(), "the Gaussian filter keeps weights");
            }
        }
    }
}
