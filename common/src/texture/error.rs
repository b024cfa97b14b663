//! The one error type of the texture module. Every message names the image file or the mesh
//! attribute it is about, so a scene builder can pass it on without adding context.

use std::path::PathBuf;

/// The image formats [`Bitmap::load`](super::Bitmap::load) reads, for error messages.
pub const SUPPORTED_FORMATS: &str = "PNG (.png), JPEG (.jpg, .jpeg), OpenEXR (.exr), Radiance HDR (.hdr, .rgbe), BMP (.bmp), TGA (.tga), PFM (.pfm), PPM (.ppm)";

/// Why a texture could not be built.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TextureError {
    /// The image file does not exist.
    #[error("{}: texture file not found", path.display())]
    NotFound {
        /// The file.
        path: PathBuf,
    },
    /// The image file exists but could not be read.
    #[error("{}: cannot read texture file: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// Neither the file's first bytes nor its extension name a supported format.
    #[error("{}: unknown image format (extension {extension:?}); supported: {SUPPORTED_FORMATS}", path.display())]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// The file's extension, empty when it has none.
        extension: String,
    },
    /// The file is of a known format but holds a variant of it that textures cannot use
    /// (an EXR without R,G,B or Y channels, a 16-bit PPM, ...).
    #[error("{}: unsupported {format} image: {message}", path.display())]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// The format the file was recognised as.
        format: &'static str,
        /// What is not supported.
        message: String,
    },
    /// The file is truncated or malformed.
    #[error("{}: corrupt {format} image: {message}", path.display())]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// The format the file was recognised as.
        format: &'static str,
        /// The decoder's reason.
        message: String,
    },
    /// Decoding the image would need more memory than the texture budget allows. Raised from the
    /// header, before any pixel is decoded.
    #[error(
        "{}: decoding this {width}x{height} image needs {needed} bytes, over the texture budget of {limit} bytes",
        path.display()
    )]
    OverBudget {
        /// The file.
        path: PathBuf,
        /// Width in pixels, from the header.
        width: u32,
        /// Height in pixels, from the header.
        height: u32,
        /// Bytes the decoded pixels would take.
        needed: u64,
        /// The budget ([`TextureLimits::max_decoded_bytes`](super::TextureLimits::max_decoded_bytes)).
        limit: u64,
    },
    /// In-memory texel data does not match the size it was declared with.
    #[error("bitmap data has {len} values, expected {expected} ({width}x{height}x{channels})")]
    DataSize {
        /// Values given.
        len: usize,
        /// Values expected.
        expected: usize,
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// Channels per pixel.
        channels: usize,
    },
    /// A mesh attribute name that is neither `vertex_*` nor `face_*`.
    #[error("invalid mesh attribute name {name:?}: it must start with \"vertex_\" or \"face_\"")]
    AttributeName {
        /// The name.
        name: String,
    },
    /// A mesh attribute whose data length does not fit its declared shape.
    #[error("mesh attribute {name:?}: {message}")]
    AttributeData {
        /// The attribute.
        name: String,
        /// What is wrong.
        message: String,
    },
    /// A `mesh_attribute` texture names an attribute the shape does not have.
    #[error("mesh_attribute texture: the shape has no attribute {name:?} (it has: {available})")]
    MissingAttribute {
        /// The attribute the texture asks for.
        name: String,
        /// The shape's attribute names, comma-separated, or `none`.
        available: String,
    },
    /// A `mesh_attribute` texture whose attribute has a component count the use cannot take:
    /// colours need 1 or 3 components, scalar uses (`eval_1`) exactly 1, as in Mitsuba.
    #[error("mesh_attribute texture {name:?}: the attribute has {components} components, {usage} needs {needed}")]
    AttributeComponents {
        /// The attribute.
        name: String,
        /// Its component count.
        components: usize,
        /// `"a colour"` or `"a scalar"`.
        usage: &'static str,
        /// What that use accepts.
        needed: &'static str,
    },
}
