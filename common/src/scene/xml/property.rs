//! Property tags (`<float>`, `<integer>`, `<boolean>`, `<string>`, `<point>`, `<vector>`,
//! `<rgb>`, `<spectrum>`, `<transform>`) → typed [`Value`]s, with Mitsuba's attribute rules.
//! `<transform>` children are composed in document order, each left-multiplied onto the
//! previous ones; a `<spectrum filename>` is read now, through the resolver in force here.

use super::super::error::{Location, SceneError};
use super::element::{Property, Value};
use super::parser::{Attrs, FileParser};
use crate::geometry::Transform;
use crate::spectrum::Spectrum;
use glam::{DMat3, DMat4, DVec3, Vec3};
use std::path::Path;

/// The largest spectrum file read: measured spectra have hundreds of samples.
const MAX_SPECTRUM_FILE_BYTES: u64 = 1 << 20;

fn number(loc: &Location, what: &str, s: &str) -> Result<f64, SceneError> {
    let v: f64 =
        s.trim().parse().map_err(|_| SceneError::at(loc, format!("\"{s}\" is not a number (parameter \"{what}\")")))?;
    if !v.is_finite() {
        return Err(SceneError::at(loc, format!("\"{s}\" is not a finite number (parameter \"{what}\")")));
    }
    Ok(v)
}

fn numbers(loc: &Location, what: &str, s: &str) -> Result<Vec<f64>, SceneError> {
    s.split(|c: char| c == ',' || c.is_whitespace()).filter(|t| !t.is_empty()).map(|t| number(loc, what, t)).collect()
}

/// `value="v"` or `value="x, y, z"`, else the `x`, `y`, `z` attributes (absent ones
/// `default`); mixing both forms is an error.
fn xyz(attrs: &Attrs, loc: &Location, what: &str, default: f64) -> Result<DVec3, SceneError> {
    let components = ["x", "y", "z"].map(|a| attrs.get(a));
    if let Some(s) = attrs.get("value") {
        if components.iter().any(Option::is_some) {
            return Err(SceneError::at(loc, "cannot mix \"value\" and \"x\"/\"y\"/\"z\" attributes"));
        }
        return match numbers(loc, what, s)?.as_slice() {
            [v] => Ok(DVec3::splat(*v)),
            [x, y, z] => Ok(DVec3::new(*x, *y, *z)),
            v => Err(SceneError::at(loc, format!("\"value\" needs 1 or 3 numbers, found {}", v.len()))),
        };
    }
    let mut out = DVec3::splat(default);
    for (i, s) in components.iter().enumerate() {
        if let Some(s) = s {
            out[i] = number(loc, what, s)?;
        }
    }
    Ok(out)
}

fn vector3(attrs: &Attrs, loc: &Location, attr: &str) -> Result<Option<DVec3>, SceneError> {
    let Some(s) = attrs.get(attr) else { return Ok(None) };
    match numbers(loc, attr, s)?.as_slice() {
        [x, y, z] => Ok(Some(DVec3::new(*x, *y, *z))),
        v => Err(SceneError::at(loc, format!("\"{attr}\" needs 3 numbers, found {}", v.len()))),
    }
}

/// The first tangent of Mitsuba's `coordinate_system(n)` (Duff et al. 2017), its up vector for a
/// `<lookat>` without one.
fn coordinate_system_up(n: DVec3) -> DVec3 {
    let sign = if n.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    DVec3::new(n.x * n.x * a * sign + 1.0, b * sign, -n.x * sign)
}

impl FileParser<'_, '_> {
    pub(super) fn property(
        &mut self,
        node: roxmltree::Node,
        tag: &str,
        attrs: &Attrs,
        location: Location,
    ) -> Result<Property, SceneError> {
        if let Some(child) = node.children().find(|n| n.is_element())
            && tag != "transform"
        {
            return Err(SceneError::at(
                &self.loc(child),
                format!("<{}> cannot occur inside the property <{tag}>", child.tag_name().name()),
            ));
        }
        let loc = &location;
        let value = match tag {
            "integer" | "float" | "boolean" | "string" | "rgb" => {
                attrs.check(loc, &["!name", "!value"])?;
                let (name, s) = (attrs.required("name", loc)?, attrs.required("value", loc)?);
                scalar(tag, name, s, loc)?
            }
            "point" | "vector" => {
                let spec: &[&str] =
                    if attrs.get("value").is_some() { &["!name", "value"] } else { &["!name", "!x", "!y", "!z"] };
                attrs.check(loc, spec)?;
                Value::Vector(xyz(attrs, loc, attrs.required("name", loc)?, 0.0)?.as_vec3())
            }
            "spectrum" => {
                attrs.check(loc, &["!name", "value", "filename"])?;
                Value::Spectrum(self.spectrum(attrs, loc)?)
            }
            "transform" => {
                attrs.check(loc, &["!name"])?;
                Value::Transform(self.transform(node)?)
            }
            other => return Err(SceneError::at(loc, format!("unknown element <{other}>"))),
        };
        Ok(Property::new(attrs.required("name", loc)?.to_string(), value, location))
    }

