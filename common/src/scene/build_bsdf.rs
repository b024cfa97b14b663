//! Interprets `<bsdf>` elements: Mitsuba's parameter names, defaults and named materials,
//! `twosided` and `mask`, and parameters given as textures, with an error for anything
//! Tessera does not support.

use super::build_texture::{Param, Textures};
use super::error::SceneError;
use super::xml::{ColorUsage, Element};
use crate::bsdf::textured::{MaterialTextures, Side, Slot, TexturedParam};
use crate::bsdf::*;
use crate::math::Rgb;

/// Named indices of refraction (Mitsuba's `ior.h` table).
const NAMED_IORS: &[(&str, f32)] = &[
    ("vacuum", 1.0),
    ("helium", 1.000036),
    ("hydrogen", 1.000132),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.3330),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.5750),
    ("diamond", 2.419),
];

fn ior(e: &Element, name: &str, default: &str) -> Result<f32, SceneError> {
    if let Ok(Some(v)) = e.float(name) {
        if v <= 0.0 {
            return Err(SceneError::at(
                e.location_of(name),
                format!("\"{name}\" of {} must be positive", e.describe()),
            ));
        }
        return Ok(v);
    }
    let s = e.string(name)?.unwrap_or(default);
    NAMED_IORS.iter().find(|(n, _)| n.eq_ignore_ascii_case(s)).map(|(_, v)| *v).ok_or_else(|| {
        let names: Vec<&str> = NAMED_IORS.iter().map(|(n, _)| *n).collect();
        SceneError::at(
            e.location_of(name),
            format!("unknown index of refraction \"{s}\" for \"{name}\" (known: {})", names.join(", ")),
        )
    })
}

/// Collects the textured parameters of one material while its BSDFs are built.
struct Ctx<'t, 'a> {
    textures: &'t mut Textures<'a>,
    side: Side,
    out: MaterialTextures,
}

impl Ctx<'_, '_> {
    /// A bounded colour parameter (reflectances, transmittances): a constant (`<rgb>` within
    /// [0, 1], spectra clipped, `<float>` as given) or a texture filling `slot`. A textured
    /// slot's template value is the texture's mean, which is what Mitsuba's sampling weights
    /// read.
    fn color(&mut self, e: &Element, name: &str, default: f32, slot: Slot) -> Result<Rgb, SceneError> {
        Ok(self.optional_color(e, name, slot)?.unwrap_or(Rgb::splat(default)))
    }

    fn optional_color(&mut self, e: &Element, name: &str, slot: Slot) -> Result<Option<Rgb>, SceneError> {
        match self.textures.param(e, name, ColorUsage::Bounded)? {
            None => Ok(None),
            Some(Param::Constant(c)) => Ok(Some(c)),
            Some(Param::Texture(texture)) => {
                let mean = texture.mean();
                self.out.params.push(TexturedParam { side: self.side, slot, texture });
                Ok(Some(Rgb::splat(mean.unwrap_or(0.5))))
            }
        }
    }

    /// A colour whose mean Mitsuba needs at load time (plastic's sampling weight).
    fn color_with_mean(&mut self, e: &Element, name: &str, slot: Slot) -> Result<Option<Rgb>, SceneError> {
        let before = self.out.params.len();
        let c = self.optional_color(e, name, slot)?;
        if self.out.params.len() > before && self.out.params[before].texture.mean().is_none() {
            return Err(SceneError::at(
                &e.object(name).map_or(&e.location, |c| &c.location).clone(),
                format!(
                    "\"{name}\" of {} cannot be a mesh_attribute texture: its sampling weight needs the texture's mean, which mesh_attribute lacks (Mitsuba fails the same way)",
                    e.describe()
                ),
            ));
        }
        Ok(c)
    }

    /// A roughness: an unbounded constant (its channel mean, as Mitsuba's `eval_1`) or, when
    /// `slot` is given, a texture.
    fn roughness(&mut self, e: &Element, name: &str, slot: Option<Slot>) -> Result<Option<f32>, SceneError> {
        match (self.textures.param(e, name, ColorUsage::Unbounded)?, slot) {
            (None, _) => Ok(None),
            (Some(Param::Constant(c)), _) => Ok(Some(c.element_sum() / 3.0)),
            (Some(Param::Texture(texture)), Some(slot)) => {
                let mean = texture.mean();
                self.out.params.push(TexturedParam { side: self.side, slot, texture });
                Ok(Some(mean.unwrap_or(0.1)))
            }
            (Some(Param::Texture(_)), None) => Err(SceneError::at(
                &e.object(name).map_or(&e.location, |c| &c.location).clone(),
                format!("\"{name}\" of {} must be a number (Mitsuba does not texture it)", e.describe()),
            )),
        }
    }
}

