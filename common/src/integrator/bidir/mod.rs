//! The bidirectional integrators `bdpt` and `vcm`, which differ only in merging.
//!
//! `bdpt`: bidirectional path tracing with a light-vertex cache (Davidovič et al. 2014, as in
//! SeeSharp's `VertexCacheBidir`), with sample counts as parameters for efficiency-aware MIS.
//! Each iteration traces N = ⌊ν·P⌋ light paths and caches their vertices. Light tracing
//! connects every light vertex to the camera. Then one camera path per pixel: at each vertex
//! it counts emitter hits, makes one next-event estimate, and connects to c light vertices
//! chosen uniformly from the cache. All techniques are combined with the balance heuristic over
//! their sample counts (`integrator::path::mis`). Both subpaths use Mitsuba's Russian roulette
//! from `rr_depth` on (SeeSharp has none); paths end at `max_depth` segments, on absorption, on
//! escape or by roulette.
//!
//! `vcm`: the same plus vertex merging (Georgiev et al. 2012): at every camera vertex but the
//! primary one, with probability χ of its pixel, photons of the iteration's cache within
//! radius r are merged (weight 1/χ); see [`super::path::merge`] for the radius and kernel. A fixed
//! radius makes `vcm` slightly biased (not progressive).
//!
//! Parameters: `max_depth`; ν (`--light-paths-per-pixel`, default 1); c (`--connections`,
//! default 1); for `vcm` χ (`--merge on|off` or a per-pixel mask) and the correlation-aware
//! factor (`--correlation-aware`). Use them where light arrives along paths camera paths find
//! hard (through small openings, from hidden lights); caustics seen directly need merging.

mod camera;

use super::observer::{IterationStart, NoObserver, PathCounters, SampleObserver};
use super::path::connections::Connections;
use super::path::light_cache::{CacheMemory, LightCache};
use super::path::light_path::{MAX_BIDIR_EDGES, light_path_count};
use super::path::merge::{MergeConfig, merge_radius_max, path_radius};
use super::path::mis::{MergeCounts, SampleCounts};
use super::path::photon_map::PhotonMap;
use super::path::techniques::light_trace;
use super::{Integrator, PathSettings, TileRequest};
use crate::film::TileAccum;
use crate::math::Rgb;
use crate::scene::Scene;
use glam::Vec2;
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;

/// The bidirectional path tracer, with optional merging, reporting samples to `O`.
#[derive(Clone, Debug)]
pub struct Bidir<O: SampleObserver = NoObserver> {
    /// Depth and emitter settings.
    pub settings: PathSettings,
    /// Light paths per pixel per iteration (ν).
    pub light_paths_per_pixel: f32,
    /// Connections per camera vertex (c), fixed or per pixel.
    pub connections: Connections,
    /// Merging (`vcm`), or none (`bdpt`).
    pub merge: Option<MergeConfig>,
    /// Measure what the strategy neither traces nor merges (see [`LightProbe`]).
    pub probe: bool,
    /// Receives every sample.
    pub observer: O,
    /// The light caches of the last iteration, whose memory the next one traces into (shared
    /// with other integrators of the same render through [`Bidir::with_memory`]).
    memory: Arc<CacheMemory>,
}

/// What an iteration observed for EMIS measures that its strategy would not: without light
/// paths (ν = 0) it traces a few, so that the cost model learns their length (L̄l); without a
/// pixel that merges, a share of the camera vertices count the photons within the merge
/// radius (φ). Otherwise the model takes both from fallbacks that make merging look free
/// (docs/emis.md §9.8). The probe adds nothing to the image; its light paths are reported as
/// the iteration's, and its queries as merge queries.
pub struct LightProbe;

impl LightProbe {
    /// Light paths per pixel the probe traces.
    pub const LIGHT_PATHS_PER_PIXEL: f32 = 1.0 / 32.0;
    /// Share of the camera vertices where a merge could happen that count photons.
    pub const QUERY_SHARE: f32 = 1.0 / 8.0;
}

/// What one iteration shares between its camera paths and splats.
pub struct Iteration {
    /// The light-vertex cache.
    pub cache: LightCache,
    /// The photon map over the cache (`vcm`).
    pub photons: Option<PhotonMap>,
    /// The map a [`LightProbe`] counts photons in (its own light paths', or the iteration's
    /// when no pixel merges).
    pub probe: Option<PhotonMap>,
    /// Largest merge radius.
    pub radius_max: f32,
}

impl Bidir<NoObserver> {
    /// `bdpt` with ν light paths per pixel and c connections.
    pub fn bdpt(settings: PathSettings, light_paths_per_pixel: f32, connections: u32) -> Self {
        Bidir {
            settings,
            light_paths_per_pixel,
            connections: Connections::Fixed(connections),
            merge: None,
            probe: false,
            observer: NoObserver,
            memory: Arc::default(),
        }
    }

