//! Shapes as the renderer sees them after loading: world-space triangle meshes and analytic
//! spheres and disks, each with a material, an optional area light and `flip_normals`.

use crate::geometry::Transform;
use glam::{Vec2, Vec3};

/// A world-space triangle mesh.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals (unit), when the mesh is smooth-shaded.
    pub normals: Option<Vec<Vec3>>,
    /// Vertex indices, counter-clockwise seen from the side the geometric normal points to.
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// The three corners of triangle `i`.
    #[inline]
    pub fn corners(&self, i: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[i];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
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

    /// Mitsuba's `rectangle`: [-1,1]² in z = 0 facing +z, two triangles.
    pub fn rectangle() -> Mesh {
        Mesh {
            positions: vec![
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(-1.0, 1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
            ],
            normals: None,
            triangles: vec![[1, 2, 0], [1, 3, 2]],
        }
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
                    m.positions.push(n + u * a + v * b);
                }
                m.triangles.push([base, base + 1, base + 2]);
                m.triangles.push([base, base + 2, base + 3]);
            }
        }
        m
    }
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
    /// Cumulative triangle areas (meshes that emit), normalised to end at 1.
    pub area_cdf: Vec<f32>,
    /// The XML `id`, when given (for messages).
    pub id: Option<String>,
}

/// A point on a shape's surface.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    /// Position.
    pub p: Vec3,
    /// Geometric normal (after `flip_normals`), which decides which side an area light faces.
    pub n: Vec3,
}

impl Shape {
    /// Builds the area CDF of a mesh shape so it can be sampled by area.
    pub fn prepare_area_sampling(&mut self, mesh: Option<&Mesh>) {
        if let Some(mesh) = mesh {
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
            self.area_cdf = cdf;
        }
    }

    /// Samples a point uniformly by area; the pdf is `1 / self.area`.
    pub fn sample_area(&self, meshes: &[Mesh], u: Vec2) -> SurfacePoint {
        let flip = if self.flip_normals { -1.0 } else { 1.0 };
        match &self.geometry {
            ShapeGeometry::Mesh(m) => {
                let mesh = &meshes[*m as usize];
                let i = self.area_cdf.partition_point(|&c| c <= u.x).min(self.area_cdf.len().saturating_sub(1));
                let lo = if i == 0 { 0.0 } else { self.area_cdf[i - 1] };
                let width = (self.area_cdf[i] - lo).max(1e-30);
                let ux = ((u.x - lo) / width).clamp(0.0, 1.0 - f32::EPSILON);
                let b = crate::math::warp::square_to_uniform_triangle(Vec2::new(ux, u.y));
                let [a, bb, c] = mesh.corners(i);
                let p = a * (1.0 - b.x - b.y) + bb * b.x + c * b.y;
                SurfacePoint { p, n: (bb - a).cross(c - a).normalize_or_zero() * flip }
            }
            ShapeGeometry::Sphere { center, radius } => {
                let n = crate::math::warp::square_to_uniform_sphere(u);
                SurfacePoint { p: *center + n * *radius, n: n * flip }
            }
            ShapeGeometry::Disk { to_world, normal } => {
                let d = crate::math::warp::square_to_disk_concentric(u);
                SurfacePoint { p: to_world.point(Vec3::new(d.x, d.y, 0.0)), n: *normal * flip }
            }
        }
    }
}
