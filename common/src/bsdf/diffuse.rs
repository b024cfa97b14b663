//! Lambertian reflection (Mitsuba `diffuse`): one-sided, `f = R / π` when both directions are
//! above the surface.

use super::{BsdfSample, TransportMode};
use crate::math::{INV_PI, Rgb, warp};
use glam::{Vec2, Vec3};

/// Lambertian BRDF with reflectance `reflectance`.
#[derive(Clone, Debug, PartialEq)]
pub struct Diffuse {
    /// Albedo per channel, in [0, 1].
    pub reflectance: Rgb,
}

impl Diffuse {
    pub(super) fn sample(&self, wo: Vec3, _uc: f32, u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = warp::square_to_cosine_hemisphere(u);
        if wi.z <= 0.0 {
            return None;
        }
        let pdf = warp::cosine_hemisphere_pdf(wi);
        let mut s = BsdfSample::smooth(wo, wi, self.reflectance * INV_PI, pdf, 1.0)?;
        s.weight = self.reflectance; // exact, no rounding through pdf
        Some(s)
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z > 0.0 && wi.z > 0.0 { self.reflectance * INV_PI } else { Rgb::ZERO }
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z > 0.0 { warp::cosine_hemisphere_pdf(wi) } else { 0.0 }
    }
}
