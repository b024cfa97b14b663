//! Interprets `<emitter>` elements: `area`, `point`, `spot`, `constant`, `envmap` and
//! `directional`, with Mitsuba's parameter names and defaults.

use super::build_texture::{Param, Textures};
use super::error::SceneError;
use super::xml::{ColorUsage, Element};
use crate::light::{Envmap, Light, Projection, Spot};
use crate::math::{Frame, Rgb};
use crate::texture::{Bitmap, BitmapOptions};
use glam::{Mat3, Vec3};
use std::path::Path;
use std::sync::Arc;

const SUPPORTED: &str = "area, point, spot, constant, envmap, directional";

/// Builds an emitter and its `sampling_weight`. `shape` is the index of the enclosing shape for
/// `area` emitters.
pub(super) fn build_emitter(
    e: &Element,
    shape: Option<u32>,
    textures: &mut Textures,
) -> Result<(Light, f32), SceneError> {
    // only an area light's radiance and a spot's projected image may be textures, as in Mitsuba
    let textured = |c: &Element| {
        let name = c.name.as_deref();
        c.tag == "texture"
            && ((e.plugin == "area" && name == Some("radiance")) || (e.plugin == "spot" && name == Some("texture")))
    };
    if let Some(child) = e.children.iter().find(|c| !c.is_spectrum() && !textured(c)) {
        let why = "only an area light's radiance and a spot's texture can be textures";
        return Err(SceneError::at(
            &child.location,
            format!("{} cannot contain <{}> ({why})", e.describe(), child.tag),
        ));
    }
    let light = match (e.plugin.as_str(), shape) {
        ("area", Some(shape)) => area(e, shape, textures)?,
        ("area", None) => return Err(SceneError::at(&e.location, "an area emitter must be nested inside a <shape>")),
        ("point", None) => {
            let intensity = emitted(e, "intensity")?;
            let position = match e.vector("position")? {
                Some(p) => p,
                None => e.transform("to_world")?.point(Vec3::ZERO),
            };
            Light::Point { position, intensity }
        }
        ("spot", None) => Light::Spot(spot(e, textures)?),
        ("constant", None) => Light::Constant { radiance: emitted(e, "radiance")? },
        ("envmap", None) => Light::Envmap(Arc::new(envmap(e, textures)?)),
        ("directional", None) => {
            let direction = match (e.vector("direction")?, e.properties.iter().any(|p| p.name == "to_world")) {
                (Some(_), true) => {
                    return Err(SceneError::at(
                        e.location_of("direction"),
                        "give either \"direction\" or \"to_world\", not both",
                    ));
                }
                (Some(d), false) => d,
                (None, _) => e.transform("to_world")?.vector(Vec3::Z),
            };
            let direction = direction.try_normalize().ok_or_else(|| {
                SceneError::at(e.location_of("direction"), "the directional emitter's direction must not be zero")
            })?;
            Light::Directional { direction, irradiance: emitted(e, "irradiance")? }
        }
        (kind, Some(_)) if SUPPORTED.contains(kind) => {
            return Err(SceneError::at(&e.location, format!("a {kind} emitter cannot be attached to a shape")));
        }
        (other, _) => {
            return Err(SceneError::at(
                &e.location,
                format!("unsupported emitter \"{other}\" (supported: {SUPPORTED})"),
            ));
        }
    };
    let weight = e.float_or("sampling_weight", 1.0)?;
    if !(weight >= 0.0 && weight.is_finite()) {
        return Err(SceneError::at(e.location_of("sampling_weight"), "\"sampling_weight\" must not be negative"));
    }
    e.check_all_used()?;
    Ok((light, weight))
}

/// An emitted quantity: Mitsuba's emitters default to 1 and read their colour as emissive.
fn emitted(e: &Element, name: &str) -> Result<Rgb, SceneError> {
    let v = e.color_or(name, ColorUsage::Emissive, 1.0)?;
    if !(v.min_element() >= 0.0) || !v.is_finite() {
        return Err(SceneError::at(
            e.location_of(name),
            format!("\"{name}\" of {} must be finite and not negative", e.describe()),
        ));
    }
    Ok(v)
}

/// Mitsuba's `area`: `radiance` a colour or a texture (looked up at the emitting point).
fn area(e: &Element, shape: u32, textures: &mut Textures) -> Result<Light, SceneError> {
    match textures.param(e, "radiance", ColorUsage::Emissive)? {
        Some(Param::Texture(t)) => {
            let radiance = Rgb::splat(t.mean().unwrap_or(0.0));
            Ok(Light::Area { shape, radiance, texture: Some(t) })
        }
        // constants are read (and checked) by `emitted`
        _ => Ok(Light::Area { shape, radiance: emitted(e, "radiance")?, texture: None }),
    }
}

