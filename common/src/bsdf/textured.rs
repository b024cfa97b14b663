//! Materials whose parameters vary over the surface: the textures of a material, resolved at
//! each surface point into a plain [`Material`] that the integrators use as any other.
//!
//! A material keeps its constant parameters in its [`Material`] template; a textured parameter
//! is listed here with the slot it fills. Sampling weights that Mitsuba derives from a
//! texture's *mean* (plastic's specular sampling weight) stay as the template computed them,
//! as in Mitsuba; only the values change per point. Untextured materials have no entry and
//! cost nothing.

use super::{BackSide, Bxdf, Material};
use crate::math::Rgb;
use crate::texture::{MeshAttribute, Texture, TextureError, TexturePoint, Usage};
use std::sync::Arc;

/// A BSDF parameter a texture can fill.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// `diffuse.reflectance`.
    Reflectance,
    /// `specular_reflectance` of conductors, dielectrics and plastics.
    SpecularReflectance,
    /// `specular_transmittance` of dielectrics.
    SpecularTransmittance,
    /// `diffuse_reflectance` of plastics.
    DiffuseReflectance,
    /// Isotropic roughness `alpha` of rough conductors and dielectrics.
    Alpha,
    /// `alpha_u`.
    AlphaU,
    /// `alpha_v`.
    AlphaV,
}

impl Slot {
    /// Whether the slot reads the texture's scalar (`eval_1`) rather than its colour.
    fn scalar(self) -> bool {
        matches!(self, Slot::Alpha | Slot::AlphaU | Slot::AlphaV)
    }
}

/// Which BSDF of a material a texture feeds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The front (and a one-BSDF `twosided`'s back).
    Front,
    /// The second BSDF of a two-BSDF `twosided`.
    Back,
}

/// One textured parameter.
#[derive(Clone, Debug)]
pub struct TexturedParam {
    /// The BSDF it belongs to.
    pub side: Side,
    /// The parameter.
    pub slot: Slot,
    /// The texture.
    pub texture: Arc<Texture>,
}

/// The textures of one material.
#[derive(Clone, Debug, Default)]
pub struct MaterialTextures {
    /// Textured BSDF parameters.
    pub params: Vec<TexturedParam>,
    /// The `mask` opacity, when textured.
    pub opacity: Option<Arc<Texture>>,
}

impl MaterialTextures {
    /// Whether there is nothing to resolve.
    pub fn is_empty(&self) -> bool {
        self.params.is_empty() && self.opacity.is_none()
    }

    /// Whether `alpha_u` or `alpha_v` is textured (the material is then anisotropic).
    pub fn is_anisotropic(&self) -> bool {
        self.params.iter().any(|p| matches!(p.slot, Slot::AlphaU | Slot::AlphaV))
    }

    /// Whether some texture reads mesh attributes (the point then needs its mesh).
    pub fn uses_mesh_attributes(&self) -> bool {
        self.params.iter().any(|p| p.texture.uses_mesh_attributes())
            || self.opacity.as_ref().is_some_and(|t| t.uses_mesh_attributes())
    }

    /// Checks that a shape with `attributes` serves every `mesh_attribute` texture.
    pub fn check_attributes(&self, attributes: &[MeshAttribute]) -> Result<(), TextureError> {
        for p in &self.params {
            let usage = if p.slot.scalar() { Usage::Scalar } else { Usage::Color };
            p.texture.check_attributes(attributes, usage)?;
        }
        if let Some(t) = &self.opacity {
            t.check_attributes(attributes, Usage::Scalar)?;
        }
        Ok(())
    }

    /// The material `base` at surface point `p`.
    pub fn resolve(&self, base: &Material, p: &TexturePoint) -> Material {
        let mut m = base.clone();
        for param in &self.params {
            let bxdf = match (param.side, &mut m.back) {
                (Side::Back, BackSide::Other(b)) => b,
                _ => &mut m.front,
            };
            if param.slot.scalar() {
                set_scalar(bxdf, param.slot, param.texture.eval_1(p));
            } else {
                set_color(bxdf, param.slot, param.texture.eval(p));
            }
        }
        if let Some(t) = &self.opacity {
            m.opacity = t.eval_1(p).clamp(0.0, 1.0);
        }
        m
    }
}

/// Sets a colour parameter of `b` (slots a model does not have are ignored: the builder only
/// records slots the model has).
fn set_color(b: &mut Bxdf, slot: Slot, v: Rgb) {
    match (b, slot) {
        (Bxdf::Diffuse(d), Slot::Reflectance) => d.reflectance = v,
        (Bxdf::Conductor(c), Slot::SpecularReflectance) => c.specular_reflectance = v,
        (Bxdf::RoughConductor(c), Slot::SpecularReflectance) => c.specular_reflectance = v,
        (Bxdf::Dielectric(d), Slot::SpecularReflectance) => d.specular_reflectance = v,
        (Bxdf::Dielectric(d), Slot::SpecularTransmittance) => d.specular_transmittance = v,
        (Bxdf::ThinDielectric(d), Slot::SpecularReflectance) => d.specular_reflectance = v,
        (Bxdf::ThinDielectric(d), Slot::SpecularTransmittance) => d.specular_transmittance = v,
        (Bxdf::RoughDielectric(d), Slot::SpecularReflectance) => d.specular_reflectance = v,
        (Bxdf::RoughDielectric(d), Slot::SpecularTransmittance) => d.specular_transmittance = v,
        (Bxdf::Plastic(p), Slot::DiffuseReflectance) => p.diffuse_reflectance = v,
        (Bxdf::Plastic(p), Slot::SpecularReflectance) => p.specular_reflectance = v,
        (Bxdf::RoughPlastic(p), Slot::DiffuseReflectance) => p.diffuse_reflectance = v,
        (Bxdf::RoughPlastic(p), Slot::SpecularReflectance) => p.specular_reflectance = v,
        _ => {}
    }
}

/// Sets a roughness of `b`.
fn set_scalar(b: &mut Bxdf, slot: Slot, v: f32) {
    let distribution = match b {
        Bxdf::RoughConductor(c) => &mut c.distribution,
        Bxdf::RoughDielectric(d) => &mut d.distribution,
        _ => return,
    };
    let (u, w) = match slot {
        Slot::Alpha => (v, v),
        Slot::AlphaU => (v, distribution.alpha_v),
        _ => (distribution.alpha_u, v),
    };
    *distribution = super::Microfacet::new(distribution.kind, u, w, distribution.sample_visible);
}
