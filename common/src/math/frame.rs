//! Orthonormal frames: the local shading frame in which BSDFs are written (z = normal).

use glam::Vec3;

/// An orthonormal basis `(s, t, n)`. Local coordinates have the normal along +z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// First tangent.
    pub s: Vec3,
    /// Second tangent.
    pub t: Vec3,
    /// Normal.
    pub n: Vec3,
}

impl Frame {
    /// Builds a frame around a unit normal (Duff et al. 2017, "Building an orthonormal basis,
    /// revisited"): continuous everywhere except at a single point, no normalisation needed.
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { s, t, n }
    }

    /// The frame Mitsuba builds from a normal and the surface's ∂p/∂u (`initialize_sh_frame`):
    /// `s` is ∂p/∂u made orthogonal to `n`, `t = n × s`; [`Frame::from_normal`] when ∂p/∂u
    /// has no component off the normal. Anisotropic BSDFs depend on `s`.
    pub fn from_normal_tangent(n: Vec3, dp_du: Vec3) -> Self {
        match (dp_du - n * n.dot(dp_du)).try_normalize() {
            Some(s) => Frame { s, t: n.cross(s), n },
            None => Frame::from_normal(n),
        }
    }

    /// World direction → local coordinates.
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    /// Local coordinates → world direction.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_orthonormal_and_round_trips() {
        for n in
            [Vec3::Z, -Vec3::Z, Vec3::X, Vec3::new(0.3, -0.5, 0.8).normalize(), Vec3::new(1e-7, 0.0, -1.0).normalize()]
        {
            let f = Frame::from_normal(n);
            assert!((f.s.length() - 1.0).abs() < 1e-5 && (f.t.length() - 1.0).abs() < 1e-5);
            assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(n).abs() < 1e-5 && f.t.dot(n).abs() < 1e-5);
            assert!(f.s.cross(f.t).dot(n) > 0.999, "right-handed");
            let v = Vec3::new(0.2, 0.7, -0.4);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }
}
