//! PLY meshes (ASCII and binary) through `ply-rs-bw`: `vertex` elements with x, y, z and
//! optional nx, ny, nz and texture coordinates (u, v / texture_u, texture_v / s, t); `face`
//! elements with a `vertex_indices` (or `vertex_index`) list, triangulated as fans.
//!
//! Other properties become mesh attributes as Mitsuba's `find_other_fields` groups them
//! (`src/shapes/ply.h`): r, g, b (a) or red, green, blue (alpha) → `{vertex,face}_color`;
//! runs of `prefix_x/y/z`, `prefix_r/g/b`, `prefix_0/1/2` or `prefix_1/2/3` (one or three
//! fields) → `{vertex,face}_prefix` (`_prefix_color` for r/g/b). Values are read as numbers,
//! integers unscaled, as Mitsuba 3.9.1 stores them.

use crate::scene::error::{Location, SceneError};
use crate::scene::shape::Mesh;
use crate::texture::MeshAttribute;
use glam::Vec3;
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Property};
use std::path::Path;

fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v as f64,
        Property::UChar(v) => v as f64,
        Property::Short(v) => v as f64,
        Property::UShort(v) => v as f64,
        Property::Int(v) => v as f64,
        Property::UInt(v) => v as f64,
        Property::Float(v) => v as f64,
        Property::Double(v) => v as f64,
        _ => return None,
    })
}

