//! Mitsuba's `checkerboard` texture (`src/textures/checkerboard.cpp`): one period per uv unit
//! after `to_uv`, `color0` where frac(u') > ½ and frac(v') > ½ agree (so at uv (0,0)), `color1`
//! elsewhere. `color0` and `color1` are any [`Texture`] (Mitsuba allows nested textures too),
//! evaluated at the original point; defaults 0.4 and 0.2.
//!
//! Mitsuba's `eval_1` (scalar uses such as `mask.opacity`) swaps the two: it returns `color0`
//! where the tests **differ**. [`Checkerboard::eval_1`] reproduces that, since scenes rendered by
//! Mitsuba show it.

use super::{Texture, TexturePoint, UvTransform};
use crate::math::Rgb;

/// A two-texture checkerboard.
#[derive(Clone, Debug)]
pub struct Checkerboard {
    color0: Box<Texture>,
    color1: Box<Texture>,
    to_uv: UvTransform,
}

impl Default for Checkerboard {
    /// Mitsuba's defaults: `color0` 0.4, `color1` 0.2, identity `to_uv`.
    fn default() -> Self {
        Checkerboard::new(Texture::uniform(0.4), Texture::uniform(0.2), UvTransform::IDENTITY)
    }
}

impl Checkerboard {
    /// A checkerboard of two textures.
    pub fn new(color0: Texture, color1: Texture, to_uv: UvTransform) -> Self {
        Checkerboard { color0: Box::new(color0), color1: Box::new(color1), to_uv }
    }

    /// `color0`.
    pub fn color0(&self) -> &Texture {
        &self.color0
    }

    /// `color1`.
    pub fn color1(&self) -> &Texture {
        &self.color1
    }

    /// `to_uv`.
    pub fn to_uv(&self) -> UvTransform {
        self.to_uv
    }

    /// True where `eval` shows `color0`.
    #[inline]
    fn is_color0(&self, p: &TexturePoint) -> bool {
        let uv = self.to_uv.apply(p.uv);
        let a = uv.x - uv.x.floor() > 0.5;
        let b = uv.y - uv.y.floor() > 0.5;
        a == b
    }

    /// The colour at `p`.
    #[inline]
    pub fn eval(&self, p: &TexturePoint) -> Rgb {
        if self.is_color0(p) { self.color0.eval(p) } else { self.color1.eval(p) }
    }

    /// The scalar at `p`, with Mitsuba's inverted test (see the module doc).
    #[inline]
    pub fn eval_1(&self, p: &TexturePoint) -> f32 {
        if self.is_color0(p) { self.color1.eval_1(p) } else { self.color0.eval_1(p) }
    }

    /// Mitsuba's `mean()`: the average of the two textures' means.
    pub fn mean(&self) -> Option<f32> {
        Some(0.5 * (self.color0.mean()? + self.color1.mean()?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    #[test]
    fn checkerboard_color0_at_origin_and_eval_1_inverted() {
        let c = Checkerboard::default();
        let at = |u, v| TexturePoint::uv(Vec2::new(u, v));
        assert_eq!(c.eval(&at(0.1, 0.1)), Rgb::splat(0.4));
        assert_eq!(c.eval(&at(0.6, 0.1)), Rgb::splat(0.2));
        assert_eq!(c.eval(&at(0.6, 0.7)), Rgb::splat(0.4));
        assert_eq!(c.eval(&at(-0.1, 0.1)), Rgb::splat(0.2));
        // Mitsuba 3.9.1, default board at (0.1, 0.1): eval 0.4, eval_1 0.2
        assert_eq!(c.eval_1(&at(0.1, 0.1)), 0.2);
        assert_eq!(c.eval_1(&at(0.6, 0.1)), 0.4);
        assert!((c.mean().unwrap() - 0.3).abs() < 1e-7);
    }
}
