//! Shapes as the renderer sees them after loading: world-space triangle meshes and analytic
//! spheres and disks, each with a material, an optional area light and `flip_normals`.

use crate::geometry::{SurfaceRef, Transform};
use crate::texture::{MeshPoint, TexturePoint};
use glam::{Vec2, Vec3};

/// A world-space triangle mesh.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals (unit), when the mesh is smooth-shaded.
    pub normals: Option<Vec<Vec3>>,
    /// Per-vertex texture coordinates, when the file has them (Mitsuba's `vertex_texcoords`);
    /// without them a point's uv is its barycentric (b1, b2), as in Mitsuba.
    pub uvs: Option<Vec<Vec2>>,
    /// Vertex indices, counter-clockwise seen from the side the geometric normal points to.
    pub triangles: Vec<[u32; 3]>,
    /// Named per-vertex or per-triangle data (PLY colours and custom properties, serialized
    /// vertex colours) for `mesh_attribute` textures.
    pub attributes: Vec<crate::texture::MeshAttribute>,
}

impl Mesh {
    /// The three corners of triangle `i`.
    #[inline]
    pub fn corners(&self, i: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[i];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }

    /// The vertex indices of corners A, B, C, D of a two-triangle mesh that is a planar
    /// parallelogram (A and C opposite, B and D on the shared diagonal, A + C = B + D up to
    /// rounding), with A in triangle 0; `None` for any other mesh.
    pub fn parallelogram(&self) -> Option<[u32; 4]> {
        let [t0, t1] = self.triangles[..] else { return None };
        let mut shared = t0.iter().filter(|i| t1.contains(i));
        let (Some(&b), Some(&d), None) = (shared.next(), shared.next(), shared.next()) else { return None };
        let a = *t0.iter().find(|i| !t1.contains(i))?;
        let c = *t1.iter().find(|i| !t0.contains(i))?;
        let [pa, pb, pc, pd] = [a, b, c, d].map(|i| self.positions[i as usize]);
        let scale = pa.abs().max(pb.abs()).max(pc.abs()).max(pd.abs()).max_element().max(1e-30);
        let degenerate = !((pb - pa).cross(pd - pa).length_squared() > 0.0);
        // both triangles wound the same way, so one normal serves both
        let normal = |t: [u32; 3]| {
            let [p0, p1, p2] = t.map(|i| self.positions[i as usize]);
            (p1 - p0).cross(p2 - p0)
        };
        if degenerate
            || !(normal(t0).dot(normal(t1)) > 0.0)
            || ((pa + pc) - (pb + pd)).abs().max_element() > 1e-6 * scale
        {
            return None;
        }
        Some([a, b, c, d])
    }

    /// Area of triangle `i`.
    pub fn triangle_area(&self, i: usize) -> f32 {
        let [a, b, c] = self.corners(i);
        0.5 * (b - a).cross(c - a).length()
    }

    /// Applies a transform to positions and normals.
    pub fn transform(&mut self, t: &Transform) {
        for p in &mut self.positions {
            *p = t.point(*p);
        }
        if let Some(ns) = &mut self.normals {
            for n in ns {
                *n = t.normal(*n).normalize_or_zero();
            }
        }
    }

    /// Mitsuba's `rectangle`: [-1,1]² in z = 0 facing +z, two triangles, uv = ((x+1)/2, (y+1)/2).
    pub fn rectangle() -> Mesh {
        let positions = vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
        ];
        let uvs = positions.iter().map(|p| Vec2::new((p.x + 1.0) * 0.5, (p.y + 1.0) * 0.5)).collect();
        Mesh { positions, normals: None, uvs: Some(uvs), triangles: vec![[1, 2, 0], [1, 3, 2]], attributes: vec![] }
    }

    /// Mitsuba's `cube`: [-1,1]³ with outward faces, 24 vertices (flat shading).
    pub fn cube() -> Mesh {
        let mut m = Mesh::default();
        // each face: outward normal axis and sign; corners wound counter-clockwise seen from outside
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                let n = Vec3::from(std::array::from_fn(|i| if i == axis { sign } else { 0.0 }));
                let u = Vec3::from(std::array::from_fn(|i| if i == (axis + 1) % 3 { 1.0 } else { 0.0 }));
                let v = n.cross(u);
                let base = m.positions.len() as u32;
                for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                    let p = n + u * a + v * b;
                    m.positions.push(p);
                    m.uvs.get_or_insert_with(Vec::new).push(cube_uv(axis, sign, p));
                }
                m.triangles.push([base, base + 1, base + 2]);
                m.triangles.push([base, base + 2, base + 3]);
            }
        }
        m
    }
}

