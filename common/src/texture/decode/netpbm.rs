//! PFM (float, linear) and binary PPM (8-bit, sRGB) textures, read as Mitsuba reads them:
//! PFM rows are stored bottom-up and flipped, its samples multiplied by |scale| when that is
//! not 1; PPM samples are bytes normalised by 255 whatever the declared maximum.

use super::budget::Reservation;
use super::{Ctx, Image, Samples};
use crate::texture::TextureError;
use std::io::BufRead;

/// Header tokens longer than this are not numbers: the file is not what its magic says.
const MAX_TOKEN: usize = 32;

/// Reads a PFM file (`PF` colour, `Pf` grey).

/// Peak allocation over the declared samples: the bytes read, their floats and the texels'
/// copy (PFM); the bytes and the texels' copy (PPM).
const PFM_PEAK: u64 = 4;
const PPM_PEAK: u64 = 3;
pub(super) fn read_pfm<R: BufRead>(ctx: &Ctx, mut reader: R) -> Result<(Image, Reservation), TextureError> {
    let magic = token(ctx, &mut reader)?;
    let channels = match magic.as_str() {
        "PF" => 3,
        "Pf" => 1,
        _ => return Err(ctx.corrupt("bad PFM magic")),
    };
    let width: u32 = number(ctx, &mut reader)?;
    let height: u32 = number(ctx, &mut reader)?;
    let scale: f32 = number(ctx, &mut reader)?;
    if width == 0 || height == 0 {
        return Err(ctx.corrupt("the image has no pixels"));
    }
    let reservation = ctx.reserve(width, height, 4 * channels as u64, PFM_PEAK)?;

    let count = width as usize * height as usize * channels;
    let bytes = read_exact_vec(ctx, &mut reader, count * 4)?;
    let little = scale <= 0.0;
    let factor = scale.abs();
    let row = width as usize * channels;
    let mut samples = Vec::with_capacity(count);
    // bottom row first in the file; ours is top-down
    for chunk in bytes.chunks_exact(row * 4).rev() {
        samples.extend(chunk.chunks_exact(4).map(|b| {
            let b = [b[0], b[1], b[2], b[3]];
            let v = if little { f32::from_le_bytes(b) } else { f32::from_be_bytes(b) };
            if factor != 1.0 { v * factor } else { v }
        }));
    }
    Ok((Image { width, height, channels, samples: Samples::F32(samples), srgb: false }, reservation))
}

/// Reads a binary (`P6`) PPM file with at most 8 bits per sample.
pub(super) fn read_ppm<R: BufRead>(ctx: &Ctx, mut reader: R) -> Result<(Image, Reservation), TextureError> {
    if token(ctx, &mut reader)? != "P6" {
        return Err(ctx.corrupt("bad PPM magic"));
    }
    let width: u32 = number(ctx, &mut reader)?;
    let height: u32 = number(ctx, &mut reader)?;
    let max: u32 = number(ctx, &mut reader)?;
    if max > 255 {
        // Mitsuba would read these samples in the wrong byte order; refuse rather than differ
        return Err(ctx.unsupported("16-bit samples"));
    }
    let reservation = ctx.reserve(width, height, 3, PPM_PEAK)?;
    let bytes = read_exact_vec(ctx, &mut reader, width as usize * height as usize * 3)?;
    Ok((Image { width, height, channels: 3, samples: Samples::U8(bytes), srgb: true }, reservation))
}

/// The next whitespace-delimited token; consumes the one whitespace byte that ends it, so the
/// binary data after the last header token starts right after.
fn token<R: BufRead>(ctx: &Ctx, reader: &mut R) -> Result<String, TextureError> {
    let mut out = String::new();
    let mut byte = [0u8; 1];
    loop {
        reader.read_exact(&mut byte).map_err(|_| ctx.corrupt("truncated header"))?;
        let c = byte[0];
        if c.is_ascii_whitespace() {
            if out.is_empty() {
                continue;
            }
            return Ok(out);
        }
        if out.len() >= MAX_TOKEN || !c.is_ascii_graphic() {
            return Err(ctx.corrupt("malformed header"));
        }
        out.push(c as char);
    }
}

fn number<T: std::str::FromStr, R: BufRead>(ctx: &Ctx, reader: &mut R) -> Result<T, TextureError> {
    let t = token(ctx, reader)?;
    t.parse().map_err(|_| ctx.corrupt(format!("header value {t:?} is not a number")))
}

fn read_exact_vec<R: BufRead>(ctx: &Ctx, reader: &mut R, len: usize) -> Result<Vec<u8>, TextureError> {
    let mut bytes = Vec::new();
    bytes.try_reserve_exact(len).map_err(|_| ctx.unsupported(format!("cannot allocate {len} bytes")))?;
    bytes.resize(len, 0);
    reader.read_exact(&mut bytes).map_err(|_| ctx.corrupt("truncated pixel data"))?;
    Ok(bytes)
}
