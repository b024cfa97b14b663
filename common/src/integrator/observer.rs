//! Sample hooks: every sample of the bidirectional integrators can be reported to an observer
//! with its technique, pixel, MIS-weighted contribution, and the gathered path densities and
//! sample counts a proxy-weight evaluation needs (docs/emis.md §3.2), plus per-iteration path
//! statistics for the cost model (docs/emis.md §2) and, when the observer asks for them, the
//! time each kind of work took ([`WorkTimes`], for costs measured per job). The integrators are
//! generic over the observer; with [`NoObserver`] every call inlines to nothing, so unobserved
//! rendering pays nothing.

use super::path::mis::{PathPdfs, PathRatios, SampleCounts, Technique};
use crate::math::Rgb;
use glam::Vec3;

/// One sample as the integrator produced it.
#[derive(Debug)]
pub struct SampleRecord<'a> {
    /// The technique that sampled the path.
    pub technique: Technique,
    /// The pixel the contribution lands in (the splat pixel for light tracing).
    pub pixel: u32,
    /// The MIS-weighted contribution added to the pixel (including 1/χ and the kernel for
    /// merges, and P/N for light tracing).
    pub value: Rgb,
    /// The MIS weight that was applied.
    pub weight: f32,
    /// The merge kernel value included in `value` (1 for every other technique).
    pub kernel: f32,
    /// For light tracing, the index of the light vertex in the iteration's cache (unique per
    /// sample, so that observers can order splats deterministically); 0 otherwise.
    pub sequence: u32,
    /// The full path's densities from both ends.
    pub pdfs: &'a PathPdfs,
    /// The path's ratios its MIS weight was computed from.
    pub ratios: &'a PathRatios,
    /// The sample counts of the strategy that produced the sample.
    pub counts: &'a SampleCounts,
}

/// A camera path's first surface vertex, for the denoiser's guides (docs/emis.md §5.4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrimaryHit {
    /// The pixel the camera path goes through.
    pub pixel: u32,
    /// The weight (f·cos/pdf) of the BSDF sample that continues the path: a one-sample
    /// estimate of the directional albedo; zero when nothing was sampled or the path ended.
    pub albedo: Rgb,
    /// World-space shading normal.
    pub normal: Vec3,
    /// Distance from the camera.
    pub distance: f32,
}

/// What an iteration's light subpaths look like, known before its camera paths start.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct IterationStart {
    /// The iteration index.
    pub iteration: u32,
    /// Light paths traced (N).
    pub light_paths: u32,
    /// Vertices stored, the emitter vertices included.
    pub light_vertices: u64,
    /// Vertices connections may choose (depth ≥ 1).
    pub selectable_vertices: u64,
}

/// Work counted over one iteration, for the cost model (docs/emis.md §2).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PathCounters {
    /// Surface vertices of all camera paths.
    pub camera_vertices: u64,
    /// Merge queries that ran (passed the χ test).
    pub merge_queries: u64,
    /// Photons found within the radius by those queries.
    pub photons_found: u64,
    /// The time the work took, where the observer asked for it
    /// ([`SampleObserver::wants_times`]).
    pub times: WorkTimes,
}

impl std::ops::AddAssign for PathCounters {
    fn add_assign(&mut self, o: Self) {
        self.camera_vertices += o.camera_vertices;
        self.merge_queries += o.merge_queries;
        self.photons_found += o.photons_found;
        self.times += o.times;
    }
}

