//! Ray queries against all shapes: one obvhs compressed wide BVH (CWBVH) over triangles,
//! spheres and disks, collapsed from the binary tree of [`super::sah`]. This is the only
//! module that imports obvhs; everything else sees [`Accel::closest_hit`] and
//! [`Accel::occluded`].
//!
//! Triangles use the watertight test of Woop, Benthin and Wald (JCGT 2013), so rays through
//! shared edges and vertices of a closed mesh always hit one of the triangles: no light leaks.

use super::sah::{self, Bounds};
use super::shape::{Mesh, Shape, ShapeGeometry};
use crate::geometry::Ray;
use glam::UVec2;
use glam::{Mat3A, Vec3, Vec3A};
use obvhs::{
    aabb::Aabb,
    bvh2::{Bvh2, node::Bvh2Node},
    cwbvh::{CwBvh, Traversal, bvh2_to_cwbvh::bvh2_to_cwbvh},
};

/// What the BVH stores per primitive, in BVH order.
#[derive(Clone, Copy, Debug)]
enum Geom {
    Triangle([Vec3A; 3]),
    Sphere { center: Vec3, radius: f32 },
    Disk { index: u32 },
    Quad { index: u32 },
}

#[derive(Clone, Copy, Debug)]
struct Prim {
    geom: Geom,
    shape: u32,
    index: u32,
}

impl Prim {
    fn bounds(&self) -> Bounds {
        match self.geom {
            Geom::Triangle([a, b, c]) => Bounds { lo: a.min(b).min(c).into(), hi: a.max(b).max(c).into() },
            Geom::Sphere { center, radius } => Bounds { lo: center - radius, hi: center + radius },
            Geom::Disk { .. } | Geom::Quad { .. } => {
                unreachable!("invariant: disk and quad bounds are computed before the build")
            }
        }
    }
}

/// The result of a closest-hit query.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the ray.
    pub t: f32,
    /// Shape index.
    pub shape: u32,
    /// Triangle index within the shape's mesh (0 for analytic shapes).
    pub index: u32,
    /// Barycentric coordinates (b1, b2) on a triangle.
    pub bary: [f32; 2],
}

/// The acceleration structure.
pub struct Accel {
    bvh: CwBvh,
    prims: Vec<Prim>,
    disks: Vec<glam::Mat4>,
    quads: Vec<Quad>,
    has_triangles: bool,
}

/// A corner of a [`Quad`]: A at (α, β) = (0, 0), B at (1, 0), C at (1, 1), D at (0, 1).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Corner {
    A,
    B,
    C,
    D,
}

/// A two-triangle mesh that is a planar parallelogram (Mitsuba's `rectangle`), tested as one
/// primitive: one plane test instead of two triangle tests, and nothing to leak through on
/// the shared diagonal. Hits report the triangle and barycentrics the mesh would have given.
#[derive(Clone, Copy, Debug)]
struct Quad {
    origin: Vec3A,
    normal: Vec3A,
    /// q·dual_α = α for a point q = origin + α·(B − A) + β·(D − A) in the plane.
    dual_alpha: Vec3A,
    dual_beta: Vec3A,
    /// Triangle 0 holds A (α + β ≤ 1), triangle 1 holds C; the corners of each triangle's
    /// second and third vertices, whose weights are the barycentrics.
    bary_corners: [[Corner; 2]; 2],
}

impl Quad {
    /// Recognises a parallelogram made of two triangles sharing a diagonal.
    fn from_mesh(mesh: &Mesh) -> Option<Quad> {
        let [a, b, c, d] = mesh.parallelogram()?;
        // plane and duals in double precision: grazing rays amplify any error of the normal
        let p = |i: u32| mesh.positions[i as usize].as_dvec3();
        let (pa, e1, e2) = (p(a), p(b) - p(a), p(d) - p(a));
        let normal = e1.cross(e2);
        let n2 = normal.length_squared();
        let corner = |i: u32| match i {
            i if i == a => Corner::A,
            i if i == b => Corner::B,
            i if i == c => Corner::C,
            _ => Corner::D,
        };
        let [t0, t1] = [mesh.triangles[0], mesh.triangles[1]];
        Some(Quad {
            origin: Vec3A::from(pa.as_vec3()),
            normal: Vec3A::from((normal / n2.sqrt()).as_vec3()),
            dual_alpha: Vec3A::from((e2.cross(normal) / n2).as_vec3()),
            dual_beta: Vec3A::from((normal.cross(e1) / n2).as_vec3()),
            bary_corners: [[corner(t0[1]), corner(t0[2])], [corner(t1[1]), corner(t1[2])]],
        })
    }

