//! Ray queries against all shapes: one obvhs compressed wide BVH (CWBVH) over triangles,
//! spheres and disks, collapsed from the binary tree of [`super::sah`]. This is the only
//! module that imports obvhs; everything else sees [`Accel::closest_hit`] and
//! [`Accel::occluded`].
//! The primitive tests themselves are in [`super::primitive`].

use super::primitive::{Quad, WatertightRay, intersect_disk, intersect_sphere};
use super::sah::{self, Bounds};
use super::shape::{Mesh, Shape, ShapeGeometry};
use crate::geometry::Ray;
use glam::UVec2;
use glam::{Mat3A, Vec3, Vec3A, Vec4};
use obvhs::{
    aabb::Aabb,
    bvh2::{Bvh2, node::Bvh2Node},
    cwbvh::{CwBvh, Traversal, bvh2_to_cwbvh::bvh2_to_cwbvh},
};

/// Scenes with at most this many primitives skip the BVH and test every primitive: decoding a
/// compressed wide node costs more than that for a handful of primitives
/// (docs/decisions/0011-small-scene-scans.md).
const FLAT_LIMIT: usize = 8;

/// Up to this many primitives, the boxes are tested four at a time first, then the primitives
/// whose boxes the ray meets (docs/decisions/0011-small-scene-scans.md).
const BOXED_FLAT_LIMIT: usize = 16;

/// How a scene too small for the BVH is scanned.
#[derive(Debug)]
enum FlatScan {
    /// Every primitive.
    All,
    /// The primitives whose boxes the ray meets (groups in `prims` order).
    Boxed(Vec<BoxGroup>),
}

/// The boxes of up to four primitives, structure of arrays, for the flat scan.
#[derive(Clone, Copy, Debug)]
struct BoxGroup {
    lo: [Vec4; 3],
    hi: [Vec4; 3],
    /// One bit per lane that holds a primitive.
    valid: u32,
}

impl BoxGroup {
    /// Groups `bounds` by four, each box padded so that rounding in the slab test never
    /// rejects a primitive the exact test would hit (flat rectangles have zero thickness).
    fn group(bounds: &[Bounds]) -> Vec<BoxGroup> {
        bounds
            .chunks(4)
            .map(|chunk| {
                let mut g = BoxGroup { lo: [Vec4::ZERO; 3], hi: [Vec4::ZERO; 3], valid: (1 << chunk.len()) - 1 };
                for (lane, b) in chunk.iter().enumerate() {
                    let pad = (b.hi - b.lo).max_element() * 1e-5 + (b.lo.abs().max(b.hi.abs())).max_element() * 1e-6;
                    for axis in 0..3 {
                        g.lo[axis][lane] = b.lo[axis] - pad;
                        g.hi[axis][lane] = b.hi[axis] + pad;
                    }
                }
                g
            })
            .collect()
    }

    /// Bit mask of the lanes whose box the ray meets within `(0, tmax)`.
    #[inline(always)]
    fn hits(&self, o: [Vec4; 3], inv_d: [Vec4; 3], tmax: f32) -> u32 {
        let t0: [Vec4; 3] = std::array::from_fn(|a| (self.lo[a] - o[a]) * inv_d[a]);
        let t1: [Vec4; 3] = std::array::from_fn(|a| (self.hi[a] - o[a]) * inv_d[a]);
        let near = t0[0].min(t1[0]).max(t0[1].min(t1[1])).max(t0[2].min(t1[2]).max(Vec4::ZERO));
        let far = t0[0].max(t1[0]).min(t0[1].max(t1[1])).min(t0[2].max(t1[2]).min(Vec4::splat(tmax)));
        near.cmple(far).bitmask() & self.valid
    }
}

