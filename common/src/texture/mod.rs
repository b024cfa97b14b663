//! Textures as Mitsuba 3.9.1 evaluates them: constants, `bitmap` (image files), `checkerboard`
//! and `mesh_attribute`, behind one closed enum, [`Texture`], so materials dispatch with a
//! `match` and a lookup never allocates.
//!
//! Every texture answers [`Texture::eval`] (a colour) and [`Texture::eval_1`] (a scalar, for
//! `mask.opacity`, roughness, ...) with Mitsuba's semantics, which differ by kind: an `<rgb>`
//! constant's scalar is the **mean** of its channels, a bitmap's the **luminance**
//! 0.212671 R + 0.715160 G + 0.072169 B, and a checkerboard's scalar uses the **inverted**
//! test (a Mitsuba bug that scenes show). [`Texture::is_constant`] lets untextured materials
//! keep a fast path; [`Texture::mean`] serves importance sampling and the optimiser.
//!
//! Building is fallible and happens at scene load: [`Bitmap::load`] reads a file within a
//! [`TextureLimits`] budget, and [`Texture::check_attributes`] verifies that a shape has the
//! attributes its `mesh_attribute` textures read. There is no XML here: the scene builder turns
//! parsed properties into these constructors.
//!
//! ```
//! use glam::Vec2;
//! use tessera_common::math::Rgb;
//! use tessera_common::texture::{Checkerboard, Texture, TexturePoint, UvTransform};
//! let board = Texture::from(Checkerboard::new(Texture::rgb(Rgb::new(0.9, 0.1, 0.1)), Texture::uniform(0.5),
//!     UvTransform::from_offset_scale(Vec2::ZERO, Vec2::splat(4.0))));
//! let p = TexturePoint::uv(Vec2::new(0.05, 0.05));
//! assert_eq!(board.eval(&p), Rgb::new(0.9, 0.1, 0.1));
//! assert_eq!(board.eval_1(&p), 0.5); // Mitsuba's inverted eval_1
//! ```

mod bitmap;
mod checkerboard;
mod decode;
mod error;
mod mesh_attribute;
mod uv;

pub use bitmap::{Bitmap, BitmapOptions, FilterType, Storage, WrapMode};
pub use checkerboard::Checkerboard;
pub use decode::budget as decode_budget;
pub use error::{SUPPORTED_FORMATS, TextureError};
pub use mesh_attribute::{AttributePer, MeshAttribute, MeshAttributeTexture, MeshPoint, Usage};
pub use uv::UvTransform;

use crate::math::Rgb;
use glam::Vec2;

/// The memory a scene's textures may take.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureLimits {
    /// Largest decoded size of one image, in bytes (width × height × channels × bytes per
    /// sample as the file decodes, alpha included). Larger files are refused from their header.
    pub max_decoded_bytes: u64,
    /// Largest decoded size of all of a scene's images together (the scene builder enforces
    /// it by lowering the per-image limit to what is left).
    pub max_total_bytes: u64,
}

impl Default for TextureLimits {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl TextureLimits {
    /// 1 GiB per image, 4 GiB per scene.
    pub const DEFAULT: TextureLimits = TextureLimits { max_decoded_bytes: 1 << 30, max_total_bytes: 4 << 30 };

    /// A budget of `bytes` for the whole scene, which any one image may use up.
    pub fn total(bytes: u64) -> Self {
        TextureLimits { max_decoded_bytes: bytes, max_total_bytes: bytes }
    }
}

/// What a lookup needs to know about the surface point.
#[derive(Clone, Copy, Debug, Default)]
pub struct TexturePoint<'a> {
    /// The surface's uv (Mitsuba's `si.uv`).
    pub uv: Vec2,
    /// The hit mesh's attributes and triangle, for `mesh_attribute`; `None` off meshes.
    pub mesh: Option<MeshPoint<'a>>,
}

impl<'a> TexturePoint<'a> {
    /// A point known by its uv only.
    pub fn uv(uv: Vec2) -> Self {
        TexturePoint { uv, mesh: None }
    }

    /// A point on a mesh triangle.
    pub fn on_mesh(uv: Vec2, mesh: MeshPoint<'a>) -> Self {
        TexturePoint { uv, mesh: Some(mesh) }
    }
}

/// A texture that does not vary: Mitsuba's `uniform` (`<float>`) or `srgb` (`<rgb>`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Constant {
    /// What `eval` returns.
    pub rgb: Rgb,
    /// What `eval_1` and `mean` return: the value of a `<float>`, the channel mean of an `<rgb>`.
    pub scalar: f32,
}

/// Every texture kind, as a closed set.
#[derive(Clone, Debug)]
pub enum Texture {
    /// A constant colour.
    Constant(Constant),
    /// An image.
    Bitmap(Bitmap),
    /// A checkerboard of two textures.
    Checkerboard(Checkerboard),
    /// Per-vertex or per-face mesh data.
    MeshAttribute(MeshAttributeTexture),
}

impl From<Bitmap> for Texture {
    fn from(b: Bitmap) -> Self {
        Texture::Bitmap(b)
    }
}