fn positive(e: &Element, name: &str, v: f32) -> Result<f32, SceneError> {
    if v > 0.0 {
        Ok(v)
    } else {
        Err(SceneError::at(e.location_of(name), format!("\"{name}\" of {} must be positive, found {v}", e.describe())))
    }
}

/// The microfacet distribution of a rough model; `textured` says whether its roughness may
/// be a texture (rough conductors and dielectrics) or only a number (rough plastic).
fn microfacet(e: &Element, ctx: &mut Ctx, allow_anisotropic: bool, textured: bool) -> Result<Microfacet, SceneError> {
    let kind = match e.string("distribution")?.unwrap_or("beckmann") {
        "beckmann" => MicrofacetKind::Beckmann,
        "ggx" => MicrofacetKind::Ggx,
        other => {
            return Err(SceneError::at(
                e.location_of("distribution"),
                format!("unknown microfacet distribution \"{other}\" (beckmann or ggx)"),
            ));
        }
    };
    let slot = |s: Slot| textured.then_some(s);
    let alpha = ctx.roughness(e, "alpha", slot(Slot::Alpha))?;
    let (au, av) = (ctx.roughness(e, "alpha_u", slot(Slot::AlphaU))?, ctx.roughness(e, "alpha_v", slot(Slot::AlphaV))?);
    let (au, av) = match (alpha, au, av) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
            return Err(SceneError::at(
                e.location_of("alpha"),
                "give either \"alpha\" or \"alpha_u\"/\"alpha_v\", not both",
            ));
        }
        (_, Some(u), Some(v)) if allow_anisotropic => (u, v),
        (_, Some(_), Some(_)) => {
            return Err(SceneError::at(
                e.location_of("alpha_u"),
                format!("{} does not support anisotropic roughness", e.describe()),
            ));
        }
        (_, Some(_), None) | (_, None, Some(_)) => {
            return Err(SceneError::at(e.location_of("alpha_u"), "\"alpha_u\" and \"alpha_v\" must be given together"));
        }
        (a, None, None) => {
            let a = a.unwrap_or(0.1);
            (a, a)
        }
    };
    let sample_visible = e.boolean_or("sample_visible", true)?;
    Ok(Microfacet::new(kind, positive(e, "alpha", au)?, positive(e, "alpha", av)?, sample_visible))
}

fn conductor_ior(e: &Element) -> Result<(Rgb, Rgb), SceneError> {
    let material = e.string("material")?;
    let (eta, k) = (e.color("eta", ColorUsage::Unbounded)?, e.color("k", ColorUsage::Unbounded)?);
    match (material, eta, k) {
        (Some(m), None, None) => super::conductors::NAMED_CONDUCTORS
            .iter()
            .find(|(n, _, _)| *n == m)
            .map(|(_, eta, k)| (Rgb::from(*eta), Rgb::from(*k)))
            .ok_or_else(|| {
                let names: Vec<&str> = super::conductors::NAMED_CONDUCTORS.iter().map(|(n, _, _)| *n).collect();
                SceneError::at(
                    e.location_of("material"),
                    format!("unknown conductor material \"{m}\" (supported: {})", names.join(", ")),
                )
            }),
        (Some(_), _, _) => {
            Err(SceneError::at(e.location_of("material"), "give either \"material\" or \"eta\"/\"k\", not both"))
        }
        // Mitsuba's default conductor is a perfect mirror: eta 0, k 1
        (None, eta, k) => Ok((eta.unwrap_or(Rgb::ZERO), k.unwrap_or(Rgb::ONE))),
    }
}

/// Fails on a nested texture for a parameter Tessera takes only as a constant.
fn constant_only(e: &Element, names: &[&str]) -> Result<(), SceneError> {
    for name in names {
        if let Some(c) = e.object(name).filter(|c| c.tag == "texture" && !c.is_spectrum()) {
            return Err(SceneError::at(
                c.reference.as_ref().unwrap_or(&c.location),
                format!("a textured \"{name}\" of {} is not supported; give a constant", e.describe()),
            ));
        }
    }
    Ok(())
}

