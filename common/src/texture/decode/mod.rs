//! Image files to texel arrays, for `bitmap` textures. The format is recognised from the
//! file's first bytes as Mitsuba's `Bitmap::detect_file_format` does (so a JPEG named `.png`
//! still loads), with the extension as the fallback for TGA files without the TGA 2 footer. The
//! size is read from the header and checked against the [`TextureLimits`] budget before any
//! pixel is decoded. Alpha is dropped and XYZ converted here, so every [`Image`] has 1 (Y) or 3
//! (RGB) channels, rows top to bottom.

pub mod budget;
mod exr;
mod netpbm;
mod raster;
mod rgbe;

use super::{TextureError, TextureLimits};
use budget::Reservation;
use half::f16;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

/// Decoded samples in the file's own precision.
pub(crate) enum Samples {
    /// 8-bit (PNG, JPEG, BMP, TGA, PPM).
    U8(Vec<u8>),
    /// 16-bit (PNG).
    U16(Vec<u16>),
    /// Half-float (OpenEXR).
    F16(Vec<f16>),
    /// Float (OpenEXR, Radiance HDR, PFM).
    F32(Vec<f32>),
}

impl Samples {
    fn len(&self) -> usize {
        match self {
            Samples::U8(v) => v.len(),
            Samples::U16(v) => v.len(),
            Samples::F16(v) => v.len(),
            Samples::F32(v) => v.len(),
        }
    }
}

/// A decoded image: `channels` (1 or 3) interleaved samples per pixel, row 0 at the top.
pub(crate) struct Image {
    pub width: u32,
    pub height: u32,
    pub channels: usize,
    pub samples: Samples,
    /// The samples are sRGB-encoded (integer formats), not linear (float formats).
    pub srgb: bool,
}

/// The file formats textures read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Format {
    Png,
    Jpeg,
    Exr,
    Rgbe,
    Bmp,
    Tga,
    Pfm,
    Ppm,
}

impl Format {
    /// The name used in error messages.
    pub fn name(self) -> &'static str {
        match self {
            Format::Png => "PNG",
            Format::Jpeg => "JPEG",
            Format::Exr => "OpenEXR",
            Format::Rgbe => "Radiance HDR",
            Format::Bmp => "BMP",
            Format::Tga => "TGA",
            Format::Pfm => "PFM",
            Format::Ppm => "PPM",
        }
    }
}

/// Reads `path` within the budget; the reservation covers the decoded image until the caller
/// has made its texels.
pub(crate) fn read(path: &Path, limits: &TextureLimits) -> Result<(Image, Reservation), TextureError> {
    let mut file = std::fs::File::open(path).map_err(|e| io_error(path, e))?;
    let file_len = file.metadata().map_err(|e| io_error(path, e))?.len();
    let format = detect(path, &mut file).map_err(|e| io_error(path, e))?.ok_or_else(|| {
        let extension = path.extension().map(|e| e.to_string_lossy().into_owned()).unwrap_or_default();
        TextureError::UnknownFormat { path: path.to_path_buf(), extension }
    })?;
    file.seek(SeekFrom::Start(0)).map_err(|e| io_error(path, e))?;
    let reader = std::io::BufReader::new(file);
    let ctx = Ctx { path, format, limits, file_len };
    // The decoders are third-party parsers of untrusted files: a panic on a malformed file must
    // become an error for this texture, not take the worker down.
    let image = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match format {
        Format::Exr => exr::read_exr(&ctx, reader),
        Format::Pfm => netpbm::read_pfm(&ctx, reader),
        Format::Ppm => netpbm::read_ppm(&ctx, reader),
        Format::Rgbe => rgbe::read_rgbe(&ctx, reader),
        _ => raster::read(&ctx, reader),
    }))
    .unwrap_or_else(|_| Err(ctx.corrupt("the decoder failed on malformed data")))?;
    let (image, reservation) = image;
    if image.width == 0 || image.height == 0 {
        return Err(ctx.corrupt("the image has no pixels"));
    }
    // lookups index the samples directly: this is what keeps them in bounds
    if image.samples.len() != image.width as usize * image.height as usize * image.channels {
        return Err(ctx.corrupt("the decoder returned a wrong number of samples"));
    }
    Ok((image, reservation))
}

fn io_error(path: &Path, e: std::io::Error) -> TextureError {
    if e.kind() == std::io::ErrorKind::NotFound {
        TextureError::NotFound { path: path.to_path_buf() }
    } else {
        TextureError::Io { path: path.to_path_buf(), source: e }
    }
}