fn list(p: &Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUChar(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListShort(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUShort(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListInt(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUInt(v) => v.iter().map(|&x| x as i64).collect(),
        _ => return None,
    })
}

/// ply-rs-bw reports ASCII errors as "Line N: …": lift N into the location.
fn parse_error(path: &Path, message: &str) -> SceneError {
    let message = message.replace('\n', " ").trim().to_string();
    let line = message
        .strip_prefix("Line ")
        .and_then(|rest| rest.split(':').next())
        .and_then(|n| n.trim().parse::<u32>().ok());
    match line {
        Some(line) => SceneError::at(
            &Location::new(path, line, 1),
            format!("invalid ply: {}", message.split_once(": ").map_or(message.as_str(), |(_, m)| m)),
        ),
        None => SceneError::file(path, format!("invalid ply: {message}")),
    }
}

/// Loads a PLY file.
pub fn load_ply(path: &Path) -> Result<Mesh, SceneError> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::file(path, format!("cannot read mesh: {e}")))?;
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut bytes.as_slice())
        .map_err(|e| parse_error(path, &e.to_string()))?;
    let ascii = ply.header.encoding == ply_rs_bw::ply::Encoding::Ascii;
    // for ASCII files, element k of the first element list sits on line header_lines + k + 1
    let header_lines =
        bytes.split(|&b| b == b'\n').position(|l| l.starts_with(b"end_header")).map_or(0, |i| i + 1) as u32;
    let vertex_loc =
        |k: usize| if ascii { Location::new(path, header_lines + k as u32 + 1, 1) } else { Location::new(path, 0, 0) };
    let vertices = ply.payload.get("vertex").ok_or_else(|| SceneError::file(path, "no \"vertex\" element"))?;
    let faces = ply.payload.get("face").ok_or_else(|| SceneError::file(path, "no \"face\" element"))?;
    let mut mesh = Mesh::default();
    let property_names = |element: &str| -> Vec<String> {
        ply.header.elements.get(element).map(|e| e.properties.keys().cloned().collect()).unwrap_or_default()
    };
    let has_normals =
        vertices.first().is_some_and(|v| v.contains_key("nx") && v.contains_key("ny") && v.contains_key("nz"));
    let mut normals = Vec::with_capacity(if has_normals { vertices.len() } else { 0 });
    // Mitsuba's names for texture coordinates, in its order of preference
    let uv_names = ["u", "texture_u", "s"]
        .iter()
        .zip(["v", "texture_v", "t"])
        .find(|(u, v)| vertices.first().is_some_and(|x| x.contains_key(**u) && x.contains_key(*v)));
    let mut uvs = Vec::new();
    for (k, v) in vertices.iter().enumerate() {
        let get = |name: &str| -> Result<f32, SceneError> {
            let p = v
                .get(name)
                .ok_or_else(|| SceneError::at(&vertex_loc(k), format!("vertex {k} has no property \"{name}\"")))?;
            let x = scalar(p)
                .ok_or_else(|| SceneError::at(&vertex_loc(k), format!("vertex property \"{name}\" must be a number")))?
                as f32;
            if !x.is_finite() {
                return Err(SceneError::at(&vertex_loc(k), format!("vertex {k} has a non-finite \"{name}\"")));
            }
            Ok(x)
        };
        mesh.positions.push(Vec3::new(get("x")?, get("y")?, get("z")?));
        if has_normals {
            normals.push(Vec3::new(get("nx")?, get("ny")?, get("nz")?).normalize_or_zero());
        }
        if let Some((u, v)) = uv_names {
            uvs.push(glam::Vec2::new(get(u)?, get(v)?));
        }
    }
    let mut reserved = vec!["x", "y", "z", "nx", "ny", "nz"];
    if let Some((u, v)) = uv_names {
        reserved.extend([*u, v]);
    }
    for (name, fields) in attribute_groups("vertex_", &property_names("vertex"), &reserved, path) {
        let data = values(vertices, &fields, |k| vertex_loc(k))?;
        mesh.attributes.push(attribute(path, name, fields.len(), data)?);
    }
    let mut face_attributes = Vec::new();
    for (name, fields) in attribute_groups("face_", &property_names("face"), &["vertex_indices", "vertex_index"], path)
    {
        let data = values(faces, &fields, |_| Location::new(path, 0, 0))?;
        face_attributes.push((name, fields.len(), data, Vec::new()));
    }
    let n = mesh.positions.len() as i64;
    for (k, f) in faces.iter().enumerate() {
        let loc = if ascii {
            Location::new(path, header_lines + vertices.len() as u32 + k as u32 + 1, 1)
        } else {
            Location::new(path, 0, 0)
        };
        let idx = f
            .get("vertex_indices")
            .or_else(|| f.get("vertex_index"))
            .and_then(list)
            .ok_or_else(|| SceneError::at(&loc, format!("face {k} has no vertex_indices list")))?;
        if idx.len() < 3 {
            return Err(SceneError::at(&loc, format!("face {k} has {} vertices (at least 3 needed)", idx.len())));
        }
        if let Some(bad) = idx.iter().find(|&&i| i < 0 || i >= n) {
            return Err(SceneError::at(&loc, format!("face {k} refers to vertex {bad}, but there are {n}")));
        }
        for j in 1..idx.len() - 1 {
            mesh.triangles.push([idx[0] as u32, idx[j] as u32, idx[j + 1] as u32]);
            // a polygon's triangles share its face attributes
            for (_, dim, data, per_triangle) in &mut face_attributes {
                per_triangle.extend_from_slice(&data[k * *dim..(k + 1) * *dim]);
            }
        }
    }
    if mesh.triangles.is_empty() {
        return Err(SceneError::file(path, "the ply file contains no faces"));
    }
    for (name, dim, _, per_triangle) in face_attributes {
        mesh.attributes.push(attribute(path, name, dim, per_triangle)?);
    }
    if has_normals {
        mesh.normals = Some(normals);
    }
    if uv_names.is_some() {
        mesh.uvs = Some(uvs);
    }
    Ok(mesh)
}

fn attribute(path: &Path, name: String, dim: usize, data: Vec<f32>) -> Result<MeshAttribute, SceneError> {
    MeshAttribute::new(name, dim, data).map_err(|e| SceneError::file(path, e.to_string()))
}