    /// `vcm`: `bdpt` plus merging.
    pub fn vcm(settings: PathSettings, light_paths_per_pixel: f32, connections: u32, merge: MergeConfig) -> Self {
        Bidir {
            settings,
            light_paths_per_pixel,
            connections: Connections::Fixed(connections),
            merge: Some(merge),
            probe: false,
            observer: NoObserver,
            memory: Arc::default(),
        }
    }

    /// The same integrator with `connections` per camera vertex (per pixel, say).
    pub fn with_connections(self, connections: Connections) -> Self {
        Bidir { connections, ..self }
    }

    /// The same integrator tracing its light caches into `memory`, which the integrators of
    /// one render's successive calls share.
    pub fn with_memory(self, memory: Arc<CacheMemory>) -> Self {
        Bidir { memory, ..self }
    }

    /// The same integrator measuring with a [`LightProbe`] what its iterations neither trace
    /// nor merge.
    pub fn with_probe(self) -> Self {
        Bidir { probe: true, ..self }
    }

    /// The same integrator reporting its samples to `observer`.
    pub fn with_observer<O: SampleObserver>(self, observer: O) -> Bidir<O> {
        Bidir {
            settings: self.settings,
            light_paths_per_pixel: self.light_paths_per_pixel,
            connections: self.connections,
            merge: self.merge,
            probe: self.probe,
            observer,
            memory: self.memory,
        }
    }
}

impl<O: SampleObserver> Bidir<O> {
    fn max_edges(&self) -> u32 {
        self.settings.max_depth.min(MAX_BIDIR_EDGES)
    }

    /// Sample counts of a camera path through `pixel` whose primary hit is `d1` away.
    pub fn counts(&self, it: &Iteration, pixel: u32, d1: f32) -> SampleCounts {
        let cache = &it.cache;
        let n = cache.paths as f32;
        let connect = if cache.selectable.is_empty() {
            0.0
        } else {
            self.connections.at(pixel) * n / cache.selectable.len() as f32
        };
        let merge = self.merge.as_ref().map(|m| {
            let r = path_radius(d1, it.radius_max);
            let rc = d1 * (1.0f32).to_radians().tan();
            MergeCounts {
                area: std::f32::consts::PI * r * r,
                count: n * m.mask.at(pixel),
                correlation_aware: m.correlation_aware,
                correlation_area: std::f32::consts::PI * rc * rc,
                light_paths: n,
            }
        });
        SampleCounts { hit: 1.0, next_event: 1.0, connect, light_trace: n, merge }
    }

    /// Light-tracing splats (raster position, value) of every cached vertex, by chunks merged
    /// in order.
    fn splats(&self, scene: &Scene, it: &Iteration, scale: f32) -> Vec<Vec<(Vec2, Rgb)>> {
        let cache = &it.cache;
        let width = scene.camera.width;
        let chunk = 4096usize;
        (0..cache.vertices.len().div_ceil(chunk))
            .into_par_iter()
            .map(|c| {
                let mut out = Vec::new();
                for i in c * chunk..((c + 1) * chunk).min(cache.vertices.len()) {
                    let light = cache.subpath(i);
                    // directly visible emitters are hidden on request; path length is bounded
                    if (light.len() == 1 && self.settings.hide_emitters) || light.len() as u32 > self.max_edges() {
                        continue;
                    }
                    // the splat pixel's χ and the radius of a camera path whose primary hit is the
                    // light subpath's last vertex
                    let Some(raster) = scene.camera.raster_of(light[light.len() - 1].p - scene.camera.origin) else {
                        continue;
                    };
                    let pixel = raster.y as u32 * width + raster.x as u32;
                    let counts = self.counts(it, pixel, (light[light.len() - 1].p - scene.camera.origin).length());
                    if let Some((w, raster)) = light_trace(scene, light, &counts, scale, &self.observer, i as u32) {
                        out.push((raster, w.value));
                    }
                }
                out
            })
            .collect()
    }
}

