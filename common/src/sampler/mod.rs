//! Deterministic samplers. Every random number is a pure function of (job seed, sample
//! identity, dimension): the identity is a pixel and sample index for camera paths, or a
//! light-path index and iteration for light paths. No RNG state crosses samples, threads or
//! machines, so any tile renders bit-identically anywhere.

use crate::math::hash::{bits_to_unit_f32, hash_words, mix64};
use glam::Vec2;

/// Domain tags keep camera and light-path streams independent even for equal indices.
const DOMAIN_CAMERA: u64 = 0x43414d;
const DOMAIN_LIGHT: u64 = 0x4c4954;

/// The closed set of samplers (Mitsuba's `independent` is the only one so far).
#[derive(Clone, Debug)]
pub enum Sampler {
    /// Independent uniform numbers per dimension.
    Independent(IndependentSampler),
}

impl Sampler {
    /// Sampler for camera sample `sample_index` of pixel `pixel_index`.
    #[inline]
    pub fn for_pixel(seed: u64, pixel_index: u32, sample_index: u32) -> Self {
        Sampler::Independent(IndependentSampler::new(hash_words(&[
            DOMAIN_CAMERA,
            seed,
            pixel_index as u64,
            sample_index as u64,
        ])))
    }

    /// Sampler for light path `path_index` of iteration `iteration`.
    #[inline]
    pub fn for_light_path(seed: u64, path_index: u32, iteration: u32) -> Self {
        Sampler::Independent(IndependentSampler::new(hash_words(&[
            DOMAIN_LIGHT,
            seed,
            path_index as u64,
            iteration as u64,
        ])))
    }

    /// Next uniform number in [0, 1).
    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        match self {
            Sampler::Independent(s) => s.next_1d(),
        }
    }

    /// Next uniform point in [0, 1)².
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        let x = self.next_1d();
        Vec2::new(x, self.next_1d())
    }
}

/// Independent sampler: dimension `d` of key `k` is `hash(k, d)`.
#[derive(Clone, Debug)]
pub struct IndependentSampler {
    key: u64,
    dimension: u64,
}

impl IndependentSampler {
    /// A sampler whose stream is determined entirely by `key`.
    pub fn new(key: u64) -> Self {
        IndependentSampler { key, dimension: 0 }
    }

    /// Next uniform number in [0, 1).
    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        let bits = mix64(self.key.wrapping_add(self.dimension.wrapping_mul(0x9e37_79b9_7f4a_7c15)));
        self.dimension += 1;
        bits_to_unit_f32(bits)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sampler_is_a_pure_function_of_its_identity() {
        let a: Vec<f32> = {
            let mut s = Sampler::for_pixel(7, 100, 3);
            (0..16).map(|_| s.next_1d()).collect()
        };
        let b: Vec<f32> = {
            let mut s = Sampler::for_pixel(7, 100, 3);
            (0..16).map(|_| s.next_1d()).collect()
        };
        let c: Vec<f32> = {
            let mut s = Sampler::for_pixel(8, 100, 3);
            (0..16).map(|_| s.next_1d()).collect()
        };
        let d: Vec<f32> = {
            let mut s = Sampler::for_light_path(7, 100, 3);
            (0..16).map(|_| s.next_1d()).collect()
        };
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert_ne!(a, d);
    }

    #[test]
    fn sampler_moments_are_uniform() {
        let n = 200_000;
        let (mut m1, mut m2, mut corr) = (0.0f64, 0.0f64, 0.0f64);
        for i in 0..n {
            let mut s = Sampler::for_pixel(1, i, 0);
            let (x, y) = (s.next_1d() as f64, s.next_1d() as f64);
            assert!((0.0..1.0).contains(&x));
            m1 += x;
            m2 += x * x;
            corr += (x - 0.5) * (y - 0.5);
        }
        let n = n as f64;
        // standard errors: mean 0.29/sqrt(n), second moment 0.30/sqrt(n), covariance 0.083/sqrt(n)
        assert!((m1 / n - 0.5).abs() < 5.0 * 0.29 / n.sqrt());
        assert!((m2 / n - 1.0 / 3.0).abs() < 5.0 * 0.30 / n.sqrt());
        assert!((corr / n).abs() < 5.0 * 0.084 / n.sqrt());
    }
}
