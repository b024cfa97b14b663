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

use super::observer::{IterationStart, NoObserver, PathCounters, PrimaryHit, SampleObserver, timed_pixel};
use super::path::connections::Connections;
use super::path::light_cache::{CacheMemory, LightCache};
use super::path::light_path::{MAX_BIDIR_EDGES, light_path_count};
use super::path::merge::{MergeConfig, merge, merge_radius_max, path_radius};
use super::path::mis::{MergeCounts, SampleCounts};
use super::path::photon_map::PhotonMap;
use super::path::techniques::{Report, area_emission, camera_vertex, connect, emitter_hit, light_trace, next_event};
use super::path::vertex::{PathVertex, VertexKind, density_at_vertex, solid_angle_to_area};
use super::{Integrator, PathSettings, TileRequest};
use crate::bsdf::TransportMode;
use crate::film::TileAccum;
use crate::geometry::SurfaceRef;
use crate::math::{Rgb, max_component};
use crate::sampler::Sampler;
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::cell::Cell;
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

    /// One camera path through pixel (x, y): the sum of its weighted contributions and the
    /// raster position it started from. Its work is added to `counters`.
    #[allow(clippy::too_many_arguments)]
    fn camera_path(
        &self,
        scene: &Scene,
        it: &Iteration,
        x: u32,
        y: u32,
        seed: u64,
        iteration: u32,
        verts: &mut Vec<PathVertex>,
        counters: &mut PathCounters,
    ) -> (Rgb, Vec2) {
        let cam = &scene.camera;
        let cache = &it.cache;
        let pixels = (cam.width * cam.height) as f32;
        let pixel = y * cam.width + x;
        let mut sampler = Sampler::for_pixel(seed, pixel, iteration);
        // until the primary hit is known, any radius will do: no merge can involve the camera ray
        let mut counts = self.counts(it, pixel, 1.0);
        let mut radius = 0.0;
        // a sample of the paths is timed (for costs measured per job), the observer's own
        // time left out
        let timed = self.observer.wants_times() && timed_pixel(pixel);
        let clock = Cell::new(0u64);
        let path_start = timed.then(Instant::now);
        let vertices_before = counters.camera_vertices;
        let mut block_ns = 0u64;
        let report = Report { observer: &self.observer, pixel, clock: timed.then_some(&clock) };
        let raster = Vec2::new(x as f32, y as f32) + sampler.next_2d();
        let mut ray = cam.generate_ray(raster);
        let mut pdf_dir = pixels * cam.pdf_ray(ray.d).1;
        let mut beta = Rgb::ONE;
        let mut eta = 1.0f32;
        let mut total = Rgb::ZERO;
        let max_edges = self.max_edges();
        let connect_scale = if counts.connect > 0.0 { 1.0 / counts.connect } else { 0.0 };
        verts.clear();
        verts.push(camera_vertex(scene));
        loop {
            let depth = verts.len() as u32;
            let prev = verts[verts.len() - 1];
            let Some(hit) = scene.intersect(&ray) else {
                // ---- escaped: infinite lights ----
                if !(self.settings.hide_emitters && depth == 1) {
                    for &li in &scene.infinite_lights {
                        let radiance = scene.lights[li as usize].eval_infinite(ray.d);
                        if radiance == Rgb::ZERO {
                            continue;
                        }
                        let env = PathVertex {
                            p: ray.o + ray.d * (2.0 * scene.bounds_radius),
                            n_geo: -ray.d,
                            n_shading: -ray.d,
                            tangent: Vec3::ZERO,
                            wo: -ray.d,
                            beta,
                            pdf_fwd: pdf_dir,
                            pdf_rev: 0.0,
                            pdf_next_event: 0.0,
                            kind: VertexKind::Light { light: li, at: SurfaceRef::default() },
                            delta: false,
                            depth,
                        };
                        verts.push(env);
                        total += emitter_hit(scene, verts, li, radiance, &counts, &report);
                        verts.pop();
                    }
                }
                break;
            };
            let shape = &scene.shapes[hit.shape as usize];
            let v = PathVertex {
                p: hit.p,
                n_geo: hit.n_geo,
                n_shading: hit.frame.n,
                tangent: scene.vertex_tangent(&hit),
                wo: hit.wo,
                beta,
                pdf_fwd: solid_angle_to_area(pdf_dir, prev.p, hit.p, hit.n_geo),
                pdf_rev: 0.0,
                pdf_next_event: 0.0,
                kind: VertexKind::Surface { material: shape.material, at: hit.surface() },
                delta: false,
                depth,
            };
            verts.push(v);
            counters.camera_vertices += 1;
            if depth == 1 {
                let d1 = (hit.p - cam.origin).length();
                counts = self.counts(it, pixel, d1);
                radius = path_radius(d1, it.radius_max);
            }
            // ---- emitter hit ----
            if let Some(li) = shape.light {
                if !(self.settings.hide_emitters && depth == 1) {
                    let le = area_emission(scene, li, &v);
                    if le != Rgb::ZERO {
                        total += emitter_hit(scene, verts, li, le, &counts, &report);
                    }
                }
            }
            // the denoiser's guides: reported once the primary vertex's BSDF sample is known
            let primary = |albedo: Rgb| PrimaryHit { pixel, albedo, normal: hit.frame.n, distance: hit.t };
            if depth >= max_edges {
                if depth == 1 {
                    self.observer.on_primary_hit(&primary(Rgb::ZERO));
                }
                break;
            }
            // drawn in the order they are used, but before the work that comes first: the first
            // connection's two dependent loads then overlap with the material and next-event
            // estimation (docs/decisions/0044)
            let (u_light, u_pos) = (sampler.next_1d(), sampler.next_2d());
            let connections = self.connections.draw(pixel, &mut sampler);
            let u_first = (connections > 0).then(|| sampler.next_1d());
            if let Some(u) = u_first {
                cache.prefetch_pick(u);
            }
            let material = scene.material_at(shape.material, hit.surface(), hit.p);
            // a vertex without a smooth lobe connects to nothing
            let smooth = material.has_smooth_lobe();
            let mut pick = u_first.filter(|_| smooth).and_then(|u| cache.pick(u));
            if let Some(i) = pick {
                cache.prefetch_subpath(i);
            }
            // ---- next-event estimation ----
            if smooth {
                if let Some(w) = next_event(scene, verts, &material, u_light, u_pos, &counts, &report) {
                    total += w.value;
                }
            }
            // ---- connections to cached light vertices ----
            let block = timed.then(|| (Instant::now(), clock.get()));
            let mut tried = 0u64;
            for k in 0..connections {
                let this = pick;
                // the next pick is loaded while this one connects
                if k + 1 < connections {
                    let u = sampler.next_1d();
                    pick = if smooth { cache.pick(u) } else { None };
                    if let Some(i) = pick {
                        cache.prefetch_subpath(i);
                    }
                }
                let Some(this) = this else { continue };
                let light = cache.subpath(this);
                if depth + light.len() as u32 > max_edges {
                    continue;
                }
                tried += 1;
                if let Some(w) = connect(scene, verts, &material, light, connect_scale, &counts, &report) {
                    total += w.value;
                }
            }
            if let Some(block) = block.filter(|_| tried > 0) {
                let ns = net_ns(block, &clock);
                block_ns += ns;
                counters.times.connections += tried;
                counters.times.connection_ns += ns;
            }
            // ---- merging (vcm), never at the primary vertex ----
            if let Some(m) = &self.merge {
                // drawn whether or not there is a map, so the samples that follow stay the same
                let u = sampler.next_1d();
                let chi = m.mask.at(pixel);
                if let Some(probe) = &it.probe
                    && depth >= 2
                    && u < LightProbe::QUERY_SHARE
                    && material.has_smooth_lobe()
                {
                    // count only, as `merge` counts what it finds
                    let mut found = 0u64;
                    probe.query(hit.p, radius, |_, _| found += 1);
                    counters.merge_queries += 1;
                    counters.photons_found += found;
                } else if let Some(photons) = &it.photons
                    && depth >= 2
                    && chi > 0.0
                    && u < chi
                    && material.has_smooth_lobe()
                {
                    let block = timed.then(|| (Instant::now(), clock.get()));
                    let (value, found) =
                        merge(scene, verts, &material, cache, photons, radius, chi, &counts, max_edges, &report);
                    total += value;
                    counters.merge_queries += 1;
                    counters.photons_found += found as u64;
                    if let Some(block) = block {
                        let (ns, t) = (net_ns(block, &clock), &mut counters.times);
                        block_ns += ns;
                        t.queries += 1;
                        t.photons += found as u64;
                        t.photons_squared += found as f64 * found as f64;
                        t.merge_ns += ns;
                        t.merge_ns_photons += ns as f64 * found as f64;
                    }
                }
            }
            // ---- continue the camera path ----
            let frame = hit.frame;
            let wo = frame.to_local(hit.wo);
            let (uc, u) = (sampler.next_1d(), sampler.next_2d());
            let sampled = material.sample(wo, uc, u, TransportMode::Radiance);
            if depth == 1 {
                let albedo = sampled.as_ref().map_or(Rgb::ZERO, |bs| bs.weight);
                self.observer.on_primary_hit(&primary(if albedo.is_finite() { albedo } else { Rgb::ZERO }));
            }
            let Some(bs) = sampled else { break };
            beta *= bs.weight;
            eta *= bs.eta;
            // Russian roulette as in Mitsuba's path (the MIS weights still sum to one per path,
            // so stopping early keeps every technique unbiased)
            if depth >= self.settings.rr_depth {
                let q = (max_component(beta) * eta * eta).min(0.95);
                if sampler.next_1d() >= q {
                    break;
                }
                beta /= q;
            }
            let n = verts.len();
            if n >= 3 {
                let before = verts[n - 2];
                verts[n - 2].pdf_rev =
                    density_at_vertex(if bs.delta { 0.0 } else { material.pdf(bs.wi, wo) }, hit.p, &before, false);
            }
            verts[n - 1].delta = bs.delta;
            pdf_dir = if bs.delta { 0.0 } else { bs.pdf };
            if beta == Rgb::ZERO || !beta.is_finite() {
                break;
            }
            ray = hit.spawn_ray(frame.to_world(bs.wi));
        }
        if let Some(start) = path_start {
            let t = &mut counters.times;
            let observer = clock.get();
            t.camera_vertices += counters.camera_vertices - vertices_before;
            t.camera_ns += (start.elapsed().as_nanos() as u64).saturating_sub(observer + block_ns);
            t.observer_ns += observer;
        }
        (total, raster)
    }
}

/// Nanoseconds since a block's start, less the observer's time in it (`clock` then and now).
fn net_ns((start, clock_then): (Instant, u64), clock: &Cell<u64>) -> u64 {
    (start.elapsed().as_nanos() as u64).saturating_sub(clock.get() - clock_then)
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