/// Mitsuba's `cube` parameterisation (`src/shapes/cube.cpp`): each face onto [0, 1]².
fn cube_uv(axis: usize, sign: f32, p: Vec3) -> Vec2 {
    let (x, y, z) = (p.x, p.y, p.z);
    let uv = match (axis, sign > 0.0) {
        (0, true) => (y + 1.0, 1.0 - z),
        (0, false) => (y + 1.0, 1.0 + z),
        (1, true) => (1.0 - x, 1.0 - z),
        (1, false) => (1.0 + z, 1.0 + x),
        (2, true) => (1.0 + y, 1.0 + x),
        _ => (1.0 - y, 1.0 + x),
    };
    Vec2::new(uv.0 * 0.5, uv.1 * 0.5)
}

/// The geometry of a shape.
#[derive(Clone, Debug)]
pub enum ShapeGeometry {
    /// Index into `Scene::meshes`.
    Mesh(u32),
    /// An analytic sphere.
    Sphere {
        /// World-space centre.
        center: Vec3,
        /// Radius.
        radius: f32,
    },
    /// Mitsuba's `disk`: the unit disk in z = 0 facing +z, under `to_world` (ellipses allowed).
    Disk {
        /// Object to world.
        to_world: Transform,
        /// World-space unit normal (before `flip_normals`).
        normal: Vec3,
    },
}

/// A shape of the scene.
#[derive(Clone, Debug)]
pub struct Shape {
    /// Its geometry.
    pub geometry: ShapeGeometry,
    /// Index into `Scene::materials`.
    pub material: u32,
    /// Index into `Scene::lights` when the shape emits.
    pub light: Option<u32>,
    /// Flip geometric and shading normals.
    pub flip_normals: bool,
    /// Total surface area.
    pub area: f32,
    /// How an emitting mesh is sampled by area (see [`Shape::prepare_area_sampling`]).
    pub area_sampling: AreaSampling,
    /// The XML `id`, when given (for messages).
    pub id: Option<String>,
    /// World to the shape's object frame, rotation only: where a sphere's uv is measured.
    pub object_rotation: glam::Mat3,
}

/// Area sampling of an emitting mesh.
#[derive(Clone, Debug, Default)]
pub enum AreaSampling {
    /// Not prepared (non-emitting shapes, analytic shapes).
    #[default]
    None,
    /// A planar parallelogram (two triangles, Mitsuba's `rectangle`): `origin + u·e1 + v·e2`.
    Parallelogram {
        /// Corner at u = v = 0.
        origin: Vec3,
        /// Edge along u.
        e1: Vec3,
        /// Edge along v.
        e2: Vec3,
        /// Unit geometric normal of the triangles (before `flip_normals`).
        normal: Vec3,
        /// For each triangle (the first holds A, B, D; the second C, B, D, with A the origin,
        /// B = A + e1, D = A + e2), which of those three corners are its second and third
        /// vertices: where a sampled point's barycentrics (b1, b2) come from.
        bary_slots: [[u8; 2]; 2],
    },
    /// Any triangle mesh: a triangle by area, then a point in it.
    Triangles {
        /// Cumulative triangle areas, normalised to end at 1.
        cdf: Vec<f32>,
    },
}

/// A point on a shape's surface.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    /// Position.
    pub p: Vec3,
    /// Geometric normal (after `flip_normals`), which decides which side an area light faces.
    pub n: Vec3,
    /// Triangle and barycentrics (zero on analytic shapes), for textured emission.
    pub prim: u32,
    /// Barycentric coordinates (b1, b2).
    pub bary: Vec2,
}

impl SurfacePoint {
    /// A point of an analytic shape (no triangle).
    pub fn analytic(p: Vec3, n: Vec3) -> Self {
        SurfacePoint { p, n, prim: 0, bary: Vec2::ZERO }
    }
}

