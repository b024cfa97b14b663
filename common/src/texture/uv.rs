//! `to_uv`: the affine map Mitsuba's `bitmap` and `checkerboard` apply to a surface's uv before
//! the lookup. Mitsuba keeps it as a 3×3 affine transform; a `<transform>` element in a scene
//! is 4×4 and is reduced to 3×3 the way Mitsuba's `Transform::extract` does.

use glam::{Mat3, Mat4, Vec2};

/// uv' = A·uv + t, with A the upper-left 2×2 of Mitsuba's 3×3 `to_uv` matrix and t its last
/// column. The bottom row of an affine 3×3 is (0, 0, 1) and Mitsuba never reads it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvTransform {
    /// Rows of the 2×3 matrix: u' = row0 · (u, v, 1), v' = row1 · (u, v, 1).
    rows: [[f32; 3]; 2],
}

impl Default for UvTransform {
    fn default() -> Self {
        UvTransform::IDENTITY
    }
}

impl UvTransform {
    /// uv' = uv.
    pub const IDENTITY: UvTransform = UvTransform { rows: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] };

    /// From the two top rows of a 3×3 affine matrix written row by row, as in Mitsuba's
    /// `ScalarTransform3f`: `[[a, b, tu], [c, d, tv]]`.
    pub fn from_rows(rows: [[f32; 3]; 2]) -> Self {
        UvTransform { rows }
    }

    /// From a 3×3 matrix acting on (u, v, 1) as a column vector (glam is column-major: the
    /// translation is `m.z_axis`). The bottom row is ignored, as in Mitsuba's affine transforms.
    pub fn from_mat3(m: Mat3) -> Self {
        let (r0, r1) = (m.row(0), m.row(1));
        UvTransform { rows: [[r0.x, r0.y, r0.z], [r1.x, r1.y, r1.z]] }
    }

    /// From the 4×4 a scene's `<transform name="to_uv">` produces: Mitsuba keeps rows 0–1 of
    /// columns 0, 1 and 3 (the x/y block and the x/y translation) and drops everything that
    /// involves z.
    pub fn from_mat4(m: Mat4) -> Self {
        let (r0, r1) = (m.row(0), m.row(1));
        UvTransform { rows: [[r0.x, r0.y, r0.w], [r1.x, r1.y, r1.w]] }
    }

    /// Mitsuba's upgrade of pre-2.0 scenes: `uoffset`, `voffset`, `uscale`, `vscale` become
    /// `to_uv = scale(us, vs) · translate(uo, vo)`, i.e. uv' = (us·(u + uo), vs·(v + vo)).
    pub fn from_offset_scale(offset: Vec2, scale: Vec2) -> Self {
        UvTransform { rows: [[scale.x, 0.0, scale.x * offset.x], [0.0, scale.y, scale.y * offset.y]] }
    }

    /// The two rows of the 2×3 matrix.
    pub fn rows(&self) -> [[f32; 3]; 2] {
        self.rows
    }

    /// True for the identity, so lookups can skip the multiply.
    pub fn is_identity(&self) -> bool {
        *self == UvTransform::IDENTITY
    }

    /// Applies the transform to a point.
    #[inline]
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        let [a, b] = self.rows;
        Vec2::new(a[0] * uv.x + a[1] * uv.y + a[2], b[0] * uv.x + b[1] * uv.y + b[2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn uv_transform_mat4_keeps_xy_block_and_translation() {
        // scale (2, 3, 5), then translate (0.25, -0.5, 7): z must not leak into uv
        let m = Mat4::from_translation(Vec3::new(0.25, -0.5, 7.0)) * Mat4::from_scale(Vec3::new(2.0, 3.0, 5.0));
        let t = UvTransform::from_mat4(m);
        assert_eq!(t.apply(Vec2::new(1.0, 1.0)), Vec2::new(2.25, 2.5));
    }

    #[test]
    fn uv_transform_mat3_matches_rows() {
        let m = Mat3::from_cols(Vec3::new(1.0, 2.0, 0.0), Vec3::new(3.0, 4.0, 0.0), Vec3::new(5.0, 6.0, 1.0));
        assert_eq!(UvTransform::from_mat3(m), UvTransform::from_rows([[1.0, 3.0, 5.0], [2.0, 4.0, 6.0]]));
    }

    #[test]
    fn uv_transform_offset_scale_translates_first() {
        let t = UvTransform::from_offset_scale(Vec2::new(0.5, 1.0), Vec2::new(2.0, 4.0));
        assert_eq!(t.apply(Vec2::new(0.25, 0.0)), Vec2::new(1.5, 4.0));
    }
}
