//! Small numeric building blocks shared by the whole renderer: colour type, orthonormal frames,
//! sample warps, and counter-based hashing for deterministic random numbers.

pub mod frame;
pub mod hash;
pub mod warp;

pub use frame::Frame;

/// Linear RGB triple used for radiance, reflectance and importance. In Mitsuba's `*_rgb`
/// variants colours are plain triples with no spectral conversion, so ours are too.
pub type Rgb = glam::Vec3;

/// π as f32.
pub const PI: f32 = std::f32::consts::PI;
/// 1/π as f32.
pub const INV_PI: f32 = std::f32::consts::FRAC_1_PI;
/// 1/(4π): the pdf of a uniformly sampled sphere direction.
pub const INV_FOUR_PI: f32 = 0.25 * std::f32::consts::FRAC_1_PI;

/// Mitsuba's `RayEpsilon` (89 ulp of 1.0 in f32): scale of the offset that moves spawned rays
/// off their surface.
pub const RAY_EPSILON: f32 = 89.0 * f32::EPSILON * 0.5;
/// Relative shortening of shadow rays so that they do not hit the surface they aim at.
pub const SHADOW_EPSILON: f32 = RAY_EPSILON * 10.0;

/// Largest channel of a colour.
#[inline]
pub fn max_component(c: Rgb) -> f32 {
    c.x.max(c.y).max(c.z)
}

/// Mean of the three channels.
#[inline]
pub fn mean(c: Rgb) -> f32 {
    (c.x + c.y + c.z) * (1.0 / 3.0)
}

/// Rec. 709 luminance of linear RGB.
#[inline]
pub fn luminance(c: Rgb) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// True when every channel is finite.
#[inline]
pub fn is_finite(c: Rgb) -> bool {
    c.is_finite()
}

/// `sqrt(max(x, 0))`: square roots of quantities that are mathematically non-negative but can
/// round below zero.
#[inline]
pub fn safe_sqrt(x: f32) -> f32 {
    x.max(0.0).sqrt()
}
