//! Sample hooks: every sample of the bidirectional integrators can be reported to an observer
//! with its technique, pixel, MIS-weighted contribution, and the gathered path densities and
//! sample counts a proxy-weight evaluation needs (emis-spec §3). The integrators are generic
//! over the observer; with [`NoObserver`] every call inlines to nothing, so unobserved
//! rendering pays nothing.

use super::path::mis::{PathPdfs, SampleCounts, Technique};
use crate::math::Rgb;

/// One sample as the integrator produced it.
#[derive(Debug)]
pub struct SampleRecord<'a> {
    /// The technique that sampled the path.
    pub technique: Technique,
    /// The pixel the contribution lands in (the splat pixel for light tracing).
    pub pixel: u32,
    /// The MIS-weighted contribution added to the pixel (including 1/χ for merges and P/N
    /// for light tracing).
    pub value: Rgb,
    /// The MIS weight that was applied.
    pub weight: f32,
    /// The full path's densities from both ends.
    pub pdfs: &'a PathPdfs,
    /// The sample counts of the strategy that produced the sample.
    pub counts: &'a SampleCounts,
}

/// Receives every sample. Called concurrently from render threads.
pub trait SampleObserver: Send + Sync {
    /// Called once per non-zero sample.
    fn on_sample(&self, record: &SampleRecord);
}

/// The observer that observes nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NoObserver;

impl SampleObserver for NoObserver {
    #[inline(always)]
    fn on_sample(&self, _record: &SampleRecord) {}
}