    fn bounds(&self, mesh: &Mesh) -> Bounds {
        let (lo, hi) = mesh
            .positions
            .iter()
            .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        Bounds { lo, hi }
    }

    /// Returns (t, triangle, b1, b2) for a hit in (0, tmax).
    #[inline(always)]
    fn intersect(&self, o: Vec3A, d: Vec3A, tmax: f32) -> Option<(f32, u32, f32, f32)> {
        let t = (self.origin - o).dot(self.normal) / d.dot(self.normal);
        if !(t > 0.0 && t < tmax) {
            return None;
        }
        let q = o + d * t - self.origin;
        let (alpha, beta) = (q.dot(self.dual_alpha), q.dot(self.dual_beta));
        if !((0.0..=1.0).contains(&alpha) && (0.0..=1.0).contains(&beta)) {
            return None;
        }
        let triangle = (alpha + beta > 1.0) as u32;
        let weight = |corner: Corner| match corner {
            Corner::A => 1.0 - alpha - beta,
            Corner::B if triangle == 0 => alpha,
            Corner::B => 1.0 - beta,
            Corner::C => alpha + beta - 1.0,
            Corner::D if triangle == 0 => beta,
            Corner::D => 1.0 - alpha,
        };
        let [c1, c2] = self.bary_corners[triangle as usize];
        Some((t, triangle, weight(c1), weight(c2)))
    }
}

/// Per-ray constants of the watertight triangle test: the permutation that makes the
/// direction's largest axis z, and the shear that maps the direction onto +z, folded into one
/// matrix so that a vertex is transformed by three SIMD multiply-adds. Each output lane sums
/// one rounded product with exact terms (the vertex coordinate times 1, and zeros), so it is
/// bit-identical to the paper's `a[kx] - Sx·a[kz]` and edges stay watertight.
struct WatertightRay {
    shear: Mat3A,
}

impl WatertightRay {
    fn new(d: Vec3) -> Self {
        let a = d.abs();
        let kz = if a.x > a.y {
            if a.x > a.z { 0 } else { 2 }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let (sx, sy, sz) = (d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]);
        const UNIT: [Vec3A; 3] = [Vec3A::X, Vec3A::Y, Vec3A::Z];
        let unit = |k: usize| UNIT[k];
        // rows: x' = v[kx] − sx·v[kz], y' = v[ky] − sy·v[kz], z' = sz·v[kz]
        let rows = Mat3A::from_cols(unit(kx) - sx * unit(kz), unit(ky) - sy * unit(kz), sz * unit(kz));
        WatertightRay { shear: rows.transpose() }
    }

    /// Returns (t, b1, b2) for a hit in (0, tmax).
    #[inline(always)]
    fn intersect(&self, o: Vec3A, tmax: f32, tri: &[Vec3A; 3]) -> Option<(f32, f32, f32)> {
        let a = self.shear * (tri[0] - o);
        let b = self.shear * (tri[1] - o);
        let c = self.shear * (tri[2] - o);
        let mut u = c.x * b.y - c.y * b.x;
        let mut v = a.x * c.y - a.y * c.x;
        let mut w = b.x * a.y - b.y * a.x;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            // fall back to double precision on edges so that the sign test is exact
            u = (c.x as f64 * b.y as f64 - c.y as f64 * b.x as f64) as f32;
            v = (a.x as f64 * c.y as f64 - a.y as f64 * c.x as f64) as f32;
            w = (b.x as f64 * a.y as f64 - b.y as f64 * a.x as f64) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let t_scaled = u * a.z + v * b.z + w * c.z;
        if (det > 0.0 && (t_scaled <= 0.0 || t_scaled >= tmax * det))
            || (det < 0.0 && (t_scaled >= 0.0 || t_scaled <= tmax * det))
        {
            return None;
        }
        let inv = 1.0 / det;
        Some((t_scaled * inv, v * inv, w * inv))
    }
}

