//! Sample hooks: every sample of the bidirectional integrators can be reported to an observer
//! with its technique, pixel, MIS-weighted contribution, and the gathered path densities and
//! sample counts a proxy-weight evaluation needs (docs/emis.md §3.2), plus per-iteration path
//! statistics for the cost model (docs/emis.md §2). The integrators are generic over the
//! observer; with [`NoObserver`] every call inlines to nothing, so unobserved rendering pays
//! nothing.

use super::path::mis::{PathPdfs, SampleCounts, Technique};
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
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PathCounters {
    /// Surface vertices of all camera paths.
    pub camera_vertices: u64,
    /// Merge queries that ran (passed the χ test).
    pub merge_queries: u64,
    /// Photons found within the radius by those queries.
    pub photons_found: u64,
}

impl std::ops::AddAssign for PathCounters {
    fn add_assign(&mut self, o: Self) {
        self.camera_vertices += o.camera_vertices;
        self.merge_queries += o.merge_queries;
        self.photons_found += o.photons_found;
    }
}

/// Receives every sample. Called concurrently from render threads: during an iteration's
/// light-tracing phase from any thread for any pixel; during its camera phase, all samples of
/// one camera path come from one thread, in order, followed by `on_camera_path_end`.
pub trait SampleObserver: Send + Sync {
    /// Called once per non-zero sample.
    fn on_sample(&self, record: &SampleRecord);
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
    #[inline(always)]
    fn on_sample(&self, record: &SampleRecord) {
        (**self).on_sample(record)
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
    fn on_sample(&self, record: &SampleRecord) {
        self.iter().for_each(|o| o.on_sample(record))
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
    #[inline(always)]
    fn on_sample(&self, record: &SampleRecord) {
        self.0.on_sample(record);
        self.1.on_sample(record);
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