/// Builds the BSDF of a `<bsdf>` element that is neither `twosided` nor `mask`.
fn build_bxdf(e: &Element, ctx: &mut Ctx) -> Result<Bxdf, SceneError> {
    expect_bsdf(e)?;
    if let Some(child) = e.children.iter().find(|c| !c.is_spectrum() && c.tag != "texture") {
        return Err(SceneError::at(
            &child.location,
            format!("{} cannot contain <{}> (nested bsdfs belong in twosided or mask)", e.describe(), child.tag),
        ));
    }
    let bxdf = match e.plugin.as_str() {
        "diffuse" => Bxdf::Diffuse(Diffuse { reflectance: ctx.color(e, "reflectance", 0.5, Slot::Reflectance)? }),
        "conductor" | "roughconductor" => {
            constant_only(e, &["eta", "k"])?;
            let (eta, k) = conductor_ior(e)?;
            let specular_reflectance = ctx.color(e, "specular_reflectance", 1.0, Slot::SpecularReflectance)?;
            if e.plugin == "conductor" {
                Bxdf::Conductor(Conductor { eta, k, specular_reflectance })
            } else {
                let distribution = microfacet(e, ctx, true, true)?;
                Bxdf::RoughConductor(RoughConductor { distribution, eta, k, specular_reflectance })
            }
        }
        "dielectric" | "thindielectric" | "roughdielectric" => {
            let eta = ior(e, "int_ior", "bk7")? / ior(e, "ext_ior", "air")?;
            let sr = ctx.color(e, "specular_reflectance", 1.0, Slot::SpecularReflectance)?;
            let st = ctx.color(e, "specular_transmittance", 1.0, Slot::SpecularTransmittance)?;
            match e.plugin.as_str() {
                "dielectric" => {
                    Bxdf::Dielectric(Dielectric { eta, specular_reflectance: sr, specular_transmittance: st })
                }
                "thindielectric" => {
                    Bxdf::ThinDielectric(ThinDielectric { eta, specular_reflectance: sr, specular_transmittance: st })
                }
                _ => Bxdf::RoughDielectric(RoughDielectric {
                    distribution: microfacet(e, ctx, true, true)?,
                    eta,
                    specular_reflectance: sr,
                    specular_transmittance: st,
                }),
            }
        }
        "plastic" | "roughplastic" => {
            let eta = ior(e, "int_ior", "polypropylene")? / ior(e, "ext_ior", "air")?;
            let diffuse = ctx.color_with_mean(e, "diffuse_reflectance", Slot::DiffuseReflectance)?;
            let diffuse = diffuse.unwrap_or(Rgb::splat(0.5));
            let specular = ctx.color_with_mean(e, "specular_reflectance", Slot::SpecularReflectance)?;
            let nonlinear = e.boolean_or("nonlinear", false)?;
            if e.plugin == "plastic" {
                Bxdf::Plastic(Plastic::new(eta, diffuse, specular, nonlinear))
            } else {
                if (eta - 1.0).abs() < 1e-6 {
                    return Err(SceneError::at(
                        e.location_of("int_ior"),
                        "roughplastic needs different interior and exterior indices",
                    ));
                }
                let distribution = microfacet(e, ctx, false, false)?;
                // each distinct coating costs about a million quadrature evaluations
                ctx.textures.count_coating(coating_key(&distribution, eta), &e.location)?;
                let plastic = RoughPlastic::new(distribution, eta, diffuse, specular, nonlinear).ok_or_else(|| {
                    SceneError::at(
                        &e.location,
                        "this process keeps the tables of too many rough plastic coatings: restart it",
                    )
                })?;
                Bxdf::RoughPlastic(plastic)
            }
        }
        "twosided" | "mask" => {
            return Err(SceneError::at(
                &e.location,
                format!("{} cannot be nested here (use mask(twosided(bsdf)))", e.describe()),
            ));
        }
        other => {
            return Err(SceneError::at(
                &e.location,
                format!(
                    "unsupported bsdf \"{other}\" (supported: diffuse, conductor, roughconductor, dielectric, roughdielectric, thindielectric, plastic, roughplastic, twosided, mask)"
                ),
            ));
        }
    };
    e.check_all_used()?;
    Ok(bxdf)
}

/// Fails unless `e` is a `<bsdf>` (it may be an element a `<ref>` placed where a BSDF goes).
fn expect_bsdf(e: &Element) -> Result<(), SceneError> {
    if e.tag == "bsdf" {
        return Ok(());
    }
    let at = e.reference.as_ref().unwrap_or(&e.location);
    match &e.id {
        Some(id) => Err(SceneError::at(at, format!("id \"{id}\" refers to a <{}>, expected a <bsdf>", e.tag))),
        None => Err(SceneError::at(at, format!("expected a <bsdf>, found <{}>", e.tag))),
    }
}

