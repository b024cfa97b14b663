//! Rays and the origin offset that keeps spawned rays from re-hitting their own surface.

use crate::math::RAY_EPSILON;
use glam::Vec3;

/// A ray `o + t·d` for `t` in `(0, tmax)`. `d` is unit length.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin.
    pub o: Vec3,
    /// Unit direction.
    pub d: Vec3,
    /// Largest distance of interest.
    pub tmax: f32,
}

impl Ray {
    /// A ray of unbounded length.
    #[inline]
    pub fn new(o: Vec3, d: Vec3) -> Self {
        Ray { o, d, tmax: f32::INFINITY }
    }

    /// Point at distance `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.o + self.d * t
    }
}

/// Moves `p` off its surface along the geometric normal `n`, to the side `d` points to, by an
/// amount proportional to the magnitude of `p` (Mitsuba's `offset_p`).
#[inline]
pub fn offset_ray_origin(p: Vec3, n: Vec3, d: Vec3) -> Vec3 {
    let mag = (1.0 + p.abs().max_element()) * RAY_EPSILON;
    let mag = if n.dot(d) >= 0.0 { mag } else { -mag };
    p + n * mag
}
