//! Dielectric interfaces: smooth (`dielectric`), rough (`roughdielectric`, Walter et al. 2007,
//! "Microfacet models for refraction through rough surfaces") and thin sheets
//! (`thindielectric`). The interior is the side opposite the normal; `eta` = interior /
//! exterior index. In radiance transport, refraction scales by 1/η² (η = n_t / n_i).

use super::fresnel::{fresnel_dielectric, reflect, reflect_z, refract};
use super::microfacet::Microfacet;
use super::{BsdfSample, TransportMode};
use crate::math::Rgb;
use glam::{Vec2, Vec3};

#[inline]
fn radiance_scale(mode: TransportMode, eta_ti: f32) -> f32 {
    match mode {
        TransportMode::Radiance => 1.0 / (eta_ti * eta_ti),
        TransportMode::Importance => 1.0,
    }
}

/// Smooth dielectric: specular reflection with probability F, refraction otherwise.
#[derive(Clone, Debug, PartialEq)]
pub struct Dielectric {
    /// Interior / exterior index of refraction.
    pub eta: f32,
    /// Multiplier on reflection.
    pub specular_reflectance: Rgb,
    /// Multiplier on transmission.
    pub specular_transmittance: Rgb,
}

impl Dielectric {
    pub(super) fn sample(&self, wo: Vec3, uc: f32, _u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let (f, cos_t, eta_ti) = fresnel_dielectric(wo.z, self.eta);
        if uc < f {
            Some(BsdfSample::delta(reflect_z(wo), self.specular_reflectance, f, 1.0, false))
        } else {
            let wi = Vec3::new(-wo.x / eta_ti, -wo.y / eta_ti, cos_t);
            let weight = self.specular_transmittance * radiance_scale(mode, eta_ti);
            Some(BsdfSample::delta(wi, weight, 1.0 - f, eta_ti, true))
        }
    }

    pub(super) fn eval(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> Rgb {
        Rgb::ZERO
    }

    pub(super) fn pdf(&self, _wo: Vec3, _wi: Vec3) -> f32 {
        0.0
    }
}

/// Thin dielectric sheet: reflection with the multiply-reflected Fresnel term, transmission
/// straight through (no refraction: the two interfaces cancel).
#[derive(Clone, Debug, PartialEq)]
pub struct ThinDielectric {
    /// Index of the sheet relative to its surroundings.
    pub eta: f32,
    /// Multiplier on reflection.
    pub specular_reflectance: Rgb,
    /// Multiplier on transmission.
    pub specular_transmittance: Rgb,
}

impl ThinDielectric {
    fn reflectance(&self, cos_theta: f32) -> f32 {
        let r = fresnel_dielectric(cos_theta.abs(), self.eta).0;
        if r < 1.0 { r + (1.0 - r) * (1.0 - r) * r / (1.0 - r * r) } else { 1.0 }
    }

    pub(super) fn sample(&self, wo: Vec3, uc: f32, _u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        let r = self.reflectance(wo.z);
        if uc < r {
            Some(BsdfSample::delta(reflect_z(wo), self.specular_reflectance, r, 1.0, false))
        } else {
            Some(BsdfSample::delta(-wo, self.specular_transmittance, 1.0 - r, 1.0, true))
        }
    }

    pub(super) fn eval(&self, _wo: Vec3, _wi: Vec3, _mode: TransportMode) -> Rgb {
        Rgb::ZERO
    }

    pub(super) fn pdf(&self, _wo: Vec3, _wi: Vec3) -> f32 {
        0.0
    }
}

/// Rough dielectric interface.
#[derive(Clone, Debug, PartialEq)]
pub struct RoughDielectric {
    /// Microfacet distribution.
    pub distribution: Microfacet,
    /// Interior / exterior index of refraction.
    pub eta: f32,
    /// Multiplier on reflection.
    pub specular_reflectance: Rgb,
    /// Multiplier on transmission.
    pub specular_transmittance: Rgb,
}

/// The generalised half vector of a pair of directions, oriented to +z, and the relative index
/// used to build it (1 for reflection).
#[inline]
fn half_vector(wo: Vec3, wi: Vec3, eta: f32) -> Option<(Vec3, f32, bool)> {
    let reflection = wo.z * wi.z > 0.0;
    let eta_rel = if reflection {
        1.0
    } else if wo.z > 0.0 {
        eta
    } else {
        1.0 / eta
    };
    let m = (wi * eta_rel + wo).try_normalize()?;
    let m = if m.z < 0.0 { -m } else { m };
    // discard microfacets that face away from either direction
    if m.dot(wi) * wi.z <= 0.0 || m.dot(wo) * wo.z <= 0.0 {
        return None;
    }
    Some((m, eta_rel, reflection))
}

impl RoughDielectric {
    pub(super) fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let m = self.distribution.sample(wo, u);
        let f = fresnel_dielectric(wo.dot(m), self.eta).0;
        let (wi, eta) = if uc < f {
            let wi = reflect(wo, m);
            if wi.z * wo.z <= 0.0 {
                return None;
            }
            (wi, 1.0)
        } else {
            let (wi, eta_ti) = refract(wo, m, self.eta)?;
            if wi.z * wo.z >= 0.0 {
                return None;
            }
            (wi, eta_ti)
        };
        BsdfSample::smooth(wo, wi, self.eval(wo, wi, mode), self.pdf(wo, wi), eta)
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        if wo.z == 0.0 || wi.z == 0.0 {
            return Rgb::ZERO;
        }
        let Some((m, eta_rel, reflection)) = half_vector(wo, wi, self.eta) else { return Rgb::ZERO };
        let d = self.distribution.d(m);
        let g = self.distribution.g(wi, wo, m);
        let f = fresnel_dielectric(wo.dot(m), self.eta).0;
        if reflection {
            self.specular_reflectance * (f * d * g / (4.0 * wo.z * wi.z).abs())
        } else {
            let denom = wi.dot(m) + wo.dot(m) / eta_rel;
            let v = d * g * (1.0 - f) * (wi.dot(m) * wo.dot(m) / (denom * denom * wi.z * wo.z)).abs();
            self.specular_transmittance * (v * radiance_scale(mode, eta_rel))
        }
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z == 0.0 || wi.z == 0.0 {
            return 0.0;
        }
        let Some((m, eta_rel, reflection)) = half_vector(wo, wi, self.eta) else { return 0.0 };
        let f = fresnel_dielectric(wo.dot(m), self.eta).0;
        let pdf_m = self.distribution.pdf(wo, m);
        if reflection {
            pdf_m * f / (4.0 * wo.dot(m).abs())
        } else {
            let denom = wi.dot(m) + wo.dot(m) / eta_rel;
            pdf_m * (1.0 - f) * wi.dot(m).abs() / (denom * denom)
        }
    }
}
