//! The record of a ray hitting a surface: position, normals, shading frame and what was hit.

use crate::geometry::ray::{Ray, offset_ray_origin};
use crate::math::{Frame, SHADOW_EPSILON};
use glam::Vec3;

/// Which point of which shape: enough to evaluate textures there later (path vertices keep it
/// so that a textured material can be resolved again at connection time).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfaceRef {
    /// Index of the shape.
    pub shape: u32,
    /// Index of the primitive within the shape (triangle index; 0 for analytic shapes).
    pub prim: u32,
    /// Barycentric coordinates (b1, b2) on the triangle (zero for analytic shapes).
    pub bary: glam::Vec2,
}

/// A point on a surface as seen by an incoming ray.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceInteraction {
    /// Position.
    pub p: Vec3,
    /// Distance along the ray that found it.
    pub t: f32,
    /// Geometric normal (of the triangle or sphere, after `flip_normals`).
    pub n_geo: Vec3,
    /// Shading frame; its normal is the interpolated shading normal.
    pub frame: Frame,
    /// Unit direction back towards the ray origin, in world space.
    pub wo: Vec3,
    /// Index of the shape that was hit.
    pub shape: u32,
    /// Index of the primitive within the shape (triangle index; 0 for spheres).
    pub prim: u32,
    /// Barycentric coordinates (b1, b2) on the triangle (zero for analytic shapes).
    pub bary: glam::Vec2,
}

impl SurfaceInteraction {
    /// Which point of which shape was hit.
    #[inline]
    pub fn surface(&self) -> SurfaceRef {
        SurfaceRef { shape: self.shape, prim: self.prim, bary: self.bary }
    }

    /// A ray leaving this point in direction `d`, offset off the surface.
    #[inline]
    pub fn spawn_ray(&self, d: Vec3) -> Ray {
        Ray::new(offset_ray_origin(self.p, self.n_geo, d), d)
    }

    /// A shadow ray towards point `target` on a surface with normal `target_n` (zero for points
    /// off surfaces), both ends offset off their surfaces and shortened so that it stops just
    /// before the target.
    #[inline]
    pub fn shadow_ray_to(&self, target: Vec3, target_n: Vec3) -> Ray {
        let d = target - self.p;
        let o = offset_ray_origin(self.p, self.n_geo, d);
        let end = if target_n == Vec3::ZERO { target } else { offset_ray_origin(target, target_n, -d) };
        let delta = end - o;
        let len = delta.length();
        Ray { o, d: delta / len.max(f32::MIN_POSITIVE), tmax: len * (1.0 - SHADOW_EPSILON) }
    }
}
