//! Denoiser guides (docs/emis.md §5.4 and D7): per pixel, the albedo and shading normal
//! at the primary hit and its distance, averaged over the pilot iterations. Albedo is a
//! one-sample estimate of the directional albedo (the weight of one BSDF sample), which works
//! for every material, delta lobes included. The pilot's own camera paths supply them through
//! the sample hooks ([`GuideCollector`]), so guides cost no extra rays. Sums with a sample
//! count, so buffers from workers add up.

use crate::integrator::observer::{IterationStart, PrimaryHit, SampleObserver, SampleRecord};
use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};

/// Per-pixel guides (means over the pilot).
pub struct Guides<'a> {
    /// Albedo.
    pub albedo: &'a [[f32; 3]],
    /// Unit shading normal, zero where the camera ray escaped.
    pub normal: &'a [[f32; 3]],
    /// Distance to the primary hit.
    pub depth: &'a [f32],
}

/// Guide sums of a full frame.
#[derive(Clone, Debug, PartialEq)]
pub struct GuideBuffer {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Σ albedo per pixel.
    pub albedo: Vec<[f32; 3]>,
    /// Σ world-space shading normal per pixel (zero where the ray escaped).
    pub normal: Vec<[f32; 3]>,
    /// Σ distance to the primary hit (0 where the ray escaped).
    pub depth: Vec<f32>,
    /// Samples per pixel summed.
    pub samples: u32,
}

impl GuideBuffer {
    /// Empty sums.
    pub fn new(width: u32, height: u32) -> Self {
        let n = (width * height) as usize;
        GuideBuffer {
            width,
            height,
            albedo: vec![[0.0; 3]; n],
            normal: vec![[0.0; 3]; n],
            depth: vec![0.0; n],
            samples: 0,
        }
    }

    /// Whether [`GuideBuffer::merge`] would take `o`: the same size.
    pub fn check_shape(&self, o: &GuideBuffer) -> Result<(), String> {
        if (self.width, self.height) != (o.width, o.height) {
            return Err(format!(
                "guide buffers differ in size: {}x{} vs {}x{}",
                self.width, self.height, o.width, o.height
            ));
        }
        Ok(())
    }

    /// Whether every sum is +0.0 (bit for bit: a −0.0 is not, so leaving such a buffer out of
    /// an upload and decoding it as [`GuideBuffer::new`] loses nothing).
    pub fn is_zero(&self) -> bool {
        self.albedo.iter().chain(&self.normal).flatten().chain(&self.depth).all(|v| v.to_bits() == 0)
    }

    /// Adds another buffer of the same size.
    pub fn merge(&mut self, o: &GuideBuffer) -> Result<(), String> {
        self.check_shape(o)?;
        for (a, b) in self.albedo.iter_mut().zip(&o.albedo) {
            *a = [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
        }
        for (a, b) in self.normal.iter_mut().zip(&o.normal) {
            *a = [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
        }
        for (a, b) in self.depth.iter_mut().zip(&o.depth) {
            *a += b;
        }
        self.samples += o.samples;
        Ok(())
    }

    /// Per-pixel means: (albedo, unit normal or zero, depth).
    pub fn means(&self) -> (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<f32>) {
        let k = self.samples.max(1) as f32;
        let albedo = self.albedo.iter().map(|a| [a[0] / k, a[1] / k, a[2] / k]).collect();
        let normal = self
            .normal
            .iter()
            .map(|n| {
                let v = glam::Vec3::from_array(*n).normalize_or_zero();
                v.to_array()
            })
            .collect();
        let depth = self.depth.iter().map(|d| d / k).collect();
        (albedo, normal, depth)
    }
}

/// Values per pixel: albedo (3), normal (3), distance.
const PER_PIXEL: usize = 7;

/// Sums the guides of the camera paths of the iterations in a range (a sample observer).
pub struct GuideCollector {
    width: u32,
    height: u32,
    iterations: Range<u32>,
    active: AtomicBool,
    /// f32 bits, [`PER_PIXEL`] per pixel; empty when no iteration is kept.
    sums: Vec<AtomicU32>,
    samples: AtomicU32,
}

impl GuideCollector {
    /// A collector for a `width × height` image that keeps the iterations in `iterations`.
    pub fn new(width: u32, height: u32, iterations: Range<u32>) -> Self {
        let len = if iterations.is_empty() { 0 } else { width as usize * height as usize * PER_PIXEL };
        GuideCollector {
            width,
            height,
            iterations,
            active: AtomicBool::new(false),
            sums: (0..len).map(|_| AtomicU32::new(0)).collect(),
            samples: AtomicU32::new(0),
        }
    }

    /// The sums collected.
    pub fn into_buffer(self) -> GuideBuffer {
        let mut out = GuideBuffer::new(self.width, self.height);
        out.samples = self.samples.into_inner();
        for (i, v) in self.sums.chunks_exact(PER_PIXEL).enumerate() {
            let v: [f32; PER_PIXEL] = std::array::from_fn(|k| f32::from_bits(v[k].load(Ordering::Relaxed)));
            out.albedo[i] = [v[0], v[1], v[2]];
            out.normal[i] = [v[3], v[4], v[5]];
            out.depth[i] = v[6];
        }
        out
    }
}

impl SampleObserver for GuideCollector {
    #[inline(always)]
    fn on_sample(&self, _record: &SampleRecord) {}

    fn on_iteration_start(&self, start: &IterationStart) {
        let active = self.iterations.contains(&start.iteration);
        self.active.store(active, Ordering::Relaxed);
        if active {
            self.samples.fetch_add(1, Ordering::Relaxed);
        }
    }

    #[inline]
    fn on_primary_hit(&self, hit: &PrimaryHit) {
        if !self.active.load(Ordering::Relaxed) {
            return;
        }
        let values = [hit.albedo.x, hit.albedo.y, hit.albedo.z, hit.normal.x, hit.normal.y, hit.normal.z, hit.distance];
        let base = hit.pixel as usize * PER_PIXEL;
        for (slot, v) in self.sums[base..base + PER_PIXEL].iter().zip(values) {
            // one camera path per pixel and iteration, iterations one after another: one writer
            let old = f32::from_bits(slot.load(Ordering::Relaxed));
            slot.store((old + v).to_bits(), Ordering::Relaxed);
        }
    }
}
