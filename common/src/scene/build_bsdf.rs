//! Interprets `<bsdf>` and `<emitter>` elements: Mitsuba's parameter names, defaults and
//! named materials, with an error for anything Tessera does not support.

use super::error::SceneError;
use super::xml::{ColorUsage, Element};
use crate::bsdf::*;
use crate::light::Light;
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

/// Named conductors as Mitsuba's `*_rgb` variants resolve them (`src/bsdfs/conductor.cpp`,
/// the spectra integrated to RGB).
const NAMED_CONDUCTORS: &[(&str, [f32; 3], [f32; 3])] = &[
    ("Au", [0.143036, 0.375307, 1.44205], [3.983, 2.38556, 1.60336]),
    ("Cu", [0.201005, 0.92375, 1.10222], [3.91326, 2.45305, 2.14209]),
    ("Ag", [0.155276, 0.116728, 0.138388], [4.82835, 3.12222, 2.1469]),
    ("Al", [1.6575, 0.880405, 0.521244], [9.22381, 6.2695, 4.837]),
    ("Cr", [4.36967, 2.91651, 1.6549], [5.20655, 4.23131, 3.7547]),
    ("none", [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
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

/// A reflectance or transmittance: `<rgb>` must lie in [0, 1], spectra are clipped, a
/// `<float>` is taken as given (all as Mitsuba reads a bounded texture).
fn reflectance(e: &Element, name: &str, default: f32) -> Result<Rgb, SceneError> {
    e.color_or(name, ColorUsage::Bounded, default)
}

/// A roughness: Mitsuba reads it as an unbounded texture and evaluates its channel mean.
fn roughness(e: &Element, name: &str) -> Result<Option<f32>, SceneError> {
    Ok(e.color(name, ColorUsage::Unbounded)?.map(|c| c.element_sum() / 3.0))
}

fn positive(e: &Element, name: &str, v: f32) -> Result<f32, SceneError> {
    if v > 0.0 {
        Ok(v)
    } else {
        Err(SceneError::at(e.location_of(name), format!("\"{name}\" of {} must be positive, found {v}", e.describe())))
    }
}

fn microfacet(e: &Element, allow_anisotropic: bool) -> Result<Microfacet, SceneError> {
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
    let alpha = roughness(e, "alpha")?;
    let (au, av) = (roughness(e, "alpha_u")?, roughness(e, "alpha_v")?);
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
        (Some(m), None, None) => NAMED_CONDUCTORS
            .iter()
            .find(|(n, _, _)| *n == m)
            .map(|(_, eta, k)| (Rgb::from(*eta), Rgb::from(*k)))
            .ok_or_else(|| {
                let names: Vec<&str> = NAMED_CONDUCTORS.iter().map(|(n, _, _)| *n).collect();
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

/// Builds the BSDF of a `<bsdf>` element that is not `twosided`.
fn build_bxdf(e: &Element) -> Result<Bxdf, SceneError> {
    expect_bsdf(e)?;
    if let Some(child) = e.children.iter().find(|c| !c.is_spectrum()) {
        return Err(SceneError::at(
            &child.location,
            format!(
                "{} cannot contain <{}> (textures and nested bsdfs other than in twosided are not supported)",
                e.describe(),
                child.tag
            ),
        ));
    }
    let bxdf = match e.plugin.as_str() {
        "diffuse" => Bxdf::Diffuse(Diffuse { reflectance: reflectance(e, "reflectance", 0.5)? }),
        "conductor" => {
            let (eta, k) = conductor_ior(e)?;
            Bxdf::Conductor(Conductor { eta, k, specular_reflectance: reflectance(e, "specular_reflectance", 1.0)? })
        }
        "roughconductor" => {
            let distribution = microfacet(e, true)?;
            let (eta, k) = conductor_ior(e)?;
            Bxdf::RoughConductor(RoughConductor {
                distribution,
                eta,
                k,
                specular_reflectance: reflectance(e, "specular_reflectance", 1.0)?,
            })
        }
        "dielectric" | "thindielectric" | "roughdielectric" => {
            let eta = ior(e, "int_ior", "bk7")? / ior(e, "ext_ior", "air")?;
            let (sr, st) =
                (reflectance(e, "specular_reflectance", 1.0)?, reflectance(e, "specular_transmittance", 1.0)?);
            match e.plugin.as_str() {
                "dielectric" => {
                    Bxdf::Dielectric(Dielectric { eta, specular_reflectance: sr, specular_transmittance: st })
                }
                "thindielectric" => {
                    Bxdf::ThinDielectric(ThinDielectric { eta, specular_reflectance: sr, specular_transmittance: st })
                }
                _ => Bxdf::RoughDielectric(RoughDielectric {
                    distribution: microfacet(e, true)?,
                    eta,
                    specular_reflectance: sr,
                    specular_transmittance: st,
                }),
            }
        }
        "plastic" | "roughplastic" => {
            let eta = ior(e, "int_ior", "polypropylene")? / ior(e, "ext_ior", "air")?;
            let diffuse = reflectance(e, "diffuse_reflectance", 0.5)?;
            let specular = e.color("specular_reflectance", ColorUsage::Bounded)?;
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
                Bxdf::RoughPlastic(RoughPlastic::new(microfacet(e, false)?, eta, diffuse, specular, nonlinear))
            }
        }
        "twosided" => return Err(SceneError::at(&e.location, "twosided cannot be nested inside another bsdf")),
        other => {
            return Err(SceneError::at(
                &e.location,
                format!(
                    "unsupported bsdf \"{other}\" (supported: diffuse, conductor, roughconductor, dielectric, roughdielectric, thindielectric, plastic, roughplastic, twosided)"
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

/// Builds the material of a `<bsdf>` element, with `twosided` semantics.
pub(super) fn build_material(e: &Element) -> Result<Material, SceneError> {
    expect_bsdf(e)?;
    if e.plugin != "twosided" {
        return Ok(Material::one_sided(build_bxdf(e)?));
    }
    e.check_all_used()?;
    match e.children.as_slice() {
        [front] => Ok(Material { front: build_bxdf(front)?, back: BackSide::MirrorFront }),
        [front, back] => Ok(Material { front: build_bxdf(front)?, back: BackSide::Other(build_bxdf(back)?) }),
        inner => {
            Err(SceneError::at(&e.location, format!("twosided needs one or two nested bsdfs, found {}", inner.len())))
        }
    }
}

/// Builds an emitter. `shape` is the index of the enclosing shape for `area` emitters.
pub(super) fn build_emitter(e: &Element, shape: Option<u32>) -> Result<(Light, f32), SceneError> {
    if let Some(child) = e.children.iter().find(|c| !c.is_spectrum()) {
        return Err(SceneError::at(
            &child.location,
            format!("{} cannot contain <{}> (textures are not supported)", e.describe(), child.tag),
        ));
    }
    // Mitsuba's emitters default to 1 and read their colour as emissive
    let emitted = |name: &str| -> Result<Rgb, SceneError> {
        let v = e.color_or(name, ColorUsage::Emissive, 1.0)?;
        if v.min_element() < 0.0 {
            return Err(SceneError::at(
                e.location_of(name),
                format!("\"{name}\" of {} must not be negative", e.describe()),
            ));
        }
        Ok(v)
    };
    let light = match (e.plugin.as_str(), shape) {
        ("area", Some(shape)) => Light::Area { shape, radiance: emitted("radiance")? },
        ("area", None) => return Err(SceneError::at(&e.location, "an area emitter must be nested inside a <shape>")),
        ("point", None) => {
            let intensity = emitted("intensity")?;
            let position = match e.vector("position")? {
                Some(p) => p,
                None => e.transform("to_world")?.point(glam::Vec3::ZERO),
            };
            Light::Point { position, intensity }
        }
        ("constant", None) => Light::Constant { radiance: emitted("radiance")? },
        (kind @ ("point" | "constant"), Some(_)) => {
            return Err(SceneError::at(&e.location, format!("a {kind} emitter cannot be attached to a shape")));
        }
        (other, _) => {
            return Err(SceneError::at(
                &e.location,
                format!("unsupported emitter \"{other}\" (supported: area, point, constant)"),
            ));
        }
    };
    let weight = e.float_or("sampling_weight", 1.0)?;
    if weight < 0.0 {
        return Err(SceneError::at(e.location_of("sampling_weight"), "\"sampling_weight\" must not be negative"));
    }
    e.check_all_used()?;
    Ok((light, weight))
}