/// Measured time of the bidirectional engine's kinds of work, in nanoseconds of one thread,
/// without the observer's own time: every light vertex (tracing and its light-tracing splat,
/// over whole iterations), the photon map's build, and, in the camera paths of a sample of
/// pixels ([`timed_pixel`]), camera vertices, connections and merge queries. Sums, so that
/// iterations and workers add up; they vary from run to run, unlike everything else a render
/// reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WorkTimes {
    /// Iterations timed.
    pub iterations: u64,
    /// Light vertices stored in those iterations.
    pub light_vertices: u64,
    /// Tracing and splatting them (the pool's wall time × its threads).
    pub light_ns: u64,
    /// Photons the maps of those iterations held.
    pub photons_built: u64,
    /// Building the maps (wall time × threads).
    pub build_ns: u64,
    /// Camera vertices of the timed paths.
    pub camera_vertices: u64,
    /// Their time: intersection, emitter hit, next-event estimate, sampling the next
    /// direction, without connections and merges.
    pub camera_ns: u64,
    /// Connections tried at the timed paths' vertices.
    pub connections: u64,
    /// Their time.
    pub connection_ns: u64,
    /// Merge queries at the timed paths' vertices.
    pub queries: u64,
    /// Photons those queries found.
    pub photons: u64,
    /// Σ photons² over the queries (for the fit of time against photons).
    pub photons_squared: f64,
    /// Their time.
    pub merge_ns: u64,
    /// Σ time × photons over the queries.
    pub merge_ns_photons: f64,
    /// The observer's own time within the timed work (left out of every figure above).
    pub observer_ns: u64,
    /// Camera vertices of the iterations the `pt` integrator rendered as a probe (costs
    /// measured per job: path tracing's cost per camera vertex), as the bidirectional engine
    /// counted them in the same iterations.
    pub path_tracing_vertices: u64,
    /// The probe's time: its tiles' times summed over the threads.
    pub path_tracing_ns: u64,
}

impl std::ops::AddAssign for WorkTimes {
    fn add_assign(&mut self, o: Self) {
        // saturating: sums a worker sends must not wrap (the coordinator bounds them as well)
        let add = |a: &mut u64, b: u64| *a = a.saturating_add(b);
        add(&mut self.iterations, o.iterations);
        add(&mut self.light_vertices, o.light_vertices);
        add(&mut self.light_ns, o.light_ns);
        add(&mut self.photons_built, o.photons_built);
        add(&mut self.build_ns, o.build_ns);
        add(&mut self.camera_vertices, o.camera_vertices);
        add(&mut self.camera_ns, o.camera_ns);
        add(&mut self.connections, o.connections);
        add(&mut self.connection_ns, o.connection_ns);
        add(&mut self.queries, o.queries);
        add(&mut self.photons, o.photons);
        self.photons_squared += o.photons_squared;
        add(&mut self.merge_ns, o.merge_ns);
        self.merge_ns_photons += o.merge_ns_photons;
        add(&mut self.observer_ns, o.observer_ns);
        add(&mut self.path_tracing_vertices, o.path_tracing_vertices);
        add(&mut self.path_tracing_ns, o.path_tracing_ns);
    }
}

/// One pixel in [`TIMED_PIXEL_STRIDE`] has its camera paths timed: enough paths for stable
/// means, few enough that the clock reads cost nothing measurable.
pub const TIMED_PIXEL_STRIDE: u32 = 8;

/// Whether `pixel`'s camera paths are timed.
#[inline(always)]
pub fn timed_pixel(pixel: u32) -> bool {
    pixel.is_multiple_of(TIMED_PIXEL_STRIDE)
}

/// Receives every sample. Called concurrently from render threads: during an iteration's
/// light-tracing phase from any thread for any pixel; during its camera phase, all samples of
/// one camera path come from one thread, in order, followed by `on_camera_path_end`.
pub trait SampleObserver: Send + Sync {
    /// Whether this kind of observer measures the work: times it ([`Self::wants_times`]) and
    /// counts a light probe's photons. When false, integrators compile none of that code for
    /// it, so plain renders pay nothing for EMIS's measurements.
    const MEASURES: bool = false;
    /// Called once per non-zero sample.
    fn on_sample(&self, record: &SampleRecord);
    /// Whether the integrator should time its work ([`PathCounters::times`]); only read when
    /// [`Self::MEASURES`].
    #[inline(always)]
    fn wants_times(&self) -> bool {
        false
    }
    /// Called before an iteration's light tracing, once its light subpaths are traced.
    #[inline(always)]
    fn on_iteration_start(&self, _start: &IterationStart) {}
    /// Called on the camera path's thread once its first surface vertex is sampled (not for
    /// camera rays that escape).
    #[inline(always)]
    fn on_primary_hit(&self, _hit: &PrimaryHit) {}
    /// Called on the camera path's thread after its last sample.
    #[inline(always)]
    fn on_camera_path_end(&self, _pixel: u32) {}
    /// Called once all of the iteration's samples were reported.
    #[inline(always)]
    fn on_iteration_end(&self, _start: &IterationStart, _counters: &PathCounters) {}
}

