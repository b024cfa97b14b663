//! Mitsuba's `upgrade_from_v1`, applied to the elements of files whose `version` is below
//! 2.0.0 (each file by its own version). It does exactly three things and nothing else:
//! camelCase parameter names become snake_case, `diffuse_reflectance` of a `diffuse` BSDF
//! becomes `reflectance`, and `uoffset`/`voffset`/`uscale`/`vscale` become a `to_uv` transform.

use super::super::error::{Location, SceneError};
use super::element::{Element, Property, Value};
use crate::geometry::Transform;
use glam::DVec3;

/// Mitsuba's `camel_to_underscore_case`: an `_` goes before an uppercase letter that follows a
/// lowercase one, and that letter with the uppercase run after it is lowercased
/// (`intIOR` → `int_ior`, `toWorld` → `to_world`).
pub(super) fn camel_to_snake(name: &str) -> String {
    let chars: Vec<char> = name.chars().collect();
    let mut out = String::with_capacity(name.len() + 4);
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if i > 0 && chars[i - 1].is_ascii_lowercase() && c.is_ascii_uppercase() {
            out.push('_');
            out.push(c.to_ascii_lowercase());
            while i + 1 < chars.len() && chars[i + 1].is_ascii_uppercase() {
                i += 1;
                out.push(chars[i].to_ascii_lowercase());
            }
        } else {
            out.push(c);
        }
        i += 1;
    }
    out
}

/// Upgrades one element of a version < 2.0.0 file in place (its parameters and the names under
/// which its nested objects are passed, which Mitsuba stores alike).
pub(super) fn upgrade_from_v1(e: &mut Element) -> Result<(), SceneError> {
    for p in &mut e.properties {
        p.name = camel_to_snake(&p.name);
    }
    for c in &mut e.children {
        if let Some(name) = &mut c.name {
            *name = camel_to_snake(name);
        }
    }
    if e.plugin == "diffuse" {
        for p in e.properties.iter_mut().filter(|p| p.name == "diffuse_reflectance") {
            p.name = "reflectance".into();
        }
        for c in e.children.iter_mut().filter(|c| c.name.as_deref() == Some("diffuse_reflectance")) {
            c.name = Some("reflectance".into());
        }
    }
    uv_to_transform(e)
}

/// `to_uv = scale(uscale, vscale) · translate(uoffset, voffset)`: uv' = (us(u + uo), vs(v + vo)).
fn uv_to_transform(e: &mut Element) -> Result<(), SceneError> {
    const NAMES: [&str; 4] = ["uoffset", "voffset", "uscale", "vscale"];
    if !e.properties.iter().any(|p| NAMES.contains(&p.name.as_str())) {
        return Ok(());
    }
    let mut v = [0.0, 0.0, 1.0, 1.0];
    let mut location: Option<Location> = None;
    for (i, name) in NAMES.iter().enumerate() {
        let Some(at) = e.properties.iter().position(|p| p.name == *name) else { continue };
        let p = e.properties.remove(at);
        v[i] = match p.value {
            Value::Float(x) => x,
            Value::Integer(x) => x as f64,
            _ => return Err(SceneError::at(&p.location, format!("\"{name}\" of {} must be a float", e.describe()))),
        };
        location.get_or_insert(p.location);
    }
    let location = location.unwrap_or_else(|| e.location.clone());
    let scale = Transform::scale(DVec3::new(v[2], v[3], 1.0))
        .ok_or_else(|| SceneError::at(&location, "\"uscale\" and \"vscale\" must not be zero"))?;
    let to_uv = scale.after(&Transform::translate(DVec3::new(v[0], v[1], 0.0)));
    e.properties.push(Property::new("to_uv".into(), Value::Transform(to_uv), location));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use std::path::Path;

    #[test]
    fn camel_to_snake_follows_mitsuba() {
        for (from, to) in [
            ("toWorld", "to_world"),
            ("maxDepth", "max_depth"),
            ("intIOR", "int_ior"),
            ("fovAxis", "fov_axis"),
            ("diffuseReflectance", "diffuse_reflectance"),
            ("sampleCount", "sample_count"),
            ("already_snake", "already_snake"),
            ("UPPER", "UPPER"),
            ("aBCdE", "a_bcd_e"),
        ] {
            assert_eq!(camel_to_snake(from), to, "{from}");
        }
    }

    #[test]
    fn upgrade_from_v1_renames_and_builds_to_uv() {
        let loc = Location::new(Path::new("old.xml"), 3, 1);
        let mut e = Element::new("bsdf", "diffuse".into(), loc.clone());
        for (name, value) in [("diffuseReflectance", 0.5), ("uscale", 2.0), ("voffset", 0.25)] {
            e.properties.push(Property::new(name.into(), Value::Float(value), loc.clone()));
        }
        upgrade_from_v1(&mut e).unwrap();
        let names: Vec<&str> = e.properties.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["reflectance", "to_uv"]);
        let to_uv = e.transform("to_uv").unwrap();
        // uv' = (2 (u + 0), 1 (v + 0.25))
        assert_eq!(to_uv.point(Vec3::new(0.5, 0.5, 0.0)), Vec3::new(1.0, 0.75, 0.0));
    }

    #[test]
    fn upgrade_from_v1_keeps_diffuse_reflectance_of_other_plugins() {
        let loc = Location::new(Path::new("old.xml"), 3, 1);
        let mut e = Element::new("bsdf", "plastic".into(), loc.clone());
        e.properties.push(Property::new("diffuseReflectance".into(), Value::Float(0.5), loc));
        upgrade_from_v1(&mut e).unwrap();
        assert_eq!(e.properties[0].name, "diffuse_reflectance");
    }
}