/// Builds the material of a `<bsdf>` element, with `twosided` and `mask` semantics, and the
/// textures it needs resolved per point (`None` when it has none).
pub(super) fn build_material(
    e: &Element,
    textures: &mut Textures,
) -> Result<(Material, Option<MaterialTextures>), SceneError> {
    expect_bsdf(e)?;
    let mut ctx = Ctx { textures, side: Side::Front, out: MaterialTextures::default() };
    let material = match e.plugin.as_str() {
        "mask" => mask(e, &mut ctx)?,
        "twosided" => twosided(e, &mut ctx)?,
        _ => Material::one_sided(build_bxdf(e, &mut ctx)?),
    };
    Ok((material, (!ctx.out.is_empty()).then_some(ctx.out)))
}

/// The nested `<bsdf>` elements of `e`.
fn nested_bsdfs(e: &Element) -> Vec<&Element> {
    e.children.iter().filter(|c| c.tag == "bsdf").collect()
}

/// `twosided` with one or two nested BSDFs. As in Mitsuba, nested models that transmit
/// (dielectrics, masks) need `allow_transmission`.
fn twosided(e: &Element, ctx: &mut Ctx) -> Result<Material, SceneError> {
    let allow_transmission = e.boolean_or("allow_transmission", false)?;
    if let Some(c) = e.children.iter().find(|c| c.tag != "bsdf") {
        return Err(SceneError::at(&c.location, format!("twosided cannot contain <{}>", c.tag)));
    }
    e.check_all_used()?;
    let inner = nested_bsdfs(e);
    for c in &inner {
        let transmits = matches!(c.plugin.as_str(), "dielectric" | "thindielectric" | "roughdielectric" | "mask");
        if transmits && !allow_transmission {
            return Err(SceneError::at(
                c.reference.as_ref().unwrap_or(&c.location),
                format!(
                    "twosided cannot nest {}, which transmits light (Mitsuba refuses it too; set allow_transmission to true)",
                    c.describe()
                ),
            ));
        }
    }
    match inner.as_slice() {
        // twosided(mask(x)) is mask(twosided(x)): the pass-through is the same from both sides
        [m] if m.plugin == "mask" => {
            let mut material = mask(m, ctx)?;
            if material.back == BackSide::AsIs {
                material.back = BackSide::MirrorFront;
            }
            Ok(material)
        }
        [front] => Ok(Material::two_sided(build_bxdf(front, ctx)?, None)),
        [front, back] if front.plugin == "mask" || back.plugin == "mask" => Err(SceneError::at(
            &e.location,
            "twosided with two nested bsdfs of which one is a mask is not supported (use mask(twosided(a, b)))",
        )),
        [front, back] => {
            let front = build_bxdf(front, ctx)?;
            ctx.side = Side::Back;
            let back = build_bxdf(back, ctx)?;
            ctx.side = Side::Front;
            Ok(Material::two_sided(front, Some(back)))
        }
        inner => {
            Err(SceneError::at(&e.location, format!("twosided needs one or two nested bsdfs, found {}", inner.len())))
        }
    }
}

/// `mask`: a nested BSDF seen with probability `opacity` (Mitsuba's default 0.5), passed
/// straight through otherwise.
fn mask(e: &Element, ctx: &mut Ctx) -> Result<Material, SceneError> {
    let opacity = match ctx.textures.param(e, "opacity", ColorUsage::Bounded)? {
        None => 0.5,
        Some(Param::Constant(c)) => (c.element_sum() / 3.0).clamp(0.0, 1.0),
        Some(Param::Texture(t)) => {
            ctx.out.opacity = Some(t);
            1.0
        }
    };
    if let Some(c) = e.children.iter().find(|c| c.tag != "bsdf" && c.name.as_deref() != Some("opacity")) {
        return Err(SceneError::at(
            &c.location,
            format!("mask cannot contain <{}> besides its bsdf and opacity", c.tag),
        ));
    }
    e.check_all_used()?;
    let mut material = match nested_bsdfs(e).as_slice() {
        [inner] if inner.plugin == "twosided" => twosided(inner, ctx)?,
        [inner] if inner.plugin == "mask" => {
            return Err(SceneError::at(&inner.location, "a mask inside a mask is not supported"));
        }
        [inner] => Material::one_sided(build_bxdf(inner, ctx)?),
        inner => return Err(SceneError::at(&e.location, format!("mask needs one nested bsdf, found {}", inner.len()))),
    };
    material.opacity = opacity;
    Ok(material)
}