fn intersect_sphere(o: Vec3, d: Vec3, tmax: f32, center: Vec3, radius: f32) -> Option<f32> {
    // double precision: the far root of a ray leaving the inside of a small sphere is accurate
    let oc = (o - center).as_dvec3();
    let dd = d.as_dvec3();
    let b = oc.dot(dd);
    let c = oc.length_squared() - (radius as f64) * (radius as f64);
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    // numerically stable roots
    let q = if b > 0.0 { -b - sq } else { -b + sq };
    let (mut t0, mut t1) = (q, if q != 0.0 { c / q } else { 0.0 });
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    let t = if t0 > 0.0 { t0 } else { t1 };
    (t > 0.0 && t < tmax as f64).then_some(t as f32)
}

fn intersect_disk(o: Vec3, d: Vec3, tmax: f32, to_local: &glam::Mat4) -> Option<f32> {
    let ol = to_local.transform_point3(o);
    let dl = to_local.transform_vector3(d);
    if dl.z == 0.0 {
        return None;
    }
    let t = -ol.z / dl.z;
    if !(t > 0.0 && t < tmax) {
        return None;
    }
    let p = ol + dl * t;
    (p.x * p.x + p.y * p.y <= 1.0).then_some(t)
}

/// Collapses the SAH builder's binary tree into obvhs's compressed wide BVH.
fn wide_from_binary(bounds: &[Bounds]) -> CwBvh {
    let binary = sah::build(bounds);
    if binary.nodes.is_empty() {
        return CwBvh::default();
    }
    let nodes = binary
        .nodes
        .iter()
        .map(|n| {
            let aabb = Aabb::new(Vec3A::from(n.bounds.lo), Vec3A::from(n.bounds.hi));
            Bvh2Node::new(aabb, n.leaf as u32, n.first)
        })
        .collect();
    let bvh2 = Bvh2 { nodes, primitive_indices: binary.order, ..Default::default() };
    // three primitives per leaf, the most the compressed format holds
    bvh2_to_cwbvh(&bvh2, 3, true, false)
}

