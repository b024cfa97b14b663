//! Sample warps: maps from the unit square to directions and points, each with its pdf.
//! The pdfs name their measure (solid angle or area) in their doc comment.

use super::{INV_FOUR_PI, INV_PI, PI, safe_sqrt};
use glam::{Vec2, Vec3};

/// Concentric map of the unit square to the unit disk (Shirley and Chiu 1997).
pub fn square_to_disk_concentric(u: Vec2) -> Vec2 {
    let a = 2.0 * u - Vec2::ONE;
    if a.x == 0.0 && a.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, phi) = if a.x.abs() > a.y.abs() {
        (a.x, std::f32::consts::FRAC_PI_4 * (a.y / a.x))
    } else {
        (a.y, std::f32::consts::FRAC_PI_2 - std::f32::consts::FRAC_PI_4 * (a.x / a.y))
    };
    Vec2::new(r * phi.cos(), r * phi.sin())
}

/// Cosine-weighted direction on the +z hemisphere (Malley's method).
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = square_to_disk_concentric(u);
    let z = safe_sqrt(1.0 - d.length_squared());
    Vec3::new(d.x, d.y, z)
}

/// Solid-angle pdf of [`square_to_cosine_hemisphere`].
#[inline]
pub fn cosine_hemisphere_pdf(v: Vec3) -> f32 {
    if v.z > 0.0 { v.z * INV_PI } else { 0.0 }
}

/// Uniform direction on the unit sphere.
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = safe_sqrt(1.0 - z * z);
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Solid-angle pdf of [`square_to_uniform_sphere`].
#[inline]
pub fn uniform_sphere_pdf() -> f32 {
    INV_FOUR_PI
}

/// Uniform direction inside the cone of half-angle `acos(cos_max)` around +z.
pub fn square_to_uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let cos_theta = (1.0 - u.x) + u.x * cos_max;
    let sin_theta = safe_sqrt(1.0 - cos_theta * cos_theta);
    let phi = 2.0 * PI * u.y;
    Vec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), cos_theta)
}

/// Solid-angle pdf of [`square_to_uniform_cone`] for directions inside the cone.
#[inline]
pub fn uniform_cone_pdf(cos_max: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_max))
}

/// Uniform barycentric coordinates `(b1, b2)` on a triangle (b0 = 1 − b1 − b2), by the
/// square-root parameterisation.
pub fn square_to_uniform_triangle(u: Vec2) -> Vec2 {
    let su = u.x.sqrt();
    Vec2::new(1.0 - su, u.y * su)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warps_land_on_their_domain() {
        for i in 0..64 {
            for j in 0..64 {
                let u = Vec2::new(i as f32 / 63.0, j as f32 / 63.0);
                assert!(square_to_disk_concentric(u).length() <= 1.0 + 1e-5);
                let c = square_to_cosine_hemisphere(u);
                assert!((c.length() - 1.0).abs() < 1e-4 && c.z >= 0.0);
                assert!((square_to_uniform_sphere(u).length() - 1.0).abs() < 1e-4);
                let cone = square_to_uniform_cone(u, 0.9);
                assert!(cone.z >= 0.9 - 1e-5);
                let b = square_to_uniform_triangle(u);
                assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6);
            }
        }
    }
}
