//! PLY meshes (ASCII and binary, read by `ply_format.rs`): `vertex` elements with x, y, z and
//! optional nx, ny, nz and texture coordinates (u, v / texture_u, texture_v / s, t); `face`
//! elements with a `vertex_indices` (or `vertex_index`) list, triangulated as fans.
//!
//! Other properties become mesh attributes as Mitsuba's `find_other_fields` groups them
//! (`src/shapes/ply.h`): r, g, b (a) or red, green, blue (alpha) → `{vertex,face}_color`;
//! runs of `prefix_x/y/z`, `prefix_r/g/b`, `prefix_0/1/2` or `prefix_1/2/3` (one or three
//! fields) → `{vertex,face}_prefix` (`_prefix_color` for r/g/b). Values are read as numbers,
//! integers unscaled, as Mitsuba 3.9.1 stores them.

use super::ply_format::{self, Column, ElementData};
use crate::scene::error::{Location, SceneError};
use crate::scene::shape::Mesh;
use crate::texture::MeshAttribute;
use glam::Vec3;
use std::path::Path;

/// Loads a PLY file.
pub fn load_ply(path: &Path) -> Result<Mesh, SceneError> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::file(path, format!("cannot read mesh: {e}")))?;
    load_ply_bytes(path, &bytes)
}

/// Loads PLY data; `path` names it in messages.
pub fn load_ply_bytes(path: &Path, bytes: &[u8]) -> Result<Mesh, SceneError> {
    let elements = ply_format::read(bytes, &["vertex", "face"])
        .map_err(|e| SceneError::at(&Location::new(path, e.line, 0), format!("invalid ply: {}", e.message)))?;
    let find = |name: &str| {
        elements
            .iter()
            .find(|e| e.def.name == name)
            .ok_or_else(|| SceneError::file(path, format!("no \"{name}\" element")))
    };
    let (vertices, faces) = (find("vertex")?, find("face")?);
    let at = |e: &ElementData, k: usize| Location::new(path, e.line(k), 0);
    let mut mesh = Mesh::default();
    let names = |e: &ElementData| e.def.properties.iter().map(|p| p.name.clone()).collect::<Vec<_>>();
    let vertex_names = names(vertices);
    let has = |n: &str| vertex_names.iter().any(|x| x == n);
    let count = vertices.def.count as usize;
    let position = vec3_column(path, vertices, ["x", "y", "z"], true)?;
    mesh.positions = position.ok_or_else(|| SceneError::file(path, "vertices have no x, y and z"))?;
    if has("nx") && has("ny") && has("nz") {
        let normals = vec3_column(path, vertices, ["nx", "ny", "nz"], true)?.unwrap_or_default();
        mesh.normals = Some(normals.into_iter().map(|n| n.normalize_or_zero()).collect());
    }
    let uv_names = ["u", "texture_u", "s"].iter().zip(["v", "texture_v", "t"]).find(|(u, v)| has(u) && has(v));
    if let Some((u, v)) = uv_names {
        let (u, v) = (values(path, vertices, &[u.to_string()])?, values(path, vertices, &[v.to_string()])?);
        mesh.uvs = Some((0..count).map(|k| glam::Vec2::new(u[k], v[k])).collect());
    }
    let mut reserved = vec!["x", "y", "z", "nx", "ny", "nz"];
    if let Some((u, v)) = uv_names {
        reserved.extend([*u, v]);
    }
    for (name, fields) in attribute_groups("vertex_", &vertex_names, &reserved, path) {
        let data = values(path, vertices, &fields)?;
        mesh.attributes.push(attribute(path, name, fields.len(), data)?);
    }
    let mut face_attributes = Vec::new();
    for (name, fields) in attribute_groups("face_", &names(faces), &["vertex_indices", "vertex_index"], path) {
        let data = values(path, faces, &fields)?;
        face_attributes.push((name, fields.len(), data, Vec::new()));
    }
    let lists = faces.column("vertex_indices").or_else(|| faces.column("vertex_index"));
    let Some(Column::List { offsets, items }) = lists else {
        return Err(SceneError::file(path, "faces have no vertex_indices list"));
    };
    let n = mesh.positions.len() as f64;
    for k in 0..faces.def.count as usize {
        let idx = &items[offsets[k]..offsets[k + 1]];
        if idx.len() < 3 {
            return Err(SceneError::at(
                &at(faces, k),
                format!("face {k} has {} vertices (at least 3 needed)", idx.len()),
            ));
        }
        if let Some(bad) = idx.iter().find(|&&i| !(i >= 0.0 && i < n)) {
            return Err(SceneError::at(&at(faces, k), format!("face {k} refers to vertex {bad}, but there are {n}")));
        }
        for j in 1..idx.len() - 1 {
            mesh.triangles.push([idx[0] as u32, idx[j] as u32, idx[j + 1] as u32]);
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
    Ok(mesh)
}

/// Three scalar properties as vectors, `None` if one is missing; `finite` refuses a
/// non-finite value, naming its record.
fn vec3_column(path: &Path, e: &ElementData, names: [&str; 3], finite: bool) -> Result<Option<Vec<Vec3>>, SceneError> {
    let mut cols = Vec::new();
    for name in names {
        match e.column(name) {
            Some(Column::Scalar(v)) => cols.push(v),
            Some(Column::List { .. }) => {
                return Err(SceneError::file(path, format!("vertex property \"{name}\" must be a number")));
            }
            None => return Ok(None),
        }
    }
    let mut out = Vec::with_capacity(cols[0].len());
    for k in 0..cols[0].len() {
        let p = Vec3::new(cols[0][k] as f32, cols[1][k] as f32, cols[2][k] as f32);
        if finite && let Some(i) = (0..3).find(|&i| !p[i].is_finite()) {
            let loc = Location::new(path, e.line(k), 0);
            return Err(SceneError::at(&loc, format!("vertex {k} has a non-finite \"{}\"", names[i])));
        }
        out.push(p);
    }
    Ok(Some(out))
}

fn attribute(path: &Path, name: String, dim: usize, data: Vec<f32>) -> Result<MeshAttribute, SceneError> {
    MeshAttribute::new(name, dim, data).map_err(|e| SceneError::file(path, e.to_string()))
}

/// The scalar properties `fields` of every record, interleaved.
fn values(path: &Path, e: &ElementData, fields: &[String]) -> Result<Vec<f32>, SceneError> {
    let mut cols = Vec::new();
    for f in fields {
        match e.column(f) {
            Some(Column::Scalar(v)) => cols.push(v),
            _ => {
                return Err(SceneError::file(
                    path,
                    format!("property \"{f}\" of element \"{}\" must be a number", e.def.name),
                ));
            }
        }
    }
    let mut out = Vec::with_capacity(e.def.count as usize * fields.len());
    for k in 0..e.def.count as usize {
        out.extend(cols.iter().map(|c| c[k] as f32));
    }
    Ok(out)
}

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