impl Accel {
    /// Builds the BVH over every shape.
    pub fn build(shapes: &[Shape], meshes: &[Mesh]) -> Accel {
        let mut prims = Vec::new();
        let mut disks = Vec::new();
        let mut quads = Vec::new();
        let mut bounds = Vec::new();
        for (si, shape) in shapes.iter().enumerate() {
            match &shape.geometry {
                ShapeGeometry::Mesh(m) => {
                    let mesh = &meshes[*m as usize];
                    if let Some(quad) = Quad::from_mesh(mesh) {
                        bounds.push(quad.bounds(mesh));
                        prims.push(Prim { geom: Geom::Quad { index: quads.len() as u32 }, shape: si as u32, index: 0 });
                        quads.push(quad);
                        continue;
                    }
                    for ti in 0..mesh.triangles.len() {
                        let p = Prim {
                            geom: Geom::Triangle(mesh.corners(ti).map(Vec3A::from)),
                            shape: si as u32,
                            index: ti as u32,
                        };
                        bounds.push(p.bounds());
                        prims.push(p);
                    }
                }
                ShapeGeometry::Sphere { center, radius } => {
                    let p =
                        Prim { geom: Geom::Sphere { center: *center, radius: *radius }, shape: si as u32, index: 0 };
                    bounds.push(p.bounds());
                    prims.push(p);
                }
                ShapeGeometry::Disk { to_world, .. } => {
                    let mut lo = Vec3::splat(f32::MAX);
                    let mut hi = Vec3::splat(f32::MIN);
                    for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
                        let p = to_world.point(Vec3::new(x, y, 0.0));
                        lo = lo.min(p);
                        hi = hi.max(p);
                    }
                    let pad = (hi - lo).max_element() * 1e-4 + 1e-6;
                    bounds.push(Bounds { lo: lo - pad, hi: hi + pad });
                    prims.push(Prim { geom: Geom::Disk { index: disks.len() as u32 }, shape: si as u32, index: 0 });
                    disks.push(to_world.inv_f32());
                }
            }
        }
        let bvh = wide_from_binary(&bounds);
        // store primitives in BVH leaf order so the traversal callback indexes them directly
        let prims: Vec<Prim> = bvh.primitive_indices.iter().map(|&i| prims[i as usize]).collect();
        let has_triangles = prims.iter().any(|p: &Prim| matches!(p.geom, Geom::Triangle(_)));
        Accel { bvh, prims, disks, quads, has_triangles }
    }

    /// Number of primitives.
    pub fn primitive_count(&self) -> usize {
        self.prims.len()
    }

    #[inline(always)]
    /// Returns (t, triangle index offset, b1, b2).
    fn intersect_prim(
        &self,
        prim: &Prim,
        wt: &WatertightRay,
        o: Vec3,
        d: Vec3,
        tmax: f32,
    ) -> Option<(f32, u32, f32, f32)> {
        match &prim.geom {
            Geom::Triangle(tri) => wt.intersect(Vec3A::from(o), tmax, tri).map(|(t, b1, b2)| (t, 0, b1, b2)),
            Geom::Quad { index } => self.quads[*index as usize].intersect(Vec3A::from(o), Vec3A::from(d), tmax),
            Geom::Sphere { center, radius } => intersect_sphere(o, d, tmax, *center, *radius).map(|t| (t, 0, 0.0, 0.0)),
            Geom::Disk { index } => intersect_disk(o, d, tmax, &self.disks[*index as usize]).map(|t| (t, 0, 0.0, 0.0)),
        }
    }

    /// The triangle test's per-ray constants; scenes without triangles (rectangles and
    /// spheres only) skip computing them.
    #[inline(always)]
    fn watertight_ray(&self, d: Vec3) -> WatertightRay {
        if self.has_triangles { WatertightRay::new(d) } else { WatertightRay { shear: Mat3A::ZERO } }
    }

    fn obvhs_ray(ray: &Ray) -> obvhs::ray::Ray {
        // obvhs takes the sign of 1/d from `signum`, which is -1 for -0.0, but classifies the
        // direction with `d < 0`, which is false for -0.0: the slab test then inverts and the
        // BVH is missed. Adding +0.0 turns -0.0 into +0.0.
        let direction = Vec3A::from(ray.d + Vec3::ZERO);
        // obvhs's `safe_inverse` per lane (±1/ε below ε), as one vector division and a select
        // instead of three branches and three scalar divisions
        let tiny = direction.abs().cmple(Vec3A::splat(f32::EPSILON));
        let inv_direction =
            Vec3A::select(tiny, direction.signum() / f32::EPSILON, Vec3A::ONE / direction);
        obvhs::ray::Ray { origin: Vec3A::from(ray.o), direction, inv_direction, tmin: 0.0, tmax: ray.tmax }
    }

    /// The closest intersection in `(0, ray.tmax)`.
    pub fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        if self.prims.is_empty() {
            return None;
        }
        let wt = self.watertight_ray(ray.d);
        let mut traverse_ray = Self::obvhs_ray(ray);
        let mut best: Option<Hit> = None;
        TRAVERSAL.with_borrow_mut(|state| {
            state.reinit(traverse_ray.direction);
            let mut node;
            obvhs::traverse!(self.bvh, node, state, node.intersect_ray(&traverse_ray, state.oct_inv4), {
                let prim = &self.prims[state.primitive_id as usize];
                if let Some((t, offset, b1, b2)) = self.intersect_prim(prim, &wt, ray.o, ray.d, traverse_ray.tmax) {
                    best = Some(Hit { t, shape: prim.shape, index: prim.index + offset, bary: [b1, b2] });
                    traverse_ray.tmax = t;
                }
            });
        });
        best
    }

    /// Whether anything blocks the ray in `(0, ray.tmax)`.
    pub fn occluded(&self, ray: &Ray) -> bool {
        if self.prims.is_empty() {
            return false;
        }
        let wt = self.watertight_ray(ray.d);
        let traverse_ray = Self::obvhs_ray(ray);
        let mut hit = false;
        TRAVERSAL.with_borrow_mut(|state| {
            state.reinit(traverse_ray.direction);
            let mut node;
            'outer: {
                obvhs::traverse!(self.bvh, node, state, node.intersect_ray(&traverse_ray, state.oct_inv4), {
                    if self
                        .intersect_prim(&self.prims[state.primitive_id as usize], &wt, ray.o, ray.d, ray.tmax)
                        .is_some()
                    {
                        hit = true;
                        break 'outer;
                    }
                });
            }
        });
        hit
    }
}

