//! BSDFs in the local shading frame (z = shading normal).
//!
//! Conventions: `wo` points towards where the path came from (the camera, for radiance
//! transport), `wi` is the other direction (sampled, or towards a light). `eval` returns the
//! BSDF value `f` **without** the cosine; `pdf` is in solid angle of `wi`; the reverse pdf is
//! `pdf(wi, wo)`. Delta lobes return zero from `eval`/`pdf` and are reached only by sampling,
//! where `pdf` is the discrete probability of the chosen lobe and `delta` is set.
//!
//! [`Material`] wraps a [`Bxdf`] with Mitsuba's `twosided` and `mask` semantics;
//! [`textured`] resolves materials whose parameters come from textures.

pub mod conductor;
pub mod dielectric;
pub mod diffuse;
pub mod fresnel;
pub mod microfacet;
pub mod plastic;
pub mod textured;

use crate::math::Rgb;
use glam::{Vec2, Vec3};

pub use conductor::{Conductor, RoughConductor};
pub use dielectric::{Dielectric, RoughDielectric, ThinDielectric};
pub use diffuse::Diffuse;
pub use microfacet::{Microfacet, MicrofacetKind};
pub use plastic::{CoatingKey, Plastic, RoughPlastic, coating_key};

/// Which quantity a path carries: radiance (camera paths) or importance (light paths). It
/// matters for refraction, where radiance is scaled by 1/η² and importance is not.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TransportMode {
    /// Camera subpaths.
    Radiance,
    /// Light subpaths.
    Importance,
}

/// A sampled direction.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// The sampled direction (local).
    pub wi: Vec3,
    /// `f(wo, wi)` without the cosine (for delta lobes: weight · pdf / |cos θi|).
    pub f: Rgb,
    /// Solid-angle pdf, or the discrete lobe probability for delta lobes.
    pub pdf: f32,
    /// `f · |cos θi| / pdf`: the throughput multiplier.
    pub weight: Rgb,
    /// Relative index of refraction crossed (n_t / n_i), 1 for reflection.
    pub eta: f32,
    /// Whether a delta (perfectly specular) lobe was sampled.
    pub delta: bool,
    /// Whether the direction crossed the surface.
    pub transmission: bool,
}

impl BsdfSample {
    /// A sample of a non-delta lobe, with `weight` derived from `f` and `pdf`.
    #[inline]
    pub fn smooth(wo: Vec3, wi: Vec3, f: Rgb, pdf: f32, eta: f32) -> Option<Self> {
        if !(pdf > 0.0) || !pdf.is_finite() {
            return None;
        }
        let weight = f * (wi.z.abs() / pdf);
        Some(BsdfSample { wi, f, pdf, weight, eta, delta: false, transmission: wo.z * wi.z < 0.0 })
    }

    /// A sample of a delta lobe chosen with probability `prob`, with throughput `weight`.
    #[inline]
    pub fn delta(wi: Vec3, weight: Rgb, prob: f32, eta: f32, transmission: bool) -> Self {
        let f = weight * (prob / wi.z.abs().max(1e-12));
        BsdfSample { wi, f, pdf: prob, weight, eta, delta: true, transmission }
    }
}

/// The closed set of BSDF models.
#[derive(Clone, Debug, PartialEq)]
pub enum Bxdf {
    /// Lambertian reflection.
    Diffuse(Diffuse),
    /// Smooth conductor (mirror with Fresnel).
    Conductor(Conductor),
    /// Rough conductor (microfacet).
    RoughConductor(RoughConductor),
    /// Smooth dielectric interface.
    Dielectric(Dielectric),
    /// Rough dielectric interface (Walter et al. 2007).
    RoughDielectric(RoughDielectric),
    /// Thin dielectric sheet.
    ThinDielectric(ThinDielectric),
    /// Smooth plastic: diffuse base under a specular dielectric coating.
    Plastic(Plastic),
    /// Rough plastic: diffuse base under a rough dielectric coating.
    RoughPlastic(RoughPlastic),
}

macro_rules! dispatch {
    ($self:expr, $b:ident => $e:expr) => {
        match $self {
            Bxdf::Diffuse($b) => $e,
            Bxdf::Conductor($b) => $e,
            Bxdf::RoughConductor($b) => $e,
            Bxdf::Dielectric($b) => $e,
            Bxdf::RoughDielectric($b) => $e,
            Bxdf::ThinDielectric($b) => $e,
            Bxdf::Plastic($b) => $e,
            Bxdf::RoughPlastic($b) => $e,
        }
    };
}

impl Bxdf {
    /// Samples `wi` given `wo`, with one uniform number to choose a lobe and two for the direction.
    #[inline]
    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        dispatch!(self, b => b.sample(wo, uc, u, mode))
    }

    /// `f(wo, wi)` without the cosine; zero for delta lobes.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        dispatch!(self, b => b.eval(wo, wi, mode))
    }

    /// Solid-angle pdf of sampling `wi` given `wo`; zero for delta lobes.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        dispatch!(self, b => b.pdf(wo, wi))
    }

    /// Whether any lobe is non-delta, i.e. light sampling can help (Mitsuba's `Smooth` flag).
    #[inline]
    pub fn has_smooth_lobe(&self) -> bool {
        !matches!(self, Bxdf::Conductor(_) | Bxdf::Dielectric(_) | Bxdf::ThinDielectric(_))
    }

    /// Whether the model depends on the tangent direction (different `alpha_u` and `alpha_v`).
    pub fn is_anisotropic(&self) -> bool {
        match self {
            Bxdf::RoughConductor(b) => b.distribution.alpha_u != b.distribution.alpha_v,
            Bxdf::RoughDielectric(b) => b.distribution.alpha_u != b.distribution.alpha_v,
            _ => false,
        }
    }
}