/// The texture coordinates of point `p` at `at`, in Mitsuba's parameterisation of the shape:
/// a mesh's interpolated uvs (or its barycentrics when it has none), a sphere's
/// (atan2(y, x)/2π, acos(z)/π) and a disk's (r, φ/2π) in object space. Computed on demand, so
/// that scenes without textures do not pay for it.
pub fn surface_uv(shapes: &[Shape], meshes: &[Mesh], at: SurfaceRef, p: Vec3) -> Vec2 {
    use std::f32::consts::PI;
    let shape = &shapes[at.shape as usize];
    let wrap = |a: f32| {
        let u = a / (2.0 * PI);
        if u < 0.0 { u + 1.0 } else { u }
    };
    match &shape.geometry {
        ShapeGeometry::Mesh(m) => {
            let mesh = &meshes[*m as usize];
            let Some(uvs) = &mesh.uvs else { return at.bary };
            let [i0, i1, i2] = mesh.triangles[at.prim as usize];
            let (b1, b2) = (at.bary.x, at.bary.y);
            uvs[i0 as usize] * (1.0 - b1 - b2) + uvs[i1 as usize] * b1 + uvs[i2 as usize] * b2
        }
        ShapeGeometry::Sphere { center, .. } => {
            let d = (shape.object_rotation * (p - *center)).normalize_or_zero();
            Vec2::new(wrap(d.y.atan2(d.x)), d.z.clamp(-1.0, 1.0).acos() / PI)
        }
        ShapeGeometry::Disk { to_world, .. } => {
            let q = to_world.inv_point(p);
            Vec2::new(Vec2::new(q.x, q.y).length(), wrap(q.y.atan2(q.x)))
        }
    }
}

/// What a texture lookup at `p` (at `at`) needs; the mesh triangle only when `with_mesh`
/// (`mesh_attribute` textures).
pub fn texture_point<'a>(
    shapes: &[Shape],
    meshes: &'a [Mesh],
    at: SurfaceRef,
    p: Vec3,
    with_mesh: bool,
) -> TexturePoint<'a> {
    let uv = surface_uv(shapes, meshes, at, p);
    let mesh = match (&shapes[at.shape as usize].geometry, with_mesh) {
        (ShapeGeometry::Mesh(m), true) => {
            let mesh = &meshes[*m as usize];
            let (b1, b2) = (at.bary.x, at.bary.y);
            Some(MeshPoint {
                attributes: &mesh.attributes,
                face: at.prim,
                vertices: mesh.triangles[at.prim as usize],
                barycentric: Vec3::new(1.0 - b1 - b2, b1, b2),
            })
        }
        _ => None,
    };
    TexturePoint { uv, mesh }
}

/// The triangle and its (b1, b2) of the parallelogram point `A + u·e1 + v·e2`: the first
/// triangle (A, B, D) when u + v ≤ 1, else the second (C, B, D).
#[inline]
fn parallelogram_barycentrics(slots: &[[u8; 2]; 2], u: Vec2) -> (u32, Vec2) {
    // selects rather than a branch: the two triangles are equally likely, so a branch here
    // mispredicts every other light sample
    let second = u.x + u.y > 1.0;
    let s = u.x + u.y - 1.0;
    let weights =
        [if second { s } else { -s }, if second { 1.0 - u.y } else { u.x }, if second { 1.0 - u.x } else { u.y }];
    let [s1, s2] = slots[second as usize];
    (second as u32, Vec2::new(weights[s1 as usize], weights[s2 as usize]))
}

impl Shape {
    /// Prepares sampling by area: parallelograms map the square linearly (no triangle choice,
    /// no square root); other meshes get a CDF over triangle areas.
    pub fn prepare_area_sampling(&mut self, mesh: Option<&Mesh>) {
        let Some(mesh) = mesh else { return };
        if let Some(corners) = mesh.parallelogram() {
            let [origin, b, _, d] = corners.map(|i| mesh.positions[i as usize]);
            let (e1, e2) = (b - origin, d - origin);
            // both triangles share this normal; orient it like triangle 0's winding
            let [p0, p1, p2] = mesh.corners(0);
            let normal = (p1 - p0).cross(p2 - p0).normalize_or_zero();
            let [a, b, c, d] = corners;
            let slot = |order: [u32; 3], v: u32| order.iter().position(|&x| x == v).unwrap_or(0) as u8;
            let slots = |t: [u32; 3], order: [u32; 3]| [slot(order, t[1]), slot(order, t[2])];
            let bary_slots = [slots(mesh.triangles[0], [a, b, d]), slots(mesh.triangles[1], [c, b, d])];
            self.area_sampling = AreaSampling::Parallelogram { origin, e1, e2, normal, bary_slots };
            return;
        }
        let mut acc = 0.0f64;
        let mut cdf = Vec::with_capacity(mesh.triangles.len());
        for i in 0..mesh.triangles.len() {
            acc += mesh.triangle_area(i) as f64;
            cdf.push(acc as f32);
        }
        let total = acc.max(1e-30) as f32;
        for c in &mut cdf {
            *c /= total;
        }
        self.area_sampling = AreaSampling::Triangles { cdf };
    }

