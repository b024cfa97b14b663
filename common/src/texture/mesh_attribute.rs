//! Per-vertex and per-face mesh data ([`MeshAttribute`], e.g. PLY colours as `vertex_color`)
//! and Mitsuba's `mesh_attribute` texture that reads it (`src/textures/mesh_attribute.cpp`,
//! `Mesh::interpolate_attribute`): b0·a0 + b1·a1 + b2·a2 over the hit triangle's vertices for
//! `vertex_*`, the triangle's own value for `face_*`, times `scale`. Colours take 1 (grey) or 3
//! components, scalar uses exactly 1; [`MeshAttributeTexture::check`] enforces that when the
//! scene is built, where Mitsuba would throw at the first lookup.

use super::{TextureError, TexturePoint};
use crate::math::Rgb;

/// Whether an attribute has one value per vertex or per triangle, from its name's prefix.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AttributePer {
    /// `vertex_*`: interpolated with the hit's barycentric coordinates.
    Vertex,
    /// `face_*`: constant over each triangle.
    Face,
}

impl AttributePer {
    /// From the name's prefix, as Mitsuba's `Mesh::add_attribute`.
    pub fn from_name(name: &str) -> Option<AttributePer> {
        if name.starts_with("vertex_") {
            Some(AttributePer::Vertex)
        } else if name.starts_with("face_") {
            Some(AttributePer::Face)
        } else {
            None
        }
    }
}

/// One named attribute of a mesh: `components` floats per vertex or face, interleaved.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshAttribute {
    name: String,
    per: AttributePer,
    components: usize,
    data: Vec<f32>,
}

impl MeshAttribute {
    /// An attribute named `vertex_*` or `face_*` with `components` (1 to 4; PLY colours with
    /// alpha have 4, which Mitsuba stores but cannot evaluate) values per element.
    pub fn new(name: impl Into<String>, components: usize, data: Vec<f32>) -> Result<MeshAttribute, TextureError> {
        let name = name.into();
        let Some(per) = AttributePer::from_name(&name) else { return Err(TextureError::AttributeName { name }) };
        if !(1..=4).contains(&components) || !data.len().is_multiple_of(components) {
            let message = format!("{} values cannot be split into elements of {components} components", data.len());
            return Err(TextureError::AttributeData { name, message });
        }
        Ok(MeshAttribute { name, per, components, data })
    }

    /// The name, with its `vertex_`/`face_` prefix.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Per vertex or per face.
    pub fn per(&self) -> AttributePer {
        self.per
    }

    /// Values per element.
    pub fn components(&self) -> usize {
        self.components
    }

    /// The values, element after element.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// Number of elements (vertices or faces) the data covers.
    pub fn element_count(&self) -> usize {
        self.data.len() / self.components
    }

    /// Component `c` of element `i`; 0 outside the data, so a lookup never panics.
    #[inline]
    fn value(&self, i: u32, c: usize) -> f32 {
        self.data.get(i as usize * self.components + c).copied().unwrap_or(0.0)
    }

    /// Component `c` at the hit: interpolated over the triangle or the face's value.
    #[inline]
    fn at(&self, hit: &MeshPoint, c: usize) -> f32 {
        match self.per {
            AttributePer::Vertex => {
                let [i0, i1, i2] = hit.vertices;
                let b = hit.barycentric;
                // Mitsuba's evaluation order: a0·b0 + (a1·b1 + a2·b2)
                self.value(i0, c) * b.x + (self.value(i1, c) * b.y + self.value(i2, c) * b.z)
            }
            AttributePer::Face => self.value(hit.face, c),
        }
    }
}

/// Where on a mesh a lookup happens, for `mesh_attribute` textures.
#[derive(Clone, Copy, Debug)]
pub struct MeshPoint<'a> {
    /// The mesh's attributes.
    pub attributes: &'a [MeshAttribute],
    /// The hit triangle's index.
    pub face: u32,
    /// The hit triangle's vertex indices.
    pub vertices: [u32; 3],
    /// Barycentric coordinates (b0, b1, b2) of the hit, weights of `vertices`.
    pub barycentric: glam::Vec3,
}

/// How a texture's value will be used, for [`MeshAttributeTexture::check`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Usage {
    /// Through `eval` (colours: reflectance, ...).
    Color,
    /// Through `eval_1` (scalars: `mask.opacity`, roughness, ...).
    Scalar,
}

/// Mitsuba's `mesh_attribute` texture.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshAttributeTexture {
    name: String,
    scale: f32,
}

impl MeshAttributeTexture {
    /// Reads attribute `name` (`vertex_*` or `face_*`) times `scale` (Mitsuba's default 1).
    pub fn new(name: impl Into<String>, scale: f32) -> Result<MeshAttributeTexture, TextureError> {
        let name = name.into();
        if AttributePer::from_name(&name).is_none() {
            return Err(TextureError::AttributeName { name });
        }
        Ok(MeshAttributeTexture { name, scale })
    }

    /// The attribute's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// `scale`.
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// Checks, at scene build time, that a shape with these attributes can serve this texture
    /// for `usage`: the attribute exists and has 1 or 3 components for colours, 1 for scalars.
    pub fn check(&self, attributes: &[MeshAttribute], usage: Usage) -> Result<(), TextureError> {
        let Some(attr) = attributes.iter().find(|a| a.name == self.name) else {
            let names: Vec<&str> = attributes.iter().map(|a| a.name.as_str()).collect();
            let available = if names.is_empty() { "none".to_string() } else { names.join(", ") };
            return Err(TextureError::MissingAttribute { name: self.name.clone(), available });
        };
        let (ok, usage, needed) = match usage {
            Usage::Color => (attr.components == 1 || attr.components == 3, "a colour", "1 or 3"),
            Usage::Scalar => (attr.components == 1, "a scalar", "1"),
        };
        if ok {
            Ok(())
        } else {
            Err(TextureError::AttributeComponents {
                name: self.name.clone(),
                components: attr.components,
                usage,
                needed,
            })
        }
    }