/// The rotation part of a rigid `to_world`, or an error naming `what`.
fn rotation(e: &Element, what: &str) -> Result<(Mat3, Vec3), SceneError> {
    let t = e.transform("to_world")?;
    if t.uniform_scale(1e-3).is_none_or(|s| (s - 1.0).abs() > 1e-3) {
        return Err(SceneError::at(
            e.location_of("to_world"),
            format!("the {what}'s to_world must be a rotation and translation (no scale or shear)"),
        ));
    }
    let m = Mat3::from_cols(t.vector(Vec3::X), t.vector(Vec3::Y), t.vector(Vec3::Z));
    Ok((m, t.point(Vec3::ZERO)))
}

/// Mitsuba's `spot`: `cutoff_angle` (20°) and `beam_width` (¾ of it) in degrees, along +z of
/// `to_world`.
fn spot(e: &Element, textures: &mut Textures) -> Result<Spot, SceneError> {
    let intensity = emitted(e, "intensity")?;
    let cutoff = e.float_or("cutoff_angle", 20.0)?;
    let beam = e.float_or("beam_width", cutoff * 0.75)?;
    if !(cutoff > 0.0 && cutoff <= 180.0) {
        return Err(SceneError::at(
            e.location_of("cutoff_angle"),
            format!("\"cutoff_angle\" must lie in (0, 180] degrees, found {cutoff}"),
        ));
    }
    if !(beam > 0.0 && beam <= cutoff) {
        return Err(SceneError::at(
            e.location_of("beam_width"),
            format!("\"beam_width\" must lie in (0, cutoff_angle = {cutoff}] degrees, found {beam}"),
        ));
    }
    let (m, position) = rotation(e, "spot")?;
    let projection = match textures.param(e, "texture", ColorUsage::Bounded)? {
        None => None,
        Some(Param::Texture(texture)) => {
            Some(Projection { texture, to_local: m.transpose(), uv_factor: cutoff.to_radians().tan() })
        }
        // Mitsuba refuses it too
        Some(Param::Constant(_)) => {
            return Err(SceneError::at(
                e.location_of("texture"),
                "the spot's \"texture\" must vary over the image (a bitmap, say)",
            ));
        }
    };
    Ok(Spot {
        position,
        frame: Frame::from_normal((m * Vec3::Z).normalize()),
        intensity,
        cutoff: cutoff.to_radians(),
        beam: beam.to_radians(),
        projection,
    })
}

/// Mitsuba's `envmap`: an image file (any format `bitmap` reads, decoded to linear RGB, alpha
/// dropped) times `scale`, rotated by `to_world`.
fn envmap(e: &Element, textures: &mut Textures) -> Result<Envmap, SceneError> {
    let file = e.string("filename")?.ok_or_else(|| SceneError::at(&e.location, "envmap needs \"filename\""))?;
    let scale = e.float_or("scale", 1.0)?;
    if !(scale >= 0.0 && scale.is_finite()) {
        return Err(SceneError::at(e.location_of("scale"), format!("\"scale\" must not be negative, found {scale}")));
    }
    if e.boolean_or("mis_compensation", false)? {
        return Err(SceneError::at(e.location_of("mis_compensation"), "envmap mis_compensation is not supported"));
    }
    let (m, _) = rotation(e, "envmap")?;
    let path = textures
        .resolver()
        .resolve_checked(Path::new(file))
        .map_err(|why| SceneError::at(e.location_of("filename"), format!("\"{file}\" {why}")))?;
    let bitmap =
        Bitmap::load(&path, BitmapOptions::default(), &textures.limits()).map_err(|err| textures.load_error(e, err))?;
    let (width, height) = (bitmap.width() as usize, bitmap.height() as usize);
    // what the map holds (texels as f32 RGB and tables) counts against the budget; the decoded
    // image is freed once converted
    let needed = Envmap::bytes_for(width, height) as u64;
    let left = textures.limits().max_decoded_bytes;
    if needed > left {
        return Err(SceneError::at(
            e.location_of("filename"),
            format!(
                "{}: this {width}x{height} environment map needs {needed} bytes for its texels and sampling tables, over the {left} bytes the texture budget allows it",
                path.display()
            ),
        ));
    }
    let texels = bitmap.linear_rgb();
    drop(bitmap);
    if texels.iter().any(|t| !t.is_finite()) {
        return Err(SceneError::at(
            e.location_of("filename"),
            format!("{}: the image has non-finite pixels", path.display()),
        ));
    }
    let map = Envmap::from_texels(width, height, texels, scale, m);
    textures.add_bytes(map.bytes());
    Ok(map)
}