impl<T: SampleObserver + ?Sized> SampleObserver for &T {
    const MEASURES: bool = T::MEASURES;
    #[inline(always)]
    fn on_sample(&self, record: &SampleRecord) {
        (**self).on_sample(record)
    }
    #[inline(always)]
    fn wants_times(&self) -> bool {
        (**self).wants_times()
    }
    #[inline(always)]
    fn on_iteration_start(&self, start: &IterationStart) {
        (**self).on_iteration_start(start)
    }
    #[inline(always)]
    fn on_primary_hit(&self, hit: &PrimaryHit) {
        (**self).on_primary_hit(hit)
    }
    #[inline(always)]
    fn on_camera_path_end(&self, pixel: u32) {
        (**self).on_camera_path_end(pixel)
    }
    #[inline(always)]
    fn on_iteration_end(&self, start: &IterationStart, counters: &PathCounters) {
        (**self).on_iteration_end(start, counters)
    }
}

/// Several observers of the same kind watching one render (e.g. moment estimators with
/// different settings).
impl<T: SampleObserver> SampleObserver for [T] {
    const MEASURES: bool = T::MEASURES;
    fn on_sample(&self, record: &SampleRecord) {
        self.iter().for_each(|o| o.on_sample(record))
    }
    fn wants_times(&self) -> bool {
        self.iter().any(|o| o.wants_times())
    }
    fn on_iteration_start(&self, start: &IterationStart) {
        self.iter().for_each(|o| o.on_iteration_start(start))
    }
    fn on_primary_hit(&self, hit: &PrimaryHit) {
        self.iter().for_each(|o| o.on_primary_hit(hit))
    }
    fn on_camera_path_end(&self, pixel: u32) {
        self.iter().for_each(|o| o.on_camera_path_end(pixel))
    }
    fn on_iteration_end(&self, start: &IterationStart, counters: &PathCounters) {
        self.iter().for_each(|o| o.on_iteration_end(start, counters))
    }
}

/// Two observers of different kinds watching one render (e.g. moments and guides), each
/// told everything in the same order.
impl<A: SampleObserver, B: SampleObserver> SampleObserver for (A, B) {
    const MEASURES: bool = A::MEASURES || B::MEASURES;
    #[inline(always)]
    fn on_sample(&self, record: &SampleRecord) {
        self.0.on_sample(record);
        self.1.on_sample(record);
    }
    #[inline(always)]
    fn wants_times(&self) -> bool {
        self.0.wants_times() || self.1.wants_times()
    }
    #[inline(always)]
    fn on_iteration_start(&self, start: &IterationStart) {
        self.0.on_iteration_start(start);
        self.1.on_iteration_start(start);
    }
    #[inline(always)]
    fn on_primary_hit(&self, hit: &PrimaryHit) {
        self.0.on_primary_hit(hit);
        self.1.on_primary_hit(hit);
    }
    #[inline(always)]
    fn on_camera_path_end(&self, pixel: u32) {
        self.0.on_camera_path_end(pixel);
        self.1.on_camera_path_end(pixel);
    }
    #[inline(always)]
    fn on_iteration_end(&self, start: &IterationStart, counters: &PathCounters) {
        self.0.on_iteration_end(start, counters);
        self.1.on_iteration_end(start, counters);
    }
}

/// The observer that observes nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NoObserver;

impl SampleObserver for NoObserver {
    #[inline(always)]
    fn on_sample(&self, _record: &SampleRecord) {}
}
