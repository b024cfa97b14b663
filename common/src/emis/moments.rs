//! Moment buffers (docs/emis.md, D2): per pixel × candidate, the sum of δ·w2 over all
//! pilot samples, kept as an unnormalised sum with an iteration count, so that buffers from
//! different workers add up. A candidate that cannot sample a pixel's path is flagged by an
//! infinite sum: every term is non-negative, so a flag stays infinite through any merge and
//! never becomes NaN. Sums are f32 (4 bytes per pixel and candidate: 13 MB for 51 candidates at
//! 256²).

use super::delta::Delta;

/// Second-moment sums of all candidates for every pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct MomentBuffer {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Number of candidates.
    pub candidates: usize,
    /// Σ δ·w2, indexed `pixel * candidates + candidate`; +∞ where the candidate cannot sample
    /// some path of the pixel.
    pub sums: Vec<f32>,
    /// Iterations accumulated.
    pub iterations: u32,
}

impl MomentBuffer {
    /// An empty buffer.
    pub fn new(width: u32, height: u32, candidates: usize) -> Self {
        let n = width as usize * height as usize * candidates;
        MomentBuffer { width, height, candidates, sums: vec![0.0; n], iterations: 0 }
    }

    /// Adds one sample's contribution `w2` (the squared, channel-averaged, MIS-weighted
    /// contribution) to candidate `candidate` of `pixel`, corrected by `delta`.
    #[inline]
    pub fn add(&mut self, pixel: u32, candidate: usize, delta: Delta, w2: f64) {
        let i = pixel as usize * self.candidates + candidate;
        match delta {
            Delta::Finite(d) => self.sums[i] += (d * w2) as f32,
            Delta::Infinite => self.sums[i] = f32::INFINITY,
        }
    }

    /// Adds another buffer of the same shape (another worker's iterations).
    pub fn merge(&mut self, other: &MomentBuffer) -> Result<(), String> {
        self.check_shape(other)?;
        for (a, b) in self.sums.iter_mut().zip(&other.sums) {
            *a += b;
        }
        self.iterations += other.iterations;
        Ok(())
    }

    /// Rounds every sum to bfloat16 (8 significant bits, at most 0.4 % off), the precision
    /// in which pilot data crosses the wire: every call's sums are rounded, locally as on a
    /// worker, so that a farm's merged moments equal a local render's bit for bit while an
    /// upload carries 2 bytes per candidate instead of 4 (docs/decisions/0019-compact-pilot-data.md).
    pub fn round_for_wire(&mut self) {
        use rayon::prelude::*;
        self.sums.par_iter_mut().for_each(|s| *s = from_bf16_bits(bf16_bits(*s)));
    }

    /// Whether [`MomentBuffer::merge`] would take `other`: the same size and candidates.
    pub fn check_shape(&self, other: &MomentBuffer) -> Result<(), String> {
        if (self.width, self.height, self.candidates) != (other.width, other.height, other.candidates) {
            return Err(format!(
                "moment buffers differ in shape: {}x{}x{} vs {}x{}x{}",
                self.width, self.height, self.candidates, other.width, other.height, other.candidates
            ));
        }
        Ok(())
    }

    /// The per-iteration second moment of `candidate` at `pixel`: +∞ when flagged, 0 before
    /// any iteration.
    #[inline]
    pub fn moment(&self, pixel: u32, candidate: usize) -> f64 {
        let i = pixel as usize * self.candidates + candidate;
        if self.iterations == 0 && self.sums[i].is_finite() {
            0.0
        } else {
            self.sums[i] as f64 / self.iterations as f64
        }
    }
}

/// The bfloat16 nearest to `x` (ties to even), as bits. A finite `x` too large for it stays
/// finite (the largest bfloat16): +∞ flags a candidate that cannot sample a path, which
/// rounding must not invent.
pub(super) fn bf16_bits(x: f32) -> u16 {
    let b = half::bf16::from_f32(x);
    if x.is_finite() && b.is_infinite() { half::bf16::MAX.copysign(b).to_bits() } else { b.to_bits() }
}

/// The f32 of bfloat16 `bits` (exact).
pub(super) fn from_bf16_bits(bits: u16) -> f32 {
    half::bf16::from_bits(bits).to_f32()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::Sampler;

    /// Simulated pilot iterations: deterministic samples per (seed, iteration).
    fn run(buffer: &mut MomentBuffer, seed: u64, iterations: std::ops::Range<u32>) {
        for it in iterations {
            for pixel in 0..buffer.width * buffer.height {
                let mut s = Sampler::for_pixel(seed, pixel, it);
                for c in 0..buffer.candidates {
                    let d = if s.next_1d() < 0.01 { Delta::Infinite } else { Delta::Finite(s.next_1d() as f64 * 3.0) };
                    buffer.add(pixel, c, d, (s.next_1d() as f64).powi(2));
                }
            }
            buffer.iterations += 1;
        }
    }

    #[test]
    fn merging_two_workers_equals_one_run_with_both() {
        let mut one = MomentBuffer::new(8, 4, 5);
        run(&mut one, 1, 0..10);
        let mut first = MomentBuffer::new(8, 4, 5);
        let mut second = MomentBuffer::new(8, 4, 5);
        run(&mut first, 1, 0..6);
        run(&mut second, 1, 6..10);
        first.merge(&second).unwrap();
        assert_eq!(first.iterations, one.iterations);
        for (a, b) in first.sums.iter().zip(&one.sums) {
            assert_eq!(a.is_infinite(), b.is_infinite());
            if b.is_finite() {
                assert!((a - b).abs() <= 1e-6 * b.abs().max(1e-12), "{a} vs {b}");
            }
        }
        assert!(first.merge(&MomentBuffer::new(4, 4, 5)).is_err());
    }

    #[test]
    fn rounding_for_the_wire_keeps_eight_bits_and_the_flags() {
        let mut b = MomentBuffer::new(2, 1, 3);
        b.sums = vec![0.0, 1.0 + 1.0 / 256.0, f32::INFINITY, f32::MAX, 3.0e-30, 1.0 + 3.0 / 256.0];
        b.round_for_wire();
        // a tie goes to the even neighbour; the largest finite sum stays finite
        assert_eq!(b.sums[..3], [0.0, 1.0, f32::INFINITY]);
        assert!(b.sums[3].is_finite() && b.sums[3] > 3.3e38);
        assert!((b.sums[4] - 3.0e-30).abs() <= 3.0e-30 / 256.0);
        assert_eq!(b.sums[5], 1.0 + 4.0 / 256.0);
        let mut twice = b.clone();
        twice.round_for_wire();
        assert_eq!(twice, b);
    }

    #[test]
    fn infinite_candidates_are_flagged_not_nan() {
        let mut b = MomentBuffer::new(1, 1, 2);
        b.add(0, 0, Delta::Infinite, 1.0);
        b.add(0, 1, Delta::Finite(2.0), 0.5);
        b.iterations = 1;
        assert_eq!(b.moment(0, 0), f64::INFINITY);
        assert_eq!(b.moment(0, 1), 1.0);
        assert!(!b.sums.iter().any(|v| v.is_nan()));
    }
}