/// How the back side of a surface scatters.
#[derive(Clone, Debug, PartialEq)]
pub enum BackSide {
    /// The BSDF is used as it is; one-sided models are black from behind.
    AsIs,
    /// `twosided` with one nested BSDF: the back mirrors the front.
    MirrorFront,
    /// `twosided` with two nested BSDFs: the second is the back.
    Other(Bxdf),
}

/// What a surface is made of: a BSDF plus `twosided` and `mask` handling.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// The BSDF of the front side (the side the shading normal points to).
    pub front: Bxdf,
    /// What happens on the back side.
    pub back: BackSide,
    /// Mitsuba's `mask` opacity in [0, 1]: with probability 1 − opacity a ray passes straight
    /// through (a delta "null" lobe), otherwise the BSDF scatters with its value scaled by
    /// the opacity. 1 for surfaces without a mask.
    pub opacity: f32,
}

impl Material {
    /// A one-sided material.
    pub fn one_sided(bxdf: Bxdf) -> Self {
        Material { front: bxdf, back: BackSide::AsIs, opacity: 1.0 }
    }

    /// A `twosided` material: `back` is `None` when the back mirrors the front.
    pub fn two_sided(front: Bxdf, back: Option<Bxdf>) -> Self {
        let back = back.map_or(BackSide::MirrorFront, BackSide::Other);
        Material { front, back, opacity: 1.0 }
    }

    /// The BSDF that applies for `wo`, and the sign to apply to local z (−1 when a two-sided
    /// material is seen from behind and queries are mirrored to its front).
    #[inline]
    fn side(&self, wo: Vec3) -> (&Bxdf, f32) {
        if wo.z >= 0.0 {
            return (&self.front, 1.0);
        }
        match &self.back {
            BackSide::AsIs => (&self.front, 1.0),
            BackSide::MirrorFront => (&self.front, -1.0),
            BackSide::Other(b) => (b, -1.0),
        }
    }

    /// See [`Bxdf::sample`]. A mask's pass-through is a delta transmission with `wi = -wo`,
    /// weight 1 and probability 1 − opacity, as Mitsuba's `mask` samples it.
    #[inline]
    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        self.sample_in::<true>(wo, uc, u, mode)
    }

    /// See [`Bxdf::eval`]; scaled by the opacity (the pass-through lobe is delta).
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        self.eval_in::<true>(wo, wi, mode)
    }

    /// See [`Bxdf::pdf`]; scaled by the opacity.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.pdf_in::<true>(wo, wi)
    }

    /// [`Material::sample`] in a scene that may have masks (`MASKS`) or has none, so that
    /// integrators can compile the unmasked case without the opacity's branches.
    #[inline]
    pub fn sample_in<const MASKS: bool>(
        &self,
        wo: Vec3,
        mut uc: f32,
        u: Vec2,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        debug_assert!(MASKS || self.opacity == 1.0, "a masked material in a scene declared without masks");
        let alpha = if MASKS { self.opacity } else { 1.0 };
        if alpha < 1.0 {
            if uc >= alpha {
                return Some(BsdfSample::delta(-wo, Rgb::ONE, 1.0 - alpha, 1.0, true));
            }
            uc /= alpha;
        }
        let (b, s) = self.side(wo);
        let flip = Vec3::new(1.0, 1.0, s);
        let mut bs = b.sample(wo * flip, uc, u, mode)?;
        bs.wi *= flip;
        if alpha < 1.0 {
            // f and pdf both scale by the opacity, so the weight is the nested one
            bs.f = bs.f * alpha;
            bs.pdf *= alpha;
        }
        Some(bs)
    }

    /// [`Material::eval`]; see [`Material::sample_in`] for `MASKS`.
    #[inline]
    pub fn eval_in<const MASKS: bool>(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        debug_assert!(MASKS || self.opacity == 1.0, "a masked material in a scene declared without masks");
        let (b, s) = self.side(wo);
        let flip = Vec3::new(1.0, 1.0, s);
        let f = b.eval(wo * flip, wi * flip, mode);
        if MASKS && self.opacity < 1.0 { f * self.opacity } else { f }
    }

    /// [`Material::pdf`]; see [`Material::sample_in`] for `MASKS`.
    #[inline]
    pub fn pdf_in<const MASKS: bool>(&self, wo: Vec3, wi: Vec3) -> f32 {
        debug_assert!(MASKS || self.opacity == 1.0, "a masked material in a scene declared without masks");
        let (b, s) = self.side(wo);
        let flip = Vec3::new(1.0, 1.0, s);
        let pdf = b.pdf(wo * flip, wi * flip);
        if MASKS { pdf * self.opacity } else { pdf }
    }

    /// `f`, forward pdf (of `wi` given `wo`) and reverse pdf (of `wo` given `wi`) in one call, as
    /// bidirectional methods need.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32, f32) {
        (self.eval(wo, wi, mode), self.pdf(wo, wi), self.pdf(wi, wo))
    }

    /// Whether either side depends on the tangent direction.
    pub fn is_anisotropic(&self) -> bool {
        self.front.is_anisotropic() || matches!(&self.back, BackSide::Other(b) if b.is_anisotropic())
    }

    /// Whether any lobe on either side is non-delta.
    pub fn has_smooth_lobe(&self) -> bool {
        self.front.has_smooth_lobe() || matches!(&self.back, BackSide::Other(b) if b.has_smooth_lobe())
    }
}

#[cfg(test)]
mod goldens;
#[cfg(test)]
mod tests;