/// Mitsuba's magic numbers; TGA has none at the start, only an optional footer.
fn detect(path: &Path, file: &mut std::fs::File) -> std::io::Result<Option<Format>> {
    let mut start = [0u8; 8];
    let n = read_up_to(file, &mut start)?;
    let start = &start[..n];
    let format = if start.starts_with(b"BM") {
        Some(Format::Bmp)
    } else if start.starts_with(b"#?") {
        Some(Format::Rgbe)
    } else if start.starts_with(b"PF") || start.starts_with(b"Pf") {
        Some(Format::Pfm)
    } else if start.starts_with(b"P6") {
        Some(Format::Ppm)
    } else if start.starts_with(&[0xFF, 0xD8]) {
        Some(Format::Jpeg)
    } else if start.starts_with(&[0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A]) {
        Some(Format::Png)
    } else if start.starts_with(&[0x76, 0x2F, 0x31, 0x01]) {
        Some(Format::Exr)
    } else if has_tga_footer(file)? {
        Some(Format::Tga)
    } else {
        None
    };
    // Mitsuba reads only TGA 2 files (with the footer); older TGA files are common, and the
    // extension is the only way to know them.
    let is_tga_ext = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("tga"));
    Ok(format.or(is_tga_ext.then_some(Format::Tga)))
}

fn has_tga_footer(file: &mut std::fs::File) -> std::io::Result<bool> {
    let len = file.seek(SeekFrom::End(0))?;
    if len < 18 {
        return Ok(false);
    }
    file.seek(SeekFrom::End(-18))?;
    let mut footer = [0u8; 18];
    file.read_exact(&mut footer)?;
    Ok(&footer[..17] == b"TRUEVISION-XFILE." && footer[17] == 0)
}

fn read_up_to(file: &mut std::fs::File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match file.read(&mut buf[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n)
}

/// What every decoder needs to report errors and check the budget.
pub(crate) struct Ctx<'a> {
    pub path: &'a Path,
    pub format: Format,
    pub limits: &'a TextureLimits,
    /// The file's size in bytes.
    pub file_len: u64,
}

impl Ctx<'_> {
    pub fn corrupt(&self, message: impl std::fmt::Display) -> TextureError {
        TextureError::Corrupt {
            path: self.path.to_path_buf(),
            format: self.format.name(),
            message: message.to_string(),
        }
    }

    pub fn unsupported(&self, message: impl Into<String>) -> TextureError {
        TextureError::Unsupported { path: self.path.to_path_buf(), format: self.format.name(), message: message.into() }
    }

    /// Checks an image's header before a pixel is decoded, and reserves the decode's memory
    /// from the process's [`budget`]. Refused: decoded samples (`width`×`height`×
    /// `bytes_per_pixel`, in the decoder's own layout, at least what the texture keeps) over
    /// the scene's budget, or more than [`MAX_INFLATION`] times the file's bytes (a header's
    /// claim that no data could back). `peak` is what the decoder allocates at most, the kept
    /// texels included, in units of the decoded samples' bytes (×`peak`).
    pub fn reserve(
        &self,
        width: u32,
        height: u32,
        bytes_per_pixel: u64,
        peak: u64,
    ) -> Result<Reservation, TextureError> {
        let needed = (width as u64).saturating_mul(height as u64).saturating_mul(bytes_per_pixel);
        if needed > self.limits.max_decoded_bytes {
            return Err(TextureError::OverBudget {
                path: self.path.to_path_buf(),
                width,
                height,
                needed,
                limit: self.limits.max_decoded_bytes,
            });
        }
        let backed = self.file_len.saturating_mul(MAX_INFLATION).max(MIN_INFLATED);
        if needed > backed {
            return Err(self.corrupt(format!(
                "the header claims {width}x{height} pixels ({needed} bytes decoded), more than {MAX_INFLATION} times the file's {} bytes",
                self.file_len
            )));
        }
        budget::GLOBAL.take(needed.saturating_mul(peak)).map_err(|refusal| match refusal {
            budget::Refusal::TooLarge { capacity } => self.unsupported(format!(
                "decoding needs {} bytes at its peak, more than the {capacity} bytes this process lets decodes hold",
                needed.saturating_mul(peak)
            )),
            budget::Refusal::Busy => self.unsupported("other images held the decoding memory for minutes: try again"),
        })
    }
}

/// The most an image's decoded samples may outweigh its file. Compression can reach about
/// 1000:1 on a flat image, but real textures shrink a few times, rarely a hundred; a file that
/// claims more is refused before it costs memory out of proportion to what was sent.
pub const MAX_INFLATION: u64 = 256;
/// What any image may decode to whatever its file's size (a flat 4096² RGB map).
pub const MIN_INFLATED: u64 = 64 << 20;

/// Keeps the first `keep` of every `stride` interleaved samples: drops alpha (Mitsuba ignores
/// it, with no premultiplication).
pub(crate) fn keep_channels<T: Copy>(samples: Vec<T>, stride: usize, keep: usize) -> Vec<T> {
    if stride == keep {
        return samples;
    }
    samples.chunks_exact(stride).flat_map(|px| px[..keep].iter().copied()).collect()
}

/// Mitsuba's XYZ → linear sRGB matrix (the one `Bitmap::convert` blends with), applied in f32.
pub(crate) fn xyz_to_rgb(xyz: [f32; 3]) -> [f32; 3] {
    let [x, y, z] = xyz;
    [
        3.240479 * x - 1.53715 * y - 0.498535 * z,
        -0.969256 * x + 1.875991 * y + 0.041556 * z,
        0.055648 * x - 0.204043 * y + 1.057311 * z,
    ]
}