impl From<Checkerboard> for Texture {
    fn from(c: Checkerboard) -> Self {
        Texture::Checkerboard(c)
    }
}

impl From<MeshAttributeTexture> for Texture {
    fn from(m: MeshAttributeTexture) -> Self {
        Texture::MeshAttribute(m)
    }
}

impl Texture {
    /// A `<float>` (or single-value `<spectrum>`) constant: grey, and `eval_1` is the value.
    pub fn uniform(value: f32) -> Texture {
        Texture::Constant(Constant { rgb: Rgb::splat(value), scalar: value })
    }

    /// An `<rgb>` constant: `eval_1` is the channel mean, as Mitsuba's `srgb` texture.
    pub fn rgb(rgb: Rgb) -> Texture {
        Texture::Constant(Constant { rgb, scalar: (rgb.x + rgb.y + rgb.z) / 3.0 })
    }

    /// The colour at `p`.
    #[inline]
    pub fn eval(&self, p: &TexturePoint) -> Rgb {
        match self {
            Texture::Constant(c) => c.rgb,
            Texture::Bitmap(b) => b.eval(p.uv),
            Texture::Checkerboard(c) => c.eval(p),
            Texture::MeshAttribute(m) => m.eval(p),
        }
    }

    /// The scalar at `p`, with each kind's Mitsuba semantics (see the module doc).
    #[inline]
    pub fn eval_1(&self, p: &TexturePoint) -> f32 {
        match self {
            Texture::Constant(c) => c.scalar,
            Texture::Bitmap(b) => b.eval_1(p.uv),
            Texture::Checkerboard(c) => c.eval_1(p),
            Texture::MeshAttribute(m) => m.eval_1(p),
        }
    }

    /// Mitsuba's `mean()`: the scalar average over the texture (luminance for colour images).
    /// `None` for `mesh_attribute`, whose average depends on the mesh (Mitsuba has none either).
    pub fn mean(&self) -> Option<f32> {
        match self {
            Texture::Constant(c) => Some(c.scalar),
            Texture::Bitmap(b) => Some(b.mean()),
            Texture::Checkerboard(c) => c.mean(),
            Texture::MeshAttribute(_) => None,
        }
    }

    /// The colour when the texture is a constant, so callers can skip lookups.
    pub fn is_constant(&self) -> Option<Rgb> {
        match self {
            Texture::Constant(c) => Some(c.rgb),
            _ => None,
        }
    }

    /// Bytes of image data held, nested textures included.
    pub fn decoded_bytes(&self) -> usize {
        match self {
            Texture::Bitmap(b) => b.decoded_bytes(),
            Texture::Checkerboard(c) => c.color0().decoded_bytes() + c.color1().decoded_bytes(),
            Texture::Constant(_) | Texture::MeshAttribute(_) => 0,
        }
    }

    /// True when some part of the texture reads mesh attributes.
    pub fn uses_mesh_attributes(&self) -> bool {
        match self {
            Texture::MeshAttribute(_) => true,
            Texture::Checkerboard(c) => c.color0().uses_mesh_attributes() || c.color1().uses_mesh_attributes(),
            Texture::Constant(_) | Texture::Bitmap(_) => false,
        }
    }

    /// Checks at scene build time that a shape with `attributes` (empty for non-meshes) can
    /// serve every `mesh_attribute` in this texture for `usage`.
    pub fn check_attributes(&self, attributes: &[MeshAttribute], usage: Usage) -> Result<(), TextureError> {
        match self {
            Texture::MeshAttribute(m) => m.check(attributes, usage),
            Texture::Checkerboard(c) => {
                c.color0().check_attributes(attributes, usage)?;
                c.color1().check_attributes(attributes, usage)
            }
            Texture::Constant(_) | Texture::Bitmap(_) => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_rgb_constant_eval_1_is_channel_mean() {
        let t = Texture::rgb(Rgb::new(0.9, 0.3, 0.0));
        let p = TexturePoint::default();
        assert_eq!(t.eval(&p), Rgb::new(0.9, 0.3, 0.0));
        assert!((t.eval_1(&p) - 0.4).abs() < 1e-7);
        assert_eq!(t.is_constant(), Some(Rgb::new(0.9, 0.3, 0.0)));
        assert_eq!(Texture::uniform(0.4).eval_1(&p), 0.4);
    }

    #[test]
    fn texture_is_shareable_across_render_threads() {
        fn send_sync<T: Send + Sync>() {}
        send_sync::<Texture>();
        send_sync::<TexturePoint>();
    }

    #[test]
    fn texture_checks_nested_mesh_attributes() {
        let board = Texture::from(Checkerboard::new(
            Texture::uniform(0.1),
            MeshAttributeTexture::new("face_id", 1.0).unwrap().into(),
            UvTransform::IDENTITY,
        ));
        assert!(board.uses_mesh_attributes());
        assert!(board.check_attributes(&[], Usage::Color).is_err());
        let attrs = [MeshAttribute::new("face_id", 1, vec![1.0]).unwrap()];
        assert!(board.check_attributes(&attrs, Usage::Scalar).is_ok());
        assert_eq!(board.mean(), None);
        assert_eq!(board.is_constant(), None);
    }
}
