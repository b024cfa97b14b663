//! How many connections to cached light vertices a camera vertex makes: the same count
//! everywhere (`bdpt`, `vcm`, EMIS with an image-level c), or an expected count per pixel
//! (EMIS's per-pixel connections, docs/emis.md §5.6) that each camera vertex rounds
//! stochastically: 1.7 makes 2 connections with probability 0.7 and 1 otherwise.
//!
//! The MIS weights use the expected count as the sample count (the connection density is
//! c_j·N/|cache|) and each connection is divided by it, so the rounding keeps every
//! technique unbiased.

use crate::sampler::Sampler;
use std::sync::Arc;

/// The largest per-pixel expected count accepted (the largest candidate is 8).
pub const MAX_PER_PIXEL: f32 = 64.0;

/// Connections per camera vertex.
#[derive(Clone, Debug, PartialEq)]
pub enum Connections {
    /// The same count at every camera vertex.
    Fixed(u32),
    /// An expected count per pixel (row-major), rounded stochastically at each camera vertex.
    PerPixel(Arc<Vec<f32>>),
}

impl Connections {
    /// The expected count at a camera vertex of `pixel` (0 outside the mask).
    #[inline]
    pub fn at(&self, pixel: u32) -> f32 {
        match self {
            Connections::Fixed(c) => *c as f32,
            Connections::PerPixel(m) => m.get(pixel as usize).copied().unwrap_or(0.0),
        }
    }

    /// The number of connections one camera vertex of `pixel` makes. A fixed count draws no
    /// sample; a per-pixel one draws one dimension at every vertex, whatever its value, so
    /// that the dimensions a path uses depend on the mask's kind only.
    #[inline]
    pub fn draw(&self, pixel: u32, sampler: &mut Sampler) -> u32 {
        match self {
            Connections::Fixed(c) => *c,
            Connections::PerPixel(_) => round_stochastically(self.at(pixel), sampler.next_1d()),
        }
    }

    /// The mean expected count over `pixels` pixels.
    pub fn mean(&self, pixels: usize) -> f64 {
        match self {
            Connections::Fixed(c) => *c as f64,
            Connections::PerPixel(m) if pixels > 0 => m.iter().map(|&c| c as f64).sum::<f64>() / pixels as f64,
            Connections::PerPixel(_) => 0.0,
        }
    }

    /// Checks a per-pixel mask from outside the process: `pixels` values, each finite, not
    /// negative and at most [`MAX_PER_PIXEL`].
    pub fn check_mask(mask: &[f32], pixels: usize) -> Result<(), String> {
        if mask.len() != pixels {
            return Err(format!("connection mask has {} values for {pixels} pixels", mask.len()));
        }
        match mask.iter().position(|c| !(0.0..=MAX_PER_PIXEL).contains(c)) {
            Some(i) => Err(format!("connection mask value {} at pixel {i} is outside 0..={MAX_PER_PIXEL}", mask[i])),
            None => Ok(()),
        }
    }
}

/// ⌊c⌋ + 1 with probability c − ⌊c⌋, else ⌊c⌋, for `u` uniform in [0, 1).
#[inline]
pub fn round_stochastically(c: f32, u: f32) -> u32 {
    let floor = c.floor();
    floor as u32 + u32::from(u < c - floor)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stochastic_rounding_has_the_expected_count_as_its_mean() {
        for c in [0.0f32, 0.25, 1.0, 1.7, 3.5, 8.0] {
            let n = 10_000;
            let sum: u32 = (0..n).map(|i| round_stochastically(c, (i as f32 + 0.5) / n as f32)).sum();
            assert!((sum as f32 / n as f32 - c).abs() < 1e-3, "c {c}: mean {}", sum as f32 / n as f32);
            assert!((0..n).all(|i| {
                let k = round_stochastically(c, i as f32 / n as f32);
                k == c.floor() as u32 || k == c.ceil() as u32
            }));
        }
    }

    #[test]
    fn a_fixed_count_draws_no_sample_and_a_mask_one_per_vertex() {
        let mut a = Sampler::for_pixel(1, 2, 3);
        let mut b = Sampler::for_pixel(1, 2, 3);
        assert_eq!(Connections::Fixed(3).draw(0, &mut a), 3);
        assert_eq!(a.next_1d(), b.next_1d(), "no dimension used");
        let mask = Connections::PerPixel(Arc::new(vec![2.0, 0.5]));
        assert_eq!(mask.draw(0, &mut a), 2);
        b.next_1d();
        assert_eq!(a.next_1d(), b.next_1d(), "one dimension used");
        assert_eq!((mask.at(1), mask.at(7)), (0.5, 0.0));
        assert!((mask.mean(2) - 1.25).abs() < 1e-12);
    }

    #[test]
    fn masks_from_outside_are_checked() {
        assert!(Connections::check_mask(&[0.0, 8.0, 64.0], 3).is_ok());
        assert!(Connections::check_mask(&[0.0, 8.0], 3).unwrap_err().contains("2 values for 3"));
        for bad in [-0.5, f32::NAN, f32::INFINITY, 65.0] {
            assert!(Connections::check_mask(&[1.0, bad], 2).unwrap_err().contains("at pixel 1"), "{bad}");
        }
    }
}
