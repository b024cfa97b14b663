//! Ray queries against all shapes: one obvhs compressed wide BVH (CWBVH) over triangles,
//! spheres and disks. This is the only module that imports obvhs; everything else sees
//! [`Accel::closest_hit`] and [`Accel::occluded`].
//!
//! Triangles use the watertight test of Woop, Benthin and Wald (JCGT 2013), so rays through
//! shared edges and vertices of a closed mesh always hit one of the triangles: no light leaks.

use super::shape::{Mesh, Shape, ShapeGeometry};
use crate::geometry::Ray;
use glam::UVec2;
use glam::{Vec3, Vec3A};
use obvhs::{
    Boundable, BvhBuildParams,
    aabb::Aabb,
    cwbvh::{CwBvh, Traversal},
};

/// What the BVH stores per primitive, in BVH order.
#[derive(Clone, Copy, Debug)]
enum Geom {
    Triangle([Vec3; 3]),
    Sphere { center: Vec3, radius: f32 },
    Disk { index: u32 },
}

#[derive(Clone, Copy, Debug)]
struct Prim {
    geom: Geom,
    shape: u32,
    index: u32,
}

impl Boundable for Prim {
    fn aabb(&self) -> Aabb {
        match self.geom {
            Geom::Triangle([a, b, c]) => Aabb::new(Vec3A::from(a.min(b).min(c)), Vec3A::from(a.max(b).max(c))),
            Geom::Sphere { center, radius } => Aabb::new(Vec3A::from(center - radius), Vec3A::from(center + radius)),
            Geom::Disk { .. } => unreachable!("invariant: disk bounds are computed before the build"),
        }
    }
}

struct Bounded(Aabb);

impl Boundable for Bounded {
    fn aabb(&self) -> Aabb {
        self.0
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
}

/// Per-ray constants of the watertight triangle test.
struct WatertightRay {
    k: [usize; 3],
    shear: Vec3,
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
        WatertightRay { k: [kx, ky, kz], shear: Vec3::new(d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]) }
    }

    /// Returns (t, b1, b2) for a hit in (0, tmax).
    #[inline(always)]
    fn intersect(&self, o: Vec3, tmax: f32, tri: &[Vec3; 3]) -> Option<(f32, f32, f32)> {
        let [kx, ky, kz] = self.k;
        // plain arrays: indexing a glam vector with a run-time axis compiles to branches
        let (a, b, c) = ((tri[0] - o).to_array(), (tri[1] - o).to_array(), (tri[2] - o).to_array());
        let s = self.shear;
        let (ax, ay) = (a[kx] - s.x * a[kz], a[ky] - s.y * a[kz]);
        let (bx, by) = (b[kx] - s.x * b[kz], b[ky] - s.y * b[kz]);
        let (cx, cy) = (c[kx] - s.x * c[kz], c[ky] - s.y * c[kz]);
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            // fall back to double precision on edges so that the sign test is exact
            u = (cx as f64 * by as f64 - cy as f64 * bx as f64) as f32;
            v = (ax as f64 * cy as f64 - ay as f64 * cx as f64) as f32;
            w = (bx as f64 * ay as f64 - by as f64 * ax as f64) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let t_scaled = u * (s.z * a[kz]) + v * (s.z * b[kz]) + w * (s.z * c[kz]);
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

impl Accel {
    /// Builds the BVH over every shape.
    pub fn build(shapes: &[Shape], meshes: &[Mesh]) -> Accel {
        let mut prims = Vec::new();
        let mut disks = Vec::new();
        let mut bounds = Vec::new();
        for (si, shape) in shapes.iter().enumerate() {
            match &shape.geometry {
                ShapeGeometry::Mesh(m) => {
                    let mesh = &meshes[*m as usize];
                    for ti in 0..mesh.triangles.len() {
                        let p = Prim { geom: Geom::Triangle(mesh.corners(ti)), shape: si as u32, index: ti as u32 };
                        bounds.push(p.aabb());
                        prims.push(p);
                    }
                }
                ShapeGeometry::Sphere { center, radius } => {
                    let p =
                        Prim { geom: Geom::Sphere { center: *center, radius: *radius }, shape: si as u32, index: 0 };
                    bounds.push(p.aabb());
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
                    bounds.push(Aabb::new(Vec3A::from(lo - pad), Vec3A::from(hi + pad)));
                    prims.push(Prim { geom: Geom::Disk { index: disks.len() as u32 }, shape: si as u32, index: 0 });
                    disks.push(to_world.inv_f32());
                }
            }
        }
        let bounded: Vec<Bounded> = bounds.into_iter().map(Bounded).collect();
        let mut build_time = std::time::Duration::ZERO;
        let bvh = if bounded.is_empty() {
            CwBvh::default()
        } else {
            obvhs::cwbvh::builder::build_cwbvh(&bounded, BvhBuildParams::fast_build(), &mut build_time)
        };
        // store primitives in BVH leaf order so the traversal callback indexes them directly
        let prims = bvh.primitive_indices.iter().map(|&i| prims[i as usize]).collect();
        Accel { bvh, prims, disks }
    }

    /// Number of primitives.
    pub fn primitive_count(&self) -> usize {
        self.prims.len()
    }

    #[inline(always)]
    fn intersect_prim(&self, prim: &Prim, wt: &WatertightRay, o: Vec3, d: Vec3, tmax: f32) -> Option<(f32, f32, f32)> {
        match &prim.geom {
            Geom::Triangle(tri) => wt.intersect(o, tmax, tri),
            Geom::Sphere { center, radius } => intersect_sphere(o, d, tmax, *center, *radius).map(|t| (t, 0.0, 0.0)),
            Geom::Disk { index } => intersect_disk(o, d, tmax, &self.disks[*index as usize]).map(|t| (t, 0.0, 0.0)),
        }
    }

    fn obvhs_ray(ray: &Ray) -> obvhs::ray::Ray {
        // obvhs takes the sign of 1/d from `signum`, which is -1 for -0.0, but classifies the
        // direction with `d < 0`, which is false for -0.0: the slab test then inverts and the
        // BVH is missed. Adding +0.0 turns -0.0 into +0.0.
        obvhs::ray::Ray::new(Vec3A::from(ray.o), Vec3A::from(ray.d + Vec3::ZERO), 0.0, ray.tmax)
    }

    /// The closest intersection in `(0, ray.tmax)`.
    pub fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        if self.prims.is_empty() {
            return None;
        }
        let wt = WatertightRay::new(ray.d);
        let mut traverse_ray = Self::obvhs_ray(ray);
        let mut best: Option<Hit> = None;
        TRAVERSAL.with_borrow_mut(|state| {
            state.reinit(traverse_ray.direction);
            let mut node;
            obvhs::traverse!(self.bvh, node, state, node.intersect_ray(&traverse_ray, state.oct_inv4), {
                let prim = &self.prims[state.primitive_id as usize];
                if let Some((t, b1, b2)) = self.intersect_prim(prim, &wt, ray.o, ray.d, traverse_ray.tmax) {
                    best = Some(Hit { t, shape: prim.shape, index: prim.index, bary: [b1, b2] });
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
        let wt = WatertightRay::new(ray.d);
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
            area_cdf: vec![],
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
