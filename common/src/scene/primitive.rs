//! Ray tests of single primitives, shared by every query of [`super::accel`]: the watertight
//! triangle test of Woop, Benthin and Wald (JCGT 2013), so rays through shared edges and
//! vertices of a closed mesh always hit one of the triangles (no light leaks); parallelograms
//! (Mitsuba's `rectangle`) as one plane test; spheres and disks.

use super::sah::Bounds;
use super::shape::Mesh;
use glam::{Mat3A, Vec3, Vec3A};

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
pub(super) struct Quad {
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
    pub(super) fn from_mesh(mesh: &Mesh) -> Option<Quad> {
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

    pub(super) fn bounds(&self, mesh: &Mesh) -> Bounds {
        let (lo, hi) = mesh
            .positions
            .iter()
            .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        Bounds { lo, hi }
    }

    /// Returns (t, triangle, b1, b2) for a hit in (0, tmax).
    #[inline(always)]
    pub(super) fn intersect(&self, o: Vec3A, d: Vec3A, tmax: f32) -> Option<(f32, u32, f32, f32)> {
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
pub(super) struct WatertightRay {
    pub(super) shear: Mat3A,
}

impl WatertightRay {
    pub(super) fn new(d: Vec3) -> Self {
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
    pub(super) fn intersect(&self, o: Vec3A, tmax: f32, tri: &[Vec3; 3]) -> Option<(f32, f32, f32)> {
        let a = self.shear * (Vec3A::from(tri[0]) - o);
        let b = self.shear * (Vec3A::from(tri[1]) - o);
        let c = self.shear * (Vec3A::from(tri[2]) - o);
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

pub(super) fn intersect_sphere(o: Vec3, d: Vec3, tmax: f32, center: Vec3, radius: f32) -> Option<f32> {
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

pub(super) fn intersect_disk(o: Vec3, d: Vec3, tmax: f32, to_local: &glam::Mat4) -> Option<f32> {
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
