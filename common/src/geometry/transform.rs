//! Affine transforms with their inverse, composed the way Mitsuba's XML parser does: each
//! child of `<transform>` is left-multiplied onto what came before it. Like Mitsuba, the
//! matrices are kept in double precision (so that e.g. a 90° rotation is exact to 1e-16 and a
//! rotated floor stays flat), and results are rounded to f32 once.

use glam::{DMat3, DMat4, DVec3, DVec4, Mat4, Vec3};

type Mat3 = DMat3;

/// An invertible affine transform and its inverse.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    /// Forward matrix.
    pub m: DMat4,
    /// Inverse matrix.
    pub inv: DMat4,
}

impl Default for Transform {
    fn default() -> Self {
        Transform::IDENTITY
    }
}

impl Transform {
    /// The identity.
    pub const IDENTITY: Transform = Transform { m: DMat4::IDENTITY, inv: DMat4::IDENTITY };

    /// From a matrix; `None` when it is singular or not finite.
    pub fn from_matrix(m: DMat4) -> Option<Self> {
        let det = m.determinant();
        if !det.is_finite() || det.abs() < 1e-30 || !m.is_finite() {
            return None;
        }
        Some(Transform { m, inv: m.inverse() })
    }

    /// Translation by `t`.
    pub fn translate(t: DVec3) -> Self {
        Transform { m: DMat4::from_translation(t), inv: DMat4::from_translation(-t) }
    }

    /// Scale by `s` (`None` if a component is zero).
    pub fn scale(s: DVec3) -> Option<Self> {
        Self::from_matrix(DMat4::from_scale(s))
    }

    /// Right-handed rotation by `angle_deg` degrees about `axis`. The axis is used as given, as
    /// Mitsuba does (its `rotate` does not normalise).
    pub fn rotate(axis: DVec3, angle_deg: f64) -> Option<Self> {
        let (s, c) = angle_deg.to_radians().sin_cos();
        let a = axis;
        // Rodrigues' formula written out with the axis as given
        let m3 = Mat3::from_cols(
            DVec3::new(a.x * a.x * (1.0 - c) + c, a.x * a.y * (1.0 - c) + a.z * s, a.x * a.z * (1.0 - c) - a.y * s),
            DVec3::new(a.x * a.y * (1.0 - c) - a.z * s, a.y * a.y * (1.0 - c) + c, a.y * a.z * (1.0 - c) + a.x * s),
            DVec3::new(a.x * a.z * (1.0 - c) + a.y * s, a.y * a.z * (1.0 - c) - a.x * s, a.z * a.z * (1.0 - c) + c),
        );
        Self::from_matrix(DMat4::from_mat3(m3))
    }

    /// Mitsuba's `lookat`: camera space looks down +z with +x = `normalize(up × dir)`.
    /// `None` when `origin == target` or `up` is parallel to the view direction.
    pub fn look_at(origin: DVec3, target: DVec3, up: DVec3) -> Option<Self> {
        let dir = (target - origin).try_normalize()?;
        let left = up.cross(dir).try_normalize()?;
        let new_up = dir.cross(left);
        let m = DMat4::from_cols(left.extend(0.0), new_up.extend(0.0), dir.extend(0.0), origin.extend(1.0));
        Self::from_matrix(m)
    }

    /// `self` applied after `first`: the product `self · first`.
    pub fn after(&self, first: &Transform) -> Transform {
        Transform { m: self.m * first.m, inv: first.inv * self.inv }
    }

    /// Transforms a point.
    #[inline]
    pub fn point(&self, p: Vec3) -> Vec3 {
        self.m.transform_point3(p.as_dvec3()).as_vec3()
    }

    /// Transforms a point by the inverse.
    #[inline]
    pub fn inv_point(&self, p: Vec3) -> Vec3 {
        self.inv.transform_point3(p.as_dvec3()).as_vec3()
    }

    /// Transforms a direction by the inverse.
    #[inline]
    pub fn inv_vector(&self, v: Vec3) -> Vec3 {
        self.inv.transform_vector3(v.as_dvec3()).as_vec3()
    }

    /// The inverse as an f32 matrix, for hot loops.
    pub fn inv_f32(&self) -> Mat4 {
        self.inv.as_mat4()
    }

