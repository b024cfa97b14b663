//! Mesh file loaders (Wavefront OBJ through `tobj`, PLY, Mitsuba's
//! `serialized` format) and the smooth
//! vertex normals Mitsuba computes when a file has none.

pub mod obj;
pub mod ply;
mod ply_format;
pub mod serialized;

use super::shape::Mesh;
use glam::Vec3;
use std::collections::HashMap;

/// Replaces the mesh's normals with angle-weighted vertex normals (Mitsuba's
/// `recompute_vertex_normals`), merging vertices that share a position so that seams from
/// texture coordinates do not show.
pub fn compute_smooth_normals(mesh: &mut Mesh) {
    let mut canonical: HashMap<[u32; 3], usize> = HashMap::new();
    let ids: Vec<usize> = mesh
        .positions
        .iter()
        .map(|p| {
            let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
            let n = canonical.len();
            *canonical.entry(key).or_insert(n)
        })
        .collect();
    let mut acc = vec![Vec3::ZERO; canonical.len()];
    for tri in &mesh.triangles {
        let p = tri.map(|i| mesh.positions[i as usize]);
        let Some(n) = (p[1] - p[0]).cross(p[2] - p[0]).try_normalize() else { continue };
        for k in 0..3 {
            let e1 = (p[(k + 1) % 3] - p[k]).normalize_or_zero();
            let e2 = (p[(k + 2) % 3] - p[k]).normalize_or_zero();
            let angle = e1.dot(e2).clamp(-1.0, 1.0).acos();
            acc[ids[tri[k] as usize]] += n * angle;
        }
    }
    let normals = ids.iter().map(|&c| acc[c].try_normalize().unwrap_or(Vec3::Z)).collect();
    mesh.normals = Some(normals);
}
