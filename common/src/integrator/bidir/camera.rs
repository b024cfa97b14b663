//! One camera path of the bidirectional integrators, vertex by vertex: the emitter hit,
//! next-event estimation, connections to cached light vertices, merging (or a light probe's
//! count), then the next direction. What EMIS measures of the work (times for costs measured
//! per job, the probe's photons) is compiled only for observers that measure
//! ([`SampleObserver::MEASURES`]): a plain `bdpt` or `vcm` render carries none of it.

use super::{Bidir, Iteration, LightProbe};
use crate::bsdf::{Material, TransportMode};
use crate::geometry::{Ray, SurfaceInteraction, SurfaceRef};
use crate::integrator::observer::{PathCounters, PrimaryHit, SampleObserver, timed_pixel};
use crate::integrator::path::merge::{MergeConfig, merge, path_radius};
use crate::integrator::path::mis::SampleCounts;
use crate::integrator::path::techniques::{Report, area_emission, camera_vertex, connect, emitter_hit, next_event};
use crate::integrator::path::vertex::{PathVertex, VertexKind, density_at_vertex, solid_angle_to_area};
use crate::math::{Rgb, max_component};
use crate::sampler::Sampler;
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use std::cell::Cell;
use std::time::Instant;

/// What a camera path carries from vertex to vertex.
struct Walk {
    ray: Ray,
    /// Density of `ray`'s direction (solid angle).
    pdf_dir: f32,
    beta: Rgb,
    eta: f32,
    counts: SampleCounts,
    /// The merge radius of the path (known at its primary hit).
    radius: f32,
    total: Rgb,
}

/// What every step of one camera path reads.
struct PathContext<'a, O: SampleObserver> {
    scene: &'a Scene,
    it: &'a Iteration,
    pixel: u32,
    report: Report<'a, O>,
    timer: &'a PathTimer,
}

/// What the steps at one surface vertex read: the path's context and the vertex's material.
struct At<'a, O: SampleObserver> {
    path: &'a PathContext<'a, O>,
    material: &'a Material,
}

/// The timing of one camera path for costs measured per job: a sample of the paths is timed,
/// the observer's own time left out. Inert (and compiled away) unless the observer measures.
struct PathTimer {
    on: bool,
    /// The observer's time within the path (nanoseconds), added by [`Report`].
    clock: Cell<u64>,
    start: Option<Instant>,
    vertices_before: u64,
    /// Time of the blocks timed on their own (connections, merges).
    blocks_ns: Cell<u64>,
}

impl PathTimer {
    #[inline(always)]
    fn new(on: bool, counters: &PathCounters) -> Self {
        let start = on.then(Instant::now);
        PathTimer { on, clock: Cell::new(0), start, vertices_before: counters.camera_vertices, blocks_ns: Cell::new(0) }
    }

    /// Where a [`Report`] adds the observer's time.
    #[inline(always)]
    fn clock(&self) -> Option<&Cell<u64>> {
        self.on.then_some(&self.clock)
    }

    #[inline(always)]
    fn block(&self) -> Option<(Instant, u64)> {
        self.on.then(|| (Instant::now(), self.clock.get()))
    }

    /// Nanoseconds since `block` began, less the observer's time in it.
    fn end_block(&self, (start, clock_then): (Instant, u64)) -> u64 {
        let ns = (start.elapsed().as_nanos() as u64).saturating_sub(self.clock.get() - clock_then);
        self.blocks_ns.set(self.blocks_ns.get() + ns);
        ns
    }

    #[inline(always)]
    fn connections(&self, block: Option<(Instant, u64)>, tried: u64, counters: &mut PathCounters) {
        if let Some(block) = block.filter(|_| tried > 0) {
            let ns = self.end_block(block);
            counters.times.connections += tried;
            counters.times.connection_ns += ns;
        }
    }

    #[inline(always)]
    fn merge(&self, block: Option<(Instant, u64)>, found: u32, counters: &mut PathCounters) {
        if let Some(block) = block {
            let ns = self.end_block(block);
            let t = &mut counters.times;
            t.queries += 1;
            t.photons += found as u64;
            t.photons_squared += found as f64 * found as f64;
            t.merge_ns += ns;
            t.merge_ns_photons += ns as f64 * found as f64;
        }
    }

    /// Adds the path's own time (its camera vertices' work) to `counters`.
    #[inline(always)]
    fn finish(self, counters: &mut PathCounters) {
        if let Some(start) = self.start {
            let t = &mut counters.times;
            let observer = self.clock.get();
            t.camera_vertices += counters.camera_vertices - self.vertices_before;
            t.camera_ns += (start.elapsed().as_nanos() as u64).saturating_sub(observer + self.blocks_ns.get());
            t.observer_ns += observer;
        }
    }
}