    /// Transforms a direction (no translation, not normalised).
    #[inline]
    pub fn vector(&self, v: Vec3) -> Vec3 {
        self.m.transform_vector3(v.as_dvec3()).as_vec3()
    }

    /// Transforms a normal with the inverse transpose (not normalised).
    #[inline]
    pub fn normal(&self, n: Vec3) -> Vec3 {
        let it = self.inv.transpose();
        (it * DVec4::new(n.x as f64, n.y as f64, n.z as f64, 0.0)).truncate().as_vec3()
    }

    /// Determinant of the linear part: negative when the transform mirrors.
    pub fn determinant3(&self) -> f64 {
        Mat3::from_mat4(self.m).determinant()
    }

    /// Whether the linear part is a rotation times a uniform scale (within `tol`), returning that
    /// scale.
    pub fn uniform_scale(&self, tol: f64) -> Option<f32> {
        let l = Mat3::from_mat4(self.m);
        let (sx, sy, sz) = (l.x_axis.length(), l.y_axis.length(), l.z_axis.length());
        let ortho = l.x_axis.dot(l.y_axis).abs() + l.y_axis.dot(l.z_axis).abs() + l.x_axis.dot(l.z_axis).abs();
        let ok = (sx - sy).abs() <= tol * sx && (sx - sz).abs() <= tol * sx && ortho <= tol * sx * sx;
        ok.then_some(sx as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn document_order_composition_matches_mitsuba() {
        // <scale x="2"/><rotate z="1" angle="90"/><translate x="10"/> on [-1,1]^3
        // gives x in [9,11], y in [-2,2] in Mitsuba 3.9.1, whose parser left-multiplies each
        // element (`src/core/parser.cpp`)
        let s = Transform::scale(DVec3::new(2.0, 1.0, 1.0)).unwrap();
        let r = Transform::rotate(DVec3::Z, 90.0).unwrap();
        let t = Transform::translate(DVec3::new(10.0, 0.0, 0.0));
        let m = t.after(&r.after(&s));
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for i in 0..8 {
            let c = Vec3::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            );
            let p = m.point(c);
            lo = lo.min(p);
            hi = hi.max(p);
        }
        assert!((lo - Vec3::new(9.0, -2.0, -1.0)).length() < 1e-4, "{lo}");
        assert!((hi - Vec3::new(11.0, 2.0, 1.0)).length() < 1e-4, "{hi}");
    }

    #[test]
    fn rotation_is_counter_clockwise_about_the_axis() {
        let r = Transform::rotate(DVec3::Z, 90.0).unwrap();
        assert!((r.vector(Vec3::X) - Vec3::Y).length() < 1e-6);
        let rx = Transform::rotate(DVec3::X, -90.0).unwrap();
        // in double precision a rotated rectangle stays exactly flat at f32 resolution
        let corner = rx.after(&Transform::scale(DVec3::new(4.0, 4.0, 1.0)).unwrap()).point(Vec3::new(1.0, 1.0, 0.0));
        assert!(corner.y.abs() < 1e-12, "{corner}");
        // a rectangle (normal +z) rotated by -90° about x faces +y: the floors of our scenes
        assert!((rx.normal(Vec3::Z).normalize() - Vec3::Y).length() < 1e-6);
    }

    #[test]
    fn look_at_puts_left_on_camera_x() {
        let t = Transform::look_at(DVec3::ZERO, DVec3::Z, DVec3::Y).unwrap();
        assert!((t.vector(Vec3::Z) - Vec3::Z).length() < 1e-6);
        assert!((t.vector(Vec3::X) - Vec3::X).length() < 1e-6, "left = up x dir = +x");
        assert!(Transform::look_at(DVec3::ZERO, DVec3::Y, DVec3::Y).is_none());
    }

    #[test]
    fn normals_use_the_inverse_transpose() {
        let s = Transform::scale(DVec3::new(4.0, 1.0, 1.0)).unwrap();
        let n = s.normal(Vec3::new(1.0, 1.0, 0.0).normalize()).normalize();
        let tangent = s.vector(Vec3::new(1.0, -1.0, 0.0));
        assert!(n.dot(tangent).abs() < 1e-5);
    }
}