impl<O: SampleObserver> Integrator for Bidir<O> {
    fn name(&self) -> &'static str {
        if self.merge.is_some() { "vcm" } else { "bdpt" }
    }

    fn full_frame(&self) -> bool {
        true
    }

    fn render_tile(&self, scene: &Scene, tile: &TileRequest, accum: &mut TileAccum) {
        let (w, h) = (scene.camera.width, scene.camera.height);
        assert_eq!(tile.rect, crate::film::Rect::full(w, h), "invariant: bdpt renders full-frame tiles");
        let n = light_path_count(self.light_paths_per_pixel, w * h);
        // the caches of the last iteration, whose memory the next one traces into (a call
        // running beside another on this integrator starts with empty ones)
        let (mut spare, mut spare_probe) = self.memory.take();
        for iteration in tile.samples.clone() {
            if tile.stop.requested() {
                break;
            }
            if self.settings.max_depth == 0 {
                for (x, y) in (0..h).flat_map(|y| (0..w).map(move |x| (x, y))) {
                    accum.add_sample(x, y, Vec2::new(x as f32 + 0.5, y as f32 + 0.5), Rgb::ZERO);
                }
                let start = IterationStart { iteration, ..IterationStart::default() };
                self.observer.on_iteration_start(&start);
                self.observer.on_iteration_end(&start, &PathCounters::default());
                continue;
            }
            // light paths stop one edge short: every technique adds at least one camera edge
            let trace = |mut cache: LightCache, paths: u32| {
                let max_edges = self.max_edges().saturating_sub(1);
                cache.retrace(scene, tile.seed, iteration, paths, max_edges, self.settings.rr_depth);
                cache
            };
            let light_start = Instant::now();
            let cache = trace(std::mem::take(&mut spare), n);
            let mut light_time = light_start.elapsed();
            let radius_max = merge_radius_max(scene);
            let probe = (self.probe && n == 0).then(|| {
                trace(std::mem::take(&mut spare_probe), light_path_count(LightProbe::LIGHT_PATHS_PER_PIXEL, w * h))
            });
            let build_start = Instant::now();
            // no map without light paths or without a pixel that merges: queries against an
            // empty map would only cost time, and would count as merges that found nothing
            // (diluting φ, photons per query and light path)
            let photons = self
                .merge
                .as_ref()
                .filter(|m| n > 0 && m.mask.may_merge())
                .map(|_| PhotonMap::build(&cache.vertices, &cache.selectable, radius_max));
            let build_time = build_start.elapsed();
            // the probe's light paths stand in for the iteration's in the statistics and the
            // proxy's connection density
            let measured = probe.as_ref().unwrap_or(&cache);
            let start = IterationStart {
                iteration,
                light_paths: measured.paths,
                light_vertices: measured.vertices.len() as u64,
                selectable_vertices: measured.selectable.len() as u64,
            };
            // photons are counted over the probe's light paths, or over the iteration's when no
            // pixel merges
            let probe_map = match (&photons, &self.merge) {
                (None, Some(_)) if self.probe && measured.paths > 0 => {
                    Some(PhotonMap::build(&measured.vertices, &measured.selectable, radius_max))
                }
                _ => None,
            };
            if let Some(probe) = probe {
                spare_probe = probe;
            }
            let it = Iteration { cache, photons, probe: probe_map, radius_max };
            self.observer.on_iteration_start(&start);
            let splat_start = Instant::now();
            let splats = if n > 0 { self.splats(scene, &it, (w * h) as f32 / n as f32) } else { Vec::new() };
            light_time += splat_start.elapsed();
            let rows: Vec<(Vec<(Rgb, Vec2)>, PathCounters)> = (0..h)
                .into_par_iter()
                .map_init(Vec::new, |verts, y| {
                    let mut counters = PathCounters::default();
                    if tile.stop.requested() {
                        return (Vec::new(), counters);
                    }
                    let row = (0..w)
                        .map(|x| {
                            let value = self.camera_path(scene, &it, x, y, tile.seed, iteration, verts, &mut counters);
                            self.observer.on_camera_path_end(y * w + x);
                            value
                        })
                        .collect();
                    (row, counters)
                })
                .collect();
            let mut counters = PathCounters::default();
            for (_, row_counters) in &rows {
                counters += *row_counters;
            }
            if self.observer.wants_times() {
                // the phases run on the whole pool (the build on one thread while the others
                // wait): their cost is the pool's time
                let pool = |t: std::time::Duration| t.as_nanos() as u64 * rayon::current_num_threads() as u64;
                let t = &mut counters.times;
                // a probe's light vertices are neither splatted nor timed
                (t.iterations, t.light_vertices, t.light_ns) = (1, it.cache.vertices.len() as u64, pool(light_time));
                if it.photons.is_some() {
                    (t.photons_built, t.build_ns) = (start.selectable_vertices, pool(build_time));
                }
            }
            self.observer.on_iteration_end(&start, &counters);
            // a stopped render's rows may be empty: they hold no samples
            let rows: Vec<&[(Rgb, Vec2)]> = rows.iter().map(|(row, _)| row.as_slice()).collect();
            accum.add_frame(&rows, &splats);
            spare = it.cache;
        }
        self.memory.put(spare, spare_probe);
    }
}