    /// The attribute at `p`; a lookup may scan the shape's few attributes by name since
    /// one texture can serve several meshes whose attribute lists differ.
    #[inline]
    fn find<'a>(&self, p: &TexturePoint<'a>) -> Option<(&'a MeshAttribute, MeshPoint<'a>)> {
        let hit = p.mesh?;
        hit.attributes.iter().find(|a| a.name == self.name).map(|a| (a, hit))
    }

    /// The colour at `p`: a 1-component attribute in all channels, a 3-component one as RGB.
    /// Zero where [`check`](Self::check) would have failed.
    #[inline]
    pub fn eval(&self, p: &TexturePoint) -> Rgb {
        match self.find(p) {
            Some((a, hit)) if a.components == 1 => Rgb::splat(a.at(&hit, 0) * self.scale),
            Some((a, hit)) if a.components == 3 => Rgb::new(a.at(&hit, 0), a.at(&hit, 1), a.at(&hit, 2)) * self.scale,
            _ => Rgb::ZERO,
        }
    }

    /// The scalar at `p` (1-component attributes only; zero otherwise).
    #[inline]
    pub fn eval_1(&self, p: &TexturePoint) -> f32 {
        match self.find(p) {
            Some((a, hit)) if a.components == 1 => a.at(&hit, 0) * self.scale,
            _ => 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Vec2, Vec3};

    fn attrs() -> Vec<MeshAttribute> {
        vec![
            // three vertices with colours red, green, blue, and one with white
            MeshAttribute::new("vertex_color", 3, vec![1., 0., 0., 0., 1., 0., 0., 0., 1., 1., 1., 1.]).unwrap(),
            MeshAttribute::new("vertex_weight", 1, vec![0.0, 1.0, 2.0, 3.0]).unwrap(),
            MeshAttribute::new("face_id", 1, vec![10.0, 20.0]).unwrap(),
            MeshAttribute::new("vertex_rgba", 4, vec![0.0; 16]).unwrap(),
        ]
    }

    fn point(attrs: &[MeshAttribute], face: u32, vertices: [u32; 3], b: Vec3) -> TexturePoint<'_> {
        TexturePoint::on_mesh(Vec2::ZERO, MeshPoint { attributes: attrs, face, vertices, barycentric: b })
    }

    #[test]
    fn mesh_attribute_vertex_interpolates_barycentrically() {
        let attrs = attrs();
        let p = point(&attrs, 1, [3, 1, 2], Vec3::new(0.5, 0.25, 0.25));
        let color = MeshAttributeTexture::new("vertex_color", 2.0).unwrap();
        assert_eq!(color.eval(&p), Rgb::new(1.0, 1.5, 1.5));
        let weight = MeshAttributeTexture::new("vertex_weight", 1.0).unwrap();
        assert_eq!(weight.eval_1(&p), 0.5 * 3.0 + 0.25 * 1.0 + 0.25 * 2.0);
        assert_eq!(weight.eval(&p), Rgb::splat(2.25));
    }

    #[test]
    fn mesh_attribute_face_is_constant_per_triangle() {
        let attrs = attrs();
        let id = MeshAttributeTexture::new("face_id", 0.5).unwrap();
        for b in [Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.2, 0.3, 0.5)] {
            assert_eq!(id.eval_1(&point(&attrs, 1, [0, 1, 2], b)), 10.0);
        }
        assert_eq!(id.eval(&point(&attrs, 0, [0, 1, 2], Vec3::X)), Rgb::splat(5.0));
    }

    #[test]
    fn mesh_attribute_check_reports_missing_and_wrong_components() {
        let attrs = attrs();
        let missing = MeshAttributeTexture::new("vertex_uv2", 1.0).unwrap().check(&attrs, Usage::Color);
        let msg = missing.unwrap_err().to_string();
        assert!(msg.contains("vertex_uv2") && msg.contains("vertex_color, vertex_weight"), "{msg}");
        let color = MeshAttributeTexture::new("vertex_color", 1.0).unwrap();
        assert!(color.check(&attrs, Usage::Color).is_ok());
        assert!(matches!(color.check(&attrs, Usage::Scalar), Err(TextureError::AttributeComponents { .. })));
        let rgba = MeshAttributeTexture::new("vertex_rgba", 1.0).unwrap();
        assert!(rgba.check(&attrs, Usage::Color).is_err());
        assert!(MeshAttributeTexture::new("vertex_weight", 1.0).unwrap().check(&[], Usage::Scalar).is_err());
    }

    #[test]
    fn mesh_attribute_rejects_bad_names_and_shapes() {
        assert!(matches!(MeshAttributeTexture::new("color", 1.0), Err(TextureError::AttributeName { .. })));
        assert!(MeshAttribute::new("vertex_color", 3, vec![0.0; 4]).is_err());
        assert!(MeshAttribute::new("vertex_color", 0, vec![]).is_err());
        assert!(MeshAttribute::new("uv", 1, vec![]).is_err());
    }

    #[test]
    fn mesh_attribute_out_of_range_or_absent_is_zero() {
        let attrs = attrs();
        let color = MeshAttributeTexture::new("vertex_color", 1.0).unwrap();
        assert_eq!(color.eval(&point(&attrs, 0, [99, 0, 0], Vec3::X)), Rgb::ZERO);
        assert_eq!(color.eval(&TexturePoint::uv(Vec2::ZERO)), Rgb::ZERO);
    }
}
