//! Wavefront OBJ meshes. The text is first checked line by line so that a malformed or
//! non-finite vertex, or a face index out of range, is reported with its line; `tobj` then
//! triangulates and builds single-index vertex buffers.

use crate::scene::error::{Location, SceneError};
use crate::scene::shape::Mesh;
use glam::Vec3;
use std::path::Path;

/// Loads an OBJ file, every group into one mesh. Normals from `vn` are kept as shading normals;
/// without them the mesh is flat (the caller decides whether to compute smooth normals).
/// Texture coordinates from `vt` are kept as stored.
pub fn load_obj(path: &Path) -> Result<Mesh, SceneError> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::file(path, format!("cannot read mesh: {e}")))?;
    load_obj_bytes(path, &bytes)
}

/// Loads OBJ data; `path` names it in messages.
pub fn load_obj_bytes(path: &Path, bytes: &[u8]) -> Result<Mesh, SceneError> {
    let text = std::str::from_utf8(bytes).map_err(|e| SceneError::file(path, format!("cannot read mesh: {e}")))?;
    validate(text, path)?;
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    };
    let (models, _materials) =
        tobj::load_obj_buf(&mut text.as_bytes(), &opts, |_| Err(tobj::LoadError::GenericFailure))
            .map_err(|e| SceneError::file(path, format!("invalid obj: {e}")))?;
    let mut mesh = Mesh::default();
    let mut all_have_normals = true;
    let mut normals = Vec::new();
    let mut all_have_uvs = true;
    let mut uvs = Vec::new();
    for model in &models {
        let m = &model.mesh;
        let base = mesh.positions.len() as u32;
        mesh.positions.extend(m.positions.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])));
        if m.normals.len() == m.positions.len() && !m.normals.is_empty() {
            normals.extend(m.normals.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2]).normalize_or_zero()));
        } else {
            all_have_normals = false;
        }
        if m.texcoords.len() / 2 == m.positions.len() / 3 && !m.texcoords.is_empty() {
            uvs.extend(m.texcoords.chunks_exact(2).map(|c| glam::Vec2::new(c[0], c[1])));
        } else {
            all_have_uvs = false;
        }
        mesh.triangles.extend(m.indices.chunks_exact(3).map(|c| [c[0] + base, c[1] + base, c[2] + base]));
    }
    if mesh.triangles.is_empty() {
        return Err(SceneError::file(path, "the obj file contains no faces"));
    }
    if all_have_normals {
        mesh.normals = Some(normals);
    }
    // as stored (v up); the caller applies Mitsuba's flip_tex_coords
    if all_have_uvs {
        mesh.uvs = Some(uvs);
    }
    Ok(mesh)
}

/// Checks vertices, normals and face indices line by line.
fn validate(text: &str, path: &Path) -> Result<(), SceneError> {
    let (mut nv, mut nvt, mut nvn) = (0i64, 0i64, 0i64);
    for (i, line) in text.lines().enumerate() {
        let loc = || Location::new(path, i as u32 + 1, 1);
        let mut tokens = line.split_whitespace();
        let Some(key) = tokens.next() else { continue };
        match key {
            "v" | "vn" | "vt" => {
                let values: Vec<&str> = tokens.collect();
                let needed = if key == "vt" { 1 } else { 3 };
                if values.len() < needed {
                    return Err(SceneError::at(
                        &loc(),
                        format!("\"{key}\" needs {needed} numbers, found {}", values.len()),
                    ));
                }
                for v in values.iter().take(if key == "vt" { 3 } else { 3 }) {
                    let x: f32 = v
                        .parse()
                        .map_err(|_| SceneError::at(&loc(), format!("\"{v}\" is not a number in \"{key}\"")))?;
                    if !x.is_finite() {
                        return Err(SceneError::at(&loc(), format!("non-finite value \"{v}\" in \"{key}\"")));
                    }
                }
                match key {
                    "v" => nv += 1,
                    "vt" => nvt += 1,
                    _ => nvn += 1,
                }
            }
            "f" => {
                let corners: Vec<&str> = tokens.collect();
                if corners.len() < 3 {
                    return Err(SceneError::at(
                        &loc(),
                        format!("a face needs at least 3 vertices, found {}", corners.len()),
                    ));
                }
                for c in corners {
                    for (k, part) in c.split('/').enumerate() {
                        if part.is_empty() {
                            continue;
                        }
                        let idx: i64 = part
                            .parse()
                            .map_err(|_| SceneError::at(&loc(), format!("\"{c}\" is not a valid face vertex")))?;
                        let count = [nv, nvt, nvn][k.min(2)];
                        let resolved = if idx < 0 { count + idx + 1 } else { idx };
                        if resolved < 1 || resolved > count {
                            return Err(SceneError::at(
                                &loc(),
                                format!("face index {idx} is out of range (only {count} defined so far)"),
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}
