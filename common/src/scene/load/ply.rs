//! PLY meshes (ASCII and binary) through `ply-rs-bw`: `vertex` elements with x, y, z and
//! optional nx, ny, nz and texture coordinates (u, v / texture_u, texture_v / s, t); `face`
//! elements with a `vertex_indices` (or `vertex_index`) list,
//! triangulated as fans.

use crate::scene::error::{Location, SceneError};
use crate::scene::shape::Mesh;
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
        }
    }
    if mesh.triangles.is_empty() {
        return Err(SceneError::file(path, "the ply file contains no faces"));
    }
    if has_normals {
        mesh.normals = Some(normals);
    }
    if uv_names.is_some() {
        mesh.uvs = Some(uvs);
    }
    Ok(mesh)
}
