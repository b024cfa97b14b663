//! PNG, JPEG, BMP and TGA through the `image` crate's decoders, which expand
//! PNG palettes, transparency and sub-byte greys as libpng does for Mitsuba.

use super::budget::Reservation;
use super::{Ctx, Format, Image, Samples, keep_channels};
use crate::texture::TextureError;
use image::codecs::{bmp::BmpDecoder, jpeg::JpegDecoder, png::PngDecoder, tga::TgaDecoder};
use image::{ColorType, ImageDecoder, ImageError, Limits};
use std::io::{BufRead, Seek};

/// Decodes a file of one of the formats above.

/// Peak allocation over the decoder's samples: its buffer, the 16-bit widening, alpha
/// dropped and the texels' copy.
const PEAK: u64 = 4;
pub(super) fn read<R: BufRead + Seek>(ctx: &Ctx, reader: R) -> Result<(Image, Reservation), TextureError> {
    let err = |e| map_error(ctx, e);
    match ctx.format {
        Format::Png => decode(ctx, PngDecoder::new(reader).map_err(err)?),
        Format::Jpeg => decode(ctx, JpegDecoder::new(reader).map_err(err)?),
        Format::Tga => decode(ctx, TgaDecoder::new(reader).map_err(err)?),
        Format::Bmp => {
            let mut decoder = BmpDecoder::new(reader).map_err(err)?;
            // Mitsuba reads an 8-bit BMP's palette indices as grey levels and ignores the
            // palette (right for the usual grey ramp); do the same so images agree.
            if decoder.get_palette().is_some() {
                decoder.set_indexed_color(true);
            }
            decode(ctx, decoder)
        }
        Format::Exr | Format::Rgbe | Format::Pfm | Format::Ppm => {
            Err(ctx.unsupported("not a raster format (internal dispatch)"))
        }
    }
}

fn decode<D: ImageDecoder>(ctx: &Ctx, mut decoder: D) -> Result<(Image, Reservation), TextureError> {
    let (width, height) = decoder.dimensions();
    let color = decoder.color_type();
    let reservation = ctx.reserve(width, height, color.bytes_per_pixel() as u64, PEAK)?;
    // the budget also caps the decoder's own working memory (the crate's default is 512 MiB)
    let mut limits = Limits::no_limits();
    limits.max_alloc = Some(ctx.limits.max_decoded_bytes);
    decoder.set_limits(limits).map_err(|e| map_error(ctx, e))?;

    let total = usize::try_from(decoder.total_bytes()).map_err(|_| ctx.unsupported("image too large"))?;
    let mut buf = Vec::new();
    buf.try_reserve_exact(total).map_err(|_| ctx.unsupported(format!("cannot allocate {total} bytes")))?;
    buf.resize(total, 0);
    decoder.read_image(&mut buf).map_err(|e| map_error(ctx, e))?;

    let (stride, keep) = match color {
        ColorType::L8 | ColorType::L16 => (1, 1),
        ColorType::La8 | ColorType::La16 => (2, 1),
        ColorType::Rgb8 | ColorType::Rgb16 => (3, 3),
        ColorType::Rgba8 | ColorType::Rgba16 => (4, 3),
        other => return Err(ctx.unsupported(format!("pixel layout {other:?}"))),
    };
    let samples = match color.bytes_per_pixel() as usize / stride {
        1 => Samples::U8(keep_channels(buf, stride, keep)),
        _ => {
            let wide = buf.chunks_exact(2).map(|b| u16::from_ne_bytes([b[0], b[1]])).collect();
            Samples::U16(keep_channels(wide, stride, keep))
        }
    };
    // all four formats are sRGB-encoded integers (core/bitmap.cpp, read_*)
    Ok((Image { width, height, channels: keep, samples, srgb: true }, reservation))
}

fn map_error(ctx: &Ctx, e: ImageError) -> TextureError {
    match e {
        ImageError::Unsupported(u) => ctx.unsupported(u.to_string()),
        ImageError::Limits(_) => ctx.unsupported(format!(
            "the decoder needs more working memory than the texture budget of {} bytes",
            ctx.limits.max_decoded_bytes
        )),
        // an I/O error while decoding a file that opened is a truncated file
        other => ctx.corrupt(other),
    }
}