impl<O: SampleObserver> Bidir<O> {
    /// One camera path through pixel (x, y): the sum of its weighted contributions and the
    /// raster position it started from. Its work is added to `counters`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn camera_path(
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
        let pixel = y * cam.width + x;
        let mut sampler = Sampler::for_pixel(seed, pixel, iteration);
        let timer = PathTimer::new(O::MEASURES && self.observer.wants_times() && timed_pixel(pixel), counters);
        let raster = Vec2::new(x as f32, y as f32) + sampler.next_2d();
        let ray = cam.generate_ray(raster);
        let pdf_dir = (cam.width * cam.height) as f32 * cam.pdf_ray(ray.d).1;
        // until the primary hit is known, any radius will do: no merge can involve the camera ray
        let counts = self.counts(it, pixel, 1.0);
        let mut walk = Walk { ray, pdf_dir, beta: Rgb::ONE, eta: 1.0, counts, radius: 0.0, total: Rgb::ZERO };
        verts.clear();
        verts.push(camera_vertex(scene));
        let report = Report { observer: &self.observer, pixel, clock: timer.clock() };
        let path = PathContext { scene, it, pixel, report, timer: &timer };
        loop {
            let Some(hit) = scene.intersect(&walk.ray) else {
                self.escaped(scene, verts, &mut walk, &path.report);
                break;
            };
            if !self.at_vertex(&path, &hit, verts, &mut walk, &mut sampler, counters) {
                break;
            }
        }
        timer.finish(counters);
        (walk.total, raster)
    }

    /// Adds the infinite lights a camera ray that escaped sees. Like every step, it adds each
    /// contribution to the path's total as it comes: summed in another order the image would
    /// not be the same bits.
    fn escaped(&self, scene: &Scene, verts: &mut Vec<PathVertex>, walk: &mut Walk, report: &Report<O>) {
        let depth = verts.len() as u32;
        if self.settings.hide_emitters && depth == 1 {
            return;
        }
        let ray = &walk.ray;
        for &li in &scene.infinite_lights {
            let radiance = scene.lights[li as usize].eval_infinite(ray.d);
            if radiance == Rgb::ZERO {
                continue;
            }
            verts.push(PathVertex {
                p: ray.o + ray.d * (2.0 * scene.bounds_radius),
                n_geo: -ray.d,
                n_shading: -ray.d,
                tangent: Vec3::ZERO,
                wo: -ray.d,
                beta: walk.beta,
                pdf_fwd: walk.pdf_dir,
                pdf_rev: 0.0,
                pdf_next_event: 0.0,
                kind: VertexKind::Light { light: li, at: SurfaceRef::default() },
                delta: false,
                depth,
            });
            walk.total += emitter_hit(scene, verts, li, radiance, &walk.counts, report);
            verts.pop();
        }
    }

    /// Everything at the surface vertex `hit`: returns whether the path goes on.
    fn at_vertex(
        &self,
        path: &PathContext<O>,
        hit: &SurfaceInteraction,
        verts: &mut Vec<PathVertex>,
        walk: &mut Walk,
        sampler: &mut Sampler,
        counters: &mut PathCounters,
    ) -> bool {
        let (scene, it, pixel, report) = (path.scene, path.it, path.pixel, &path.report);
        let depth = verts.len() as u32;
        let shape = &scene.shapes[hit.shape as usize];
        let v = PathVertex {
            p: hit.p,
            n_geo: hit.n_geo,
            n_shading: hit.frame.n,
            tangent: scene.vertex_tangent(hit),
            wo: hit.wo,
            beta: walk.beta,
            pdf_fwd: solid_angle_to_area(walk.pdf_dir, verts[verts.len() - 1].p, hit.p, hit.n_geo),
            pdf_rev: 0.0,
            pdf_next_event: 0.0,
            kind: VertexKind::Surface { material: shape.material, at: hit.surface() },
            delta: false,
            depth,
        };
        verts.push(v);
        counters.camera_vertices += 1;
        if depth == 1 {
            let d1 = (hit.p - scene.camera.origin).length();
            walk.counts = self.counts(it, pixel, d1);
            walk.radius = path_radius(d1, it.radius_max);
        }
        // ---- emitter hit ----
        if let Some(li) = shape.light
            && !(self.settings.hide_emitters && depth == 1)
        {
            let le = area_emission(scene, li, &v);
            if le != Rgb::ZERO {
                walk.total += emitter_hit(scene, verts, li, le, &walk.counts, report);
            }
        }
        // the denoiser's guides: reported once the primary vertex's BSDF sample is known
        let primary = |albedo: Rgb| PrimaryHit { pixel, albedo, normal: hit.frame.n, distance: hit.t };
        if depth >= self.max_edges() {
            if depth == 1 {
                self.observer.on_primary_hit(&primary(Rgb::ZERO));
            }
            return false;
        }
        // drawn in the order they are used, but before the work that comes first: the first
        // connection's two dependent loads then overlap with the material and next-event
        // estimation (docs/decisions/0044-connection-picks-prefetched.md)
        let (u_light, u_pos) = (sampler.next_1d(), sampler.next_2d());
        let connections = self.connections.draw(pixel, sampler);
        let u_first = (connections > 0).then(|| sampler.next_1d());
        if let Some(u) = u_first {
            it.cache.prefetch_pick(u);
        }
        let material = scene.material_at(shape.material, hit.surface(), hit.p);
        // a vertex without a smooth lobe connects to nothing
        let smooth = material.has_smooth_lobe();
        let pick = u_first.filter(|_| smooth).and_then(|u| it.cache.pick(u));
        if let Some(i) = pick {
            it.cache.prefetch_subpath(i);
        }
        // ---- next-event estimation ----
        if smooth && let Some(w) = next_event(scene, verts, &material, u_light, u_pos, &walk.counts, report) {
            walk.total += w.value;
        }
        let at = At { path, material: &material };
        self.connect_cached(&at, verts, (connections, pick), walk, sampler, counters);
        if let Some(m) = &self.merge {
            walk.total += self.merge_at(&at, m, hit, verts, walk, sampler, counters);
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
        let Some(bs) = sampled else { return false };
        walk.beta *= bs.weight;
        walk.eta *= bs.eta;
        // Russian roulette as in Mitsuba's path (the MIS weights still sum to one per path,
        // so stopping early keeps every technique unbiased)
        if depth >= self.settings.rr_depth {
            let q = (max_component(walk.beta) * walk.eta * walk.eta).min(0.95);
            if sampler.next_1d() >= q {
                return false;
            }
            walk.beta /= q;
        }
        let n = verts.len();
        if n >= 3 {
            let before = verts[n - 2];
            verts[n - 2].pdf_rev =
                density_at_vertex(if bs.delta { 0.0 } else { material.pdf(bs.wi, wo) }, hit.p, &before, false);
        }
        verts[n - 1].delta = bs.delta;
        walk.pdf_dir = if bs.delta { 0.0 } else { bs.pdf };
        if walk.beta == Rgb::ZERO || !walk.beta.is_finite() {
            return false;
        }
        walk.ray = hit.spawn_ray(frame.to_world(bs.wi));
        true
    }

    /// Connections of the path's last vertex to `connections` cached light vertices, the first
    /// being `pick` (chosen and prefetched before next-event estimation); each next pick is
    /// loaded while the one before connects. A vertex without a smooth lobe connects to
    /// nothing, but draws its picks all the same.
    fn connect_cached(
        &self,
        at: &At<O>,
        verts: &[PathVertex],
        (connections, mut pick): (u32, Option<usize>),
        walk: &mut Walk,
        sampler: &mut Sampler,
        counters: &mut PathCounters,
    ) {
        let (cache, material, timer) = (&at.path.it.cache, at.material, at.path.timer);
        let max_edges = self.max_edges();
        let depth = verts.len() as u32 - 1;
        let smooth = material.has_smooth_lobe();
        let connect_scale = if walk.counts.connect > 0.0 { 1.0 / walk.counts.connect } else { 0.0 };
        let block = timer.block();
        let mut tried = 0u64;
        for k in 0..connections {
            let this = pick;
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
            if let Some(w) =
                connect(at.path.scene, verts, material, light, connect_scale, &walk.counts, &at.path.report)
            {
                walk.total += w.value;
            }
        }
        timer.connections(block, tried, counters);
    }

    /// Merging at a camera vertex but the primary one, with probability χ of its pixel; or,
    /// where the iteration carries a light probe, a count of the photons a merge would find.
    #[allow(clippy::too_many_arguments)]
    fn merge_at(
        &self,
        at: &At<O>,
        m: &MergeConfig,
        hit: &SurfaceInteraction,
        verts: &[PathVertex],
        walk: &Walk,
        sampler: &mut Sampler,
        counters: &mut PathCounters,
    ) -> Rgb {
        let (it, material, pixel) = (at.path.it, at.material, at.path.pixel);
        let depth = verts.len() as u32 - 1;
        // drawn whether or not there is a map, so the samples that follow stay the same
        let u = sampler.next_1d();
        let chi = m.mask.at(pixel);
        if depth < 2 || !material.has_smooth_lobe() {
            return Rgb::ZERO;
        }
        if O::MEASURES
            && let Some(probe) = &it.probe
            && u < LightProbe::QUERY_SHARE
        {
            // count only, as `merge` counts what it finds
            let mut found = 0u64;
            probe.query(hit.p, walk.radius, |_, _| found += 1);
            counters.merge_queries += 1;
            counters.photons_found += found;
            return Rgb::ZERO;
        }
        let Some(photons) = &it.photons else { return Rgb::ZERO };
        if !(chi > 0.0 && u < chi) {
            return Rgb::ZERO;
        }
        let block = at.path.timer.block();
        let (max_edges, cache) = (self.max_edges(), &it.cache);
        let (value, found) = merge(
            at.path.scene,
            verts,
            material,
            cache,
            photons,
            walk.radius,
            chi,
            &walk.counts,
            max_edges,
            &at.path.report,
        );
        counters.merge_queries += 1;
        counters.photons_found += found as u64;
        at.path.timer.merge(block, found, counters);
        value
    }
}
