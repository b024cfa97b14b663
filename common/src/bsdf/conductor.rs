//! Conductors: the smooth mirror (`conductor`) and the microfacet model (`roughconductor`), both
//! with the exact conductor Fresnel term per RGB channel and one-sided like Mitsuba's.

use super::fresnel::{fresnel_conductor, reflect, reflect_z};
use super::microfacet::Microfacet;
use super::{BsdfSample, TransportMode};
use crate::math::Rgb;
use glam::{Vec2, Vec3};

/// Smooth conductor: a mirror whose reflectance follows the Fresnel equations.
#[derive(Clone, Debug, PartialEq)]
pub struct Conductor {
    /// Real part of the relative index of refraction.
    pub eta: Rgb,
    /// Imaginary part (absorption).
    pub k: Rgb,
    /// Multiplier on the reflectance.
    pub specular_reflectance: Rgb,
}

impl Conductor {
    pub(super) fn sample(&self, wo: Vec3, _uc: f32, _u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let weight = fresnel_conductor(wo.z, self.eta, self.k) * self.specular_reflectance;
        Some(BsdfSample::delta(reflect_z(wo), weight, 1.0, 1.0, false))
    }

    pub(super) fn eval(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> Rgb {
        Rgb::ZERO
    }

    pub(super) fn pdf(&self, _wo: Vec3, _wi: Vec3) -> f32 {
        0.0
    }
}

/// Rough conductor: `F(wo·h) D(h) G(wo, wi) / (4 cos θo cos θi)`.
#[derive(Clone, Debug, PartialEq)]
pub struct RoughConductor {
    /// Microfacet distribution.
    pub distribution: Microfacet,
    /// Real part of the relative index of refraction.
    pub eta: Rgb,
    /// Imaginary part (absorption).
    pub k: Rgb,
    /// Multiplier on the reflectance.
    pub specular_reflectance: Rgb,
}

impl RoughConductor {
    pub(super) fn sample(&self, wo: Vec3, _uc: f32, u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let m = self.distribution.sample(wo, u);
        let wi = reflect(wo, m);
        if wi.z <= 0.0 {
            return None;
        }
        // `eval` and `pdf` in one pass: the sampled normal is the half vector, and D(m) and
        // G1(wo, m) serve both the value and the density
        let d = self.distribution.d(m);
        if d == 0.0 {
            return None;
        }
        let g1_wo = self.distribution.g1(wo, m);
        let g = g1_wo * self.distribution.g1(wi, m);
        let wo_m = wo.dot(m);
        let f = fresnel_conductor(wo_m, self.eta, self.k) * self.specular_reflectance;
        let value = f * (d * g / (4.0 * wo.z * wi.z));
        let pdf = self.distribution.pdf_given(wo, m, d, g1_wo) / (4.0 * wo_m);
        BsdfSample::smooth(wo, wi, value, pdf, 1.0)
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        let Some(h) = (wo + wi).try_normalize() else { return Rgb::ZERO };
        let d = self.distribution.d(h);
        if d == 0.0 {
            return Rgb::ZERO;
        }
        let g = self.distribution.g(wi, wo, h);
        let f = fresnel_conductor(wo.dot(h), self.eta, self.k) * self.specular_reflectance;
        f * (d * g / (4.0 * wo.z * wi.z))
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let Some(h) = (wo + wi).try_normalize() else { return 0.0 };
        self.distribution.pdf(wo, h) / (4.0 * wo.dot(h))
    }
}