thread_local! {
    /// Each thread's traversal stack, reused so that no ray pays for zeroing a fresh one.
    static TRAVERSAL: std::cell::RefCell<Traversal> = std::cell::RefCell::new(Traversal::default());
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Transform;
    use crate::sampler::Sampler;
    use glam::DVec3;

    fn cube_scene(t: &Transform) -> (Vec<Shape>, Vec<Mesh>) {
        let mut mesh = Mesh::cube();
        mesh.transform(t);
        let shape = Shape {
            geometry: ShapeGeometry::Mesh(0),
            material: 0,
            light: None,
            flip_normals: false,
            area: 1.0,
            area_sampling: Default::default(),
            id: None,
        };
        (vec![shape], vec![mesh])
    }

    /// Rays aimed exactly at shared edges and vertices of a closed mesh always hit it, and rays
    /// from inside never escape.
    #[test]
    fn closed_mesh_has_no_leaks_at_edges_and_vertices() {
        let t = Transform::translate(DVec3::new(0.3, -0.2, 0.7))
            .after(&Transform::rotate(DVec3::new(1.0, 2.0, 3.0).normalize(), 37.0).unwrap());
        let (shapes, meshes) = cube_scene(&t);
        let accel = Accel::build(&shapes, &meshes);
        let center = t.point(Vec3::ZERO);
        let mesh = &meshes[0];
        let mut targets = Vec::new();
        for tri in &mesh.triangles {
            let c = tri.map(|i| mesh.positions[i as usize]);
            for k in 0..3 {
                targets.push(c[k]);
                for f in [0.25f32, 0.5, 0.75] {
                    targets.push(c[k] * (1.0 - f) + c[(k + 1) % 3] * f);
                }
            }
        }
        let mut misses_in = 0;
        let mut misses_out = 0;
        for (i, target) in targets.iter().enumerate() {
            // from the centre outwards, through an edge or vertex
            let d = (*target - center).normalize();
            if accel.closest_hit(&Ray::new(center, d)).is_none() {
                misses_in += 1;
            }
            // from outside, through the edge or vertex towards a point inside: the ray must
            // enter the solid exactly there (rays that only graze a silhouette are not tested)
            let mut s = Sampler::for_pixel(1, i as u32, 0);
            let inner = center + (s.next_2d().extend(s.next_1d()) - 0.5) * 0.8;
            let origin = *target + (*target - inner) * 2.0;
            let from_out = Ray::new(origin, (*target - origin).normalize());
            match accel.closest_hit(&from_out) {
                Some(h) if (from_out.at(h.t) - *target).length() < 1e-4 => {}
                _ => misses_out += 1,
            }
        }
        assert_eq!(misses_in, 0, "rays from inside escaped through edges or vertices");
        assert_eq!(misses_out, 0, "rays aimed at edges or vertices passed through");
        // random rays from inside never escape
        for i in 0..100_000u32 {
            let mut s = Sampler::for_pixel(2, i, 0);
            let d = crate::math::warp::square_to_uniform_sphere(s.next_2d());
            let o = center + (s.next_2d().extend(s.next_1d()) - 0.5) * 0.5;
            assert!(accel.closest_hit(&Ray::new(o, d)).is_some(), "escaped from inside at ray {i}");
        }
    }

    /// A rectangle is tested as one quad. Against the exact (f64) plane intersection, its
    /// distance and its hit point (rebuilt from the reported triangle and barycentrics, as
    /// `Scene::intersect` does) are within a few roundings times the conditioning of the ray
    /// meeting the plane, and rays clearly inside hit while rays clearly outside miss.
    #[test]
    fn rectangle_quad_hits_match_the_exact_plane() {
        let t = Transform::translate(DVec3::new(0.2, 0.1, -0.4))
            .after(&Transform::rotate(DVec3::new(0.3, 1.0, -0.5).normalize(), 61.0).unwrap())
            .after(&Transform::scale(DVec3::new(1.5, 0.7, 1.0)).unwrap());
        let mut mesh = Mesh::rectangle();
        mesh.transform(&t);
        let [a, b, _, d] = mesh.parallelogram().unwrap().map(|i| mesh.positions[i as usize].as_dvec3());
        let (e1, e2) = (b - a, d - a);
        let n = e1.cross(e2);
        let (mut shapes, _) = cube_scene(&Transform::IDENTITY);
        shapes.truncate(1);
        let accel = Accel::build(&shapes, std::slice::from_ref(&mesh));
        assert!(matches!(accel.prims[..], [Prim { geom: Geom::Quad { .. }, .. }]));
        let (mut hits, mut misses) = (0, 0);
        for i in 0..20_000u32 {
            let mut s = Sampler::for_pixel(3, i, 0);
            // points on a slightly larger rectangle, seen from random origins on both sides
            let local = (s.next_2d() * 2.0 - 1.0) * 1.1;
            let target = t.point(Vec3::new(local.x, local.y, 0.0));
            let origin = target + crate::math::warp::square_to_uniform_sphere(s.next_2d()) * 3.0;
            let ray = Ray::new(origin, (target - origin).normalize());
            let (o, dir) = (ray.o.as_dvec3(), ray.d.as_dvec3());
            let cos = dir.dot(n.normalize()).abs();
            let t_true = (a - o).dot(n) / dir.dot(n);
            let p_true = o + dir * t_true;
            let (alpha, beta) = (
                (p_true - a).dot(e2.cross(n)) / n.length_squared(),
                (p_true - a).dot(n.cross(e1)) / n.length_squared(),
            );
            let bound = 16.0 * f32::EPSILON as f64 * (t_true + o.abs().max_element()) / cos;
            // how far inside the border the exact point is, in distance
            let inside =
                [alpha * e1.length(), (1.0 - alpha) * e1.length(), beta * e2.length(), (1.0 - beta) * e2.length()]
                    .into_iter()
                    .fold(f64::INFINITY, f64::min);
            match accel.closest_hit(&ray) {
                Some(hit) => {
                    hits += 1;
                    assert!(inside > -bound, "ray {i} hit outside the rectangle");
                    assert!((hit.t as f64 - t_true).abs() <= bound, "ray {i}: t {} vs {t_true}", hit.t);
                    let [p0, p1, p2] = mesh.corners(hit.index as usize).map(|p| p.as_dvec3());
                    let [b1, b2] = hit.bary.map(|w| w as f64);
                    let p = p0 * (1.0 - b1 - b2) + p1 * b1 + p2 * b2;
                    assert!((p - p_true).length() <= bound, "ray {i}: point off by {}", (p - p_true).length());
                }
                None => {
                    misses += 1;
                    assert!(inside < bound, "ray {i} missed a point {inside} inside");
                }
            }
        }
        assert!(hits > 10_000 && misses > 2_000, "hits {hits}, misses {misses}");
    }

    #[test]
    fn closest_hit_is_the_nearest_of_several_shapes() {
        let (mut shapes, meshes) = cube_scene(&Transform::IDENTITY);
        shapes.push(Shape {
            geometry: ShapeGeometry::Sphere { center: Vec3::new(0.0, 0.0, -5.0), radius: 1.0 },
            ..shapes[0].clone()
        });
        let accel = Accel::build(&shapes, &meshes);
        let hit = accel.closest_hit(&Ray::new(Vec3::new(0.0, 0.0, -10.0), Vec3::Z)).unwrap();
        assert_eq!(hit.shape, 1);
        assert!((hit.t - 4.0).abs() < 1e-5);
        let hit = accel.closest_hit(&Ray::new(Vec3::new(0.0, 0.0, 10.0), -Vec3::Z)).unwrap();
        assert_eq!(hit.shape, 0);
        assert!((hit.t - 9.0).abs() < 1e-5);
        assert!(accel.closest_hit(&Ray::new(Vec3::new(0.0, 5.0, 10.0), -Vec3::Z)).is_none());
        assert!(!accel.occluded(&Ray { o: Vec3::new(0.0, 0.0, 10.0), d: -Vec3::Z, tmax: 8.9 }));
        assert!(accel.occluded(&Ray { o: Vec3::new(0.0, 0.0, 10.0), d: -Vec3::Z, tmax: 9.1 }));
        // an empty scene hits nothing
        let empty = Accel::build(&[], &[]);
        assert!(empty.closest_hit(&Ray::new(Vec3::ZERO, Vec3::Z)).is_none());
    }
}