/// The values of `fields` for every element, interleaved.
fn values(
    elements: &[DefaultElement],
    fields: &[String],
    loc: impl Fn(usize) -> Location,
) -> Result<Vec<f32>, SceneError> {
    let mut out = Vec::with_capacity(elements.len() * fields.len());
    for (k, e) in elements.iter().enumerate() {
        for f in fields {
            let v = e
                .get(f)
                .and_then(scalar)
                .ok_or_else(|| SceneError::at(&loc(k), format!("property \"{f}\" of element {k} must be a number")))?;
            out.push(v as f32);
        }
    }
    Ok(out)
}

/// Mitsuba's grouping of the properties of one element (`kind` is `vertex_` or `face_`) that
/// are not `reserved` into named attributes: (attribute name, property names in order).
/// What Mitsuba ignores with a warning is ignored with one here.
fn attribute_groups(kind: &str, names: &[String], reserved: &[&str], path: &Path) -> Vec<(String, Vec<String>)> {
    let has = |n: &str| names.iter().any(|x| x == n);
    let mut groups = Vec::new();
    let mut skip: Vec<String> = reserved.iter().map(|s| s.to_string()).collect();
    let colour = if has("r") && has("g") && has("b") {
        Some(["r", "g", "b", "a"])
    } else if has("red") && has("green") && has("blue") {
        Some(["red", "green", "blue", "alpha"])
    } else {
        None
    };
    if let Some(c) = colour {
        let fields: Vec<String> = c.iter().filter(|n| has(n)).map(|n| n.to_string()).collect();
        skip.extend(c.iter().map(|n| n.to_string()));
        groups.push((format!("{kind}color"), fields));
    }
    skip.extend(["r", "g", "b", "a"].map(String::from));
    const POSTFIXES: [&[u8; 4]; 4] = [b"xr01", b"yg12", b"zb23", b"wa34"];
    let warn = |what: &str| tracing::warn!(file = %path.display(), "ply attribute ignored: {what}");
    let mut seen: Vec<String> = Vec::new();
    // the attribute being read: prefix, postfix category, fields so far
    let mut current: Option<(String, usize, Vec<String>)> = None;
    let flush = |current: &mut Option<(String, usize, Vec<String>)>,
                 groups: &mut Vec<(String, Vec<String>)>,
                 seen: &mut Vec<String>| {
        if let Some((prefix, category, fields)) = current.take() {
            if fields.len() == 1 || fields.len() == 3 {
                let suffix = if category == 1 { "_color" } else { "" };
                groups.push((format!("{kind}{prefix}{suffix}"), fields));
            } else {
                warn(&format!("\"{kind}{prefix}\" has {} fields (1 or 3 are read)", fields.len()));
            }
            seen.push(prefix);
        }
    };
    for name in names.iter().filter(|n| !skip.contains(n)) {
        let Some((prefix, postfix)) = name.rsplit_once('_').filter(|(_, p)| p.len() == 1) else {
            warn(&format!("\"{name}\" has no one-letter _postfix"));
            flush(&mut current, &mut groups, &mut seen);
            continue;
        };
        if current.as_ref().is_some_and(|(p, _, _)| p != prefix) {
            flush(&mut current, &mut groups, &mut seen);
        }
        let c = postfix.as_bytes()[0];
        match &mut current {
            None if seen.iter().any(|p| p == prefix) => warn(&format!("prefix of \"{name}\" seen before")),
            None => match POSTFIXES[0].iter().position(|&x| x == c) {
                Some(category) => current = Some((prefix.to_string(), category, vec![name.clone()])),
                None => warn(&format!("\"{name}\" cannot start an attribute")),
            },
            Some((_, category, fields)) => {
                if fields.len() < 4 && POSTFIXES[fields.len()][*category] == c {
                    fields.push(name.clone());
                } else {
                    warn(&format!("\"{name}\" breaks its attribute's postfix sequence"));
                    current = None;
                    seen.push(prefix.to_string());
                }
            }
        }
    }
    flush(&mut current, &mut groups, &mut seen);
    groups
}