    fn spectrum(&mut self, attrs: &Attrs, loc: &Location) -> Result<Spectrum, SceneError> {
        let name = attrs.required("name", loc)?;
        let bad = |e: crate::spectrum::SpectrumError| SceneError::at(loc, format!("spectrum \"{name}\": {e}"));
        match (attrs.get("value").filter(|v| !v.is_empty()), attrs.get("filename").filter(|v| !v.is_empty())) {
            (Some(value), None) => Spectrum::parse(value).map_err(bad),
            (None, Some(filename)) => {
                if let Some(why) = self.session.resolver.refusal(Path::new(filename)) {
                    return Err(SceneError::at(loc, format!("spectrum file \"{filename}\" {why}")));
                }
                let path = self
                    .session
                    .resolver
                    .find(Path::new(filename))
                    .ok_or_else(|| SceneError::at(loc, format!("spectrum file \"{filename}\" not found")))?;
                let cannot =
                    |e: std::io::Error| SceneError::at(loc, format!("cannot read spectrum file \"{filename}\": {e}"));
                // a spectrum file is a few hundred lines; it is read whole, so its size is checked first
                let len = std::fs::metadata(&path).map_err(cannot)?.len();
                if len > MAX_SPECTRUM_FILE_BYTES {
                    return Err(SceneError::at(
                        loc,
                        format!("spectrum file \"{filename}\" has {len} bytes, over {MAX_SPECTRUM_FILE_BYTES}"),
                    ));
                }
                let text = std::fs::read_to_string(&path).map_err(cannot)?;
                self.session.record_file(&path);
                Spectrum::parse_file(&text)
                    .map_err(|e| SceneError::at(loc, format!("spectrum file \"{filename}\": {e}")))
            }
            _ => Err(SceneError::at(loc, "<spectrum> needs either \"value\" or \"filename\" (not both)")),
        }
    }

    fn transform(&mut self, node: roxmltree::Node) -> Result<Transform, SceneError> {
        let mut acc = Transform::IDENTITY;
        for child in node.children().filter(|n| n.is_element()) {
            let loc = self.loc(child);
            let attrs = self.attrs(child)?;
            let tag = child.tag_name().name();
            let step = transform_step(tag, &attrs, &loc)?.ok_or_else(|| {
                SceneError::at(&loc, format!("<{tag}> gives a degenerate (non-invertible) transform"))
            })?;
            acc = step.after(&acc);
        }
        Ok(acc)
    }
}

/// `<integer>`, `<float>`, `<boolean>`, `<string>` and `<rgb>` from their `value` text.
fn scalar(tag: &str, name: &str, s: &str, loc: &Location) -> Result<Value, SceneError> {
    Ok(match tag {
        "integer" => Value::Integer(
            s.trim()
                .parse::<i64>()
                .map_err(|_| SceneError::at(loc, format!("\"{s}\" is not an integer (parameter \"{name}\")")))?,
        ),
        "float" => Value::Float(number(loc, name, s)?),
        "boolean" if s.eq_ignore_ascii_case("true") => Value::Boolean(true),
        "boolean" if s.eq_ignore_ascii_case("false") => Value::Boolean(false),
        "boolean" => {
            return Err(SceneError::at(
                loc,
                format!("\"{s}\" is not a boolean (parameter \"{name}\"; use true or false)"),
            ));
        }
        "string" => Value::String(s.to_string()),
        _ => match numbers(loc, name, s)?.as_slice() {
            [g] => Value::Rgb(Vec3::splat(*g as f32)),
            [r, g, b] => Value::Rgb(Vec3::new(*r as f32, *g as f32, *b as f32)),
            v => return Err(SceneError::at(loc, format!("<rgb> \"{name}\" needs 1 or 3 values, found {}", v.len()))),
        },
    })
}

/// One child of `<transform>`; `None` when it is degenerate.
fn transform_step(tag: &str, attrs: &Attrs, loc: &Location) -> Result<Option<Transform>, SceneError> {
    Ok(match tag {
        "translate" => {
            attrs.check(loc, &["value", "x", "y", "z"])?;
            Some(Transform::translate(xyz(attrs, loc, tag, 0.0)?))
        }
        "scale" => {
            attrs.check(loc, &["value", "x", "y", "z"])?;
            Transform::scale(xyz(attrs, loc, tag, 1.0)?)
        }
        "rotate" => {
            attrs.check(loc, &["!angle", "value", "x", "y", "z"])?;
            let axis = xyz(attrs, loc, tag, 0.0)?;
            if axis == DVec3::ZERO {
                return Err(SceneError::at(loc, "<rotate> needs a non-zero axis (x, y, z or value)"));
            }
            Transform::rotate(axis, number(loc, tag, attrs.required("angle", loc)?)?)
        }
        "matrix" => {
            attrs.check(loc, &["!value"])?;
            let v = numbers(loc, tag, attrs.required("value", loc)?)?;
            let m = match v.len() {
                16 => DMat4::from_cols_array(&std::array::from_fn(|i| v[i])).transpose(),
                9 => DMat4::from_mat3(DMat3::from_cols_array(&std::array::from_fn(|i| v[i])).transpose()),
                n => return Err(SceneError::at(loc, format!("<matrix> needs 16 or 9 values, found {n}"))),
            };
            Transform::from_matrix(m)
        }
        "lookat" => {
            attrs.check(loc, &["!origin", "!target", "up"])?;
            let origin = vector3(attrs, loc, "origin")?.unwrap_or_default();
            let target = vector3(attrs, loc, "target")?.unwrap_or_default();
            let up = match vector3(attrs, loc, "up")? {
                Some(up) if up != DVec3::ZERO => up,
                // Mitsuba builds an up vector from the view direction when none is given
                _ => coordinate_system_up((target - origin).normalize_or_zero()),
            };
            Transform::look_at(origin, target, up)
        }
        other => return Err(SceneError::at(loc, format!("unknown transform operation <{other}>"))),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coordinate_system_up_is_orthonormal_to_the_direction() {
        for n in [DVec3::Z, -DVec3::Z, DVec3::X, DVec3::new(0.3, -0.5, 0.8).normalize()] {
            let up = coordinate_system_up(n);
            assert!((up.length() - 1.0).abs() < 1e-12 && up.dot(n).abs() < 1e-12, "{n} -> {up}");
        }
        assert_eq!(coordinate_system_up(DVec3::Z), DVec3::X);
    }
}