    /// Samples a point uniformly by area; the pdf is `1 / self.area`. A parallelogram reports
    /// its triangle and barycentrics only `with_surface` (textured emitters need them; the
    /// untextured common case should not pay for them).
    pub fn sample_area(&self, meshes: &[Mesh], u: Vec2, with_surface: bool) -> SurfacePoint {
        let flip = if self.flip_normals { -1.0 } else { 1.0 };
        match &self.geometry {
            ShapeGeometry::Mesh(m) => {
                let cdf = match &self.area_sampling {
                    AreaSampling::Parallelogram { origin, e1, e2, normal, bary_slots } => {
                        let p = *origin + *e1 * u.x + *e2 * u.y;
                        let (prim, bary) =
                            if with_surface { parallelogram_barycentrics(bary_slots, u) } else { (0, Vec2::ZERO) };
                        return SurfacePoint { p, n: *normal * flip, prim, bary };
                    }
                    AreaSampling::Triangles { cdf } => cdf,
                    AreaSampling::None => unreachable!("invariant: emitting meshes are prepared for sampling"),
                };
                let mesh = &meshes[*m as usize];
                let i = cdf.partition_point(|&c| c <= u.x).min(cdf.len().saturating_sub(1));
                let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
                let width = (cdf[i] - lo).max(1e-30);
                let ux = ((u.x - lo) / width).clamp(0.0, 1.0 - f32::EPSILON);
                let b = crate::math::warp::square_to_uniform_triangle(Vec2::new(ux, u.y));
                let [a, bb, c] = mesh.corners(i);
                let p = a * (1.0 - b.x - b.y) + bb * b.x + c * b.y;
                SurfacePoint { p, n: (bb - a).cross(c - a).normalize_or_zero() * flip, prim: i as u32, bary: b }
            }
            ShapeGeometry::Sphere { center, radius } => {
                let n = crate::math::warp::square_to_uniform_sphere(u);
                SurfacePoint::analytic(*center + n * *radius, n * flip)
            }
            ShapeGeometry::Disk { to_world, normal } => {
                let d = crate::math::warp::square_to_disk_concentric(u);
                SurfacePoint::analytic(to_world.point(Vec3::new(d.x, d.y, 0.0)), *normal * flip)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sampled point reports the triangle and barycentrics it lies at, on parallelograms
    /// (both triangles, either winding) and on meshes sampled by triangle area.
    #[test]
    fn area_samples_report_their_triangle_and_barycentrics() {
        let t = Transform::rotate(glam::DVec3::new(1.0, 2.0, 0.5), 37.0).expect("rotation");
        let mut rect = Mesh::rectangle();
        rect.transform(&t);
        let mut flipped = rect.clone();
        flipped.triangles.iter_mut().for_each(|t| t.swap(1, 2));
        let mut cube = Mesh::cube();
        cube.transform(&t);
        for mesh in [rect, flipped, cube] {
            let mut shape = Shape {
                geometry: ShapeGeometry::Mesh(0),
                material: 0,
                light: None,
                flip_normals: false,
                area: 1.0,
                area_sampling: Default::default(),
                id: None,
                object_rotation: glam::Mat3::IDENTITY,
            };
            shape.prepare_area_sampling(Some(&mesh));
            let meshes = [mesh];
            for i in 0..64 {
                let u = Vec2::new((i % 8) as f32 / 8.0 + 0.03, (i / 8) as f32 / 8.0 + 0.05);
                let sp = shape.sample_area(&meshes, u, true);
                let [a, b, c] = meshes[0].corners(sp.prim as usize);
                let p = a * (1.0 - sp.bary.x - sp.bary.y) + b * sp.bary.x + c * sp.bary.y;
                assert!((p - sp.p).length() < 1e-5, "{u}: {p} vs {}", sp.p);
                assert!(sp.bary.min_element() >= -1e-6 && sp.bary.element_sum() <= 1.0 + 1e-6);
            }
        }
    }
}