/// What the BVH stores per primitive, in BVH order.
#[derive(Clone, Copy, Debug)]
enum Geom {
    Triangle([Vec3; 3]),
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
            Geom::Triangle([a, b, c]) => Bounds { lo: a.min(b).min(c), hi: a.max(b).max(c) },
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
    /// Set when there are few enough primitives that a flat scan beats decoding a wide node.
    flat: Option<FlatScan>,
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
                        let p = Prim { geom: Geom::Triangle(mesh.corners(ti)), shape: si as u32, index: ti as u32 };
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
        let flat = match prims.len() {
            n if n <= FLAT_LIMIT => Some(FlatScan::All),
            n if n <= BOXED_FLAT_LIMIT => {
                let ordered: Vec<Bounds> = bvh.primitive_indices.iter().map(|&i| bounds[i as usize]).collect();
                Some(FlatScan::Boxed(BoxGroup::group(&ordered)))
            }
            _ => None,
        };
        Accel { bvh, prims, disks, quads, has_triangles, flat }
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
        let inv_direction = Vec3A::select(tiny, direction.signum() / f32::EPSILON, Vec3A::ONE / direction);
        obvhs::ray::Ray { origin: Vec3A::from(ray.o), direction, inv_direction, tmin: 0.0, tmax: ray.tmax }
    }

    /// The ray's origin and inverse direction, each axis broadcast to four lanes.
    #[inline(always)]
    fn splat_ray(ray: &obvhs::ray::Ray) -> ([Vec4; 3], [Vec4; 3]) {
        (
            std::array::from_fn(|a| Vec4::splat(ray.origin[a])),
            std::array::from_fn(|a| Vec4::splat(ray.inv_direction[a])),
        )
    }

    /// The closest intersection in `(0, ray.tmax)`.
    pub fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        if self.prims.is_empty() {
            return None;
        }
        let wt = self.watertight_ray(ray.d);
        let mut traverse_ray = Self::obvhs_ray(ray);
        if let Some(FlatScan::All) = &self.flat {
            let mut best: Option<Hit> = None;
            let mut tmax = ray.tmax;
            for prim in &self.prims {
                if let Some((t, offset, b1, b2)) = self.intersect_prim(prim, &wt, ray.o, ray.d, tmax) {
                    best = Some(Hit { t, shape: prim.shape, index: prim.index + offset, bary: [b1, b2] });
                    tmax = t;
                }
            }
            return best;
        }
        if let Some(FlatScan::Boxed(groups)) = &self.flat {
            let mut best: Option<Hit> = None;
            let mut tmax = ray.tmax;
            let (o, inv_d) = Self::splat_ray(&traverse_ray);
            for (g, group) in groups.iter().enumerate() {
                let mut lanes = group.hits(o, inv_d, tmax);
                while lanes != 0 {
                    let prim = &self.prims[4 * g + lanes.trailing_zeros() as usize];
                    lanes &= lanes - 1;
                    if let Some((t, offset, b1, b2)) = self.intersect_prim(prim, &wt, ray.o, ray.d, tmax) {
                        best = Some(Hit { t, shape: prim.shape, index: prim.index + offset, bary: [b1, b2] });
                        tmax = t;
                    }
                }
            }
            return best;
        }
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
        if let Some(FlatScan::All) = &self.flat {
            return self.prims.iter().any(|prim| self.intersect_prim(prim, &wt, ray.o, ray.d, ray.tmax).is_some());
        }
        if let Some(FlatScan::Boxed(groups)) = &self.flat {
            let (o, inv_d) = Self::splat_ray(&traverse_ray);
            return groups.iter().enumerate().any(|(g, group)| {
                let mut lanes = group.hits(o, inv_d, ray.tmax);
                while lanes != 0 {
                    let prim = &self.prims[4 * g + lanes.trailing_zeros() as usize];
                    lanes &= lanes - 1;
                    if self.intersect_prim(prim, &wt, ray.o, ray.d, ray.tmax).is_some() {
                        return true;
                    }
                }
                false
            });
        }
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
            object_rotation: glam::Mat3::IDENTITY,
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

    /// A scene small enough to be scanned flat gives the same hits as the same scene padded
    /// with far-away spheres, scanned by boxes, and padded further, through the BVH.
    #[test]
    fn flat_and_bvh_queries_agree() {
        let (cube, _) = cube_scene(&Transform::IDENTITY);
        let sphere = |x: f32, y: f32, r: f32| Shape {
            geometry: ShapeGeometry::Sphere { center: Vec3::new(x, y, 0.5), radius: r },
            ..cube[0].clone()
        };
        let mut shapes = vec![Shape { geometry: ShapeGeometry::Mesh(0), ..cube[0].clone() }];
        shapes.extend((0..4).map(|i| sphere(i as f32 - 1.5, 0.3 * i as f32, 0.4)));
        let meshes = vec![Mesh::rectangle()];
        let flat = Accel::build(&shapes, &meshes);
        shapes.extend((0..6).map(|i| sphere(100.0 + i as f32 * 3.0, 0.0, 1.0)));
        let boxed = Accel::build(&shapes, &meshes);
        shapes.extend((0..10).map(|i| sphere(200.0 + i as f32 * 3.0, 0.0, 1.0)));
        let tree = Accel::build(&shapes, &meshes);
        assert!(matches!(flat.flat, Some(FlatScan::All)));
        assert!(matches!(boxed.flat, Some(FlatScan::Boxed(_))));
        assert!(tree.flat.is_none());
        let mut hits = 0;
        for i in 0..5_000u32 {
            let mut s = Sampler::for_pixel(5, i, 0);
            let o = Vec3::new(0.0, 0.0, 3.0) + (s.next_2d().extend(s.next_1d()) - 0.5) * 4.0;
            let target = Vec3::new(0.0, 0.4, 0.3) + (s.next_2d().extend(s.next_1d()) - 0.5) * Vec3::new(4.0, 2.0, 1.0);
            let ray = Ray { o, d: (target - o).normalize(), tmax: 50.0 };
            let key = |h: Option<Hit>| h.map(|h| (h.t, h.shape, h.index));
            let (a, b, c) = (flat.closest_hit(&ray), boxed.closest_hit(&ray), tree.closest_hit(&ray));
            assert_eq!(key(a), key(c), "ray {i}");
            assert_eq!(key(b), key(c), "ray {i}");
            assert_eq!(flat.occluded(&ray), tree.occluded(&ray), "ray {i}");
            assert_eq!(boxed.occluded(&ray), tree.occluded(&ray), "ray {i}");
            hits += a.is_some() as u32;
        }
        assert!(hits > 500, "{hits} hits");
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
