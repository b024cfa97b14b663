//! Radiance HDR (RGBE) files, read as Mitsuba's `Bitmap::read_rgbe` reads them rather than
//! through the `image` crate, whose decoder insists on a `#?RADIANCE` signature (Mitsuba itself
//! writes `#?RGBE`) and expands pre-1991 run markers that Mitsuba reads as pixels. Only the
//! standard `-Y H +X W` orientation exists for Mitsuba; `xyze` files are converted to RGB.

use super::budget::Reservation;
use super::{Ctx, Image, Samples, xyz_to_rgb};
use crate::texture::TextureError;
use std::io::{BufRead, Read};

/// Header lines longer than this are not a Radiance header.
const MAX_LINE: u64 = 4096;

/// Reads an RGBE file as linear RGB floats.

/// Peak allocation over the declared floats: the image and the texels' copy.
const PEAK: u64 = 3;
pub(super) fn read_rgbe<R: BufRead>(ctx: &Ctx, mut reader: R) -> Result<(Image, Reservation), TextureError> {
    let first = line(ctx, &mut reader)?;
    if !first.starts_with("#?") {
        return Err(ctx.corrupt("invalid header"));
    }
    let mut xyz = None;
    let (width, height) = loop {
        let l = line(ctx, &mut reader)?;
        if l.starts_with("FORMAT=32-bit_rle_rgbe") {
            xyz = Some(false);
        } else if l.starts_with("FORMAT=32-bit_rle_xyze") {
            xyz = Some(true);
        } else {
            let tokens: Vec<&str> = l.split_ascii_whitespace().collect();
            if let ["-Y", h, "+X", w] = tokens[..] {
                let parse = |s: &str| s.parse::<u32>().map_err(|_| ctx.corrupt(format!("bad resolution {l:?}")));
                break (parse(w)?, parse(h)?);
            }
        }
    };
    let Some(xyz) = xyz else { return Err(ctx.corrupt("no FORMAT=32-bit_rle_rgbe line")) };
    let reservation = ctx.reserve(width, height, 12, PEAK)?;

    let (w, count) = (width as usize, width as usize * height as usize);
    let mut out = Vec::new();
    out.try_reserve_exact(count * 3).map_err(|_| ctx.unsupported("image too large"))?;
    let truncated = |_| ctx.corrupt("truncated pixel data");
    if !(8..=0x7fff).contains(&w) {
        // run-length encoding cannot describe such widths: the pixels are stored flat
        read_flat(&mut reader, count, &mut out).map_err(truncated)?;
    } else {
        let mut planes = vec![0u8; 4 * w];
        for y in 0..height as usize {
            let mut px = [0u8; 4];
            reader.read_exact(&mut px).map_err(truncated)?;
            if px[0] != 2 || px[1] != 2 || px[2] & 0x80 != 0 {
                // not run-length encoded: this pixel and all that follow are flat
                push(&mut out, px);
                read_flat(&mut reader, count - y * w - 1, &mut out).map_err(truncated)?;
                break;
            }
            if ((px[2] as usize) << 8 | px[3] as usize) != w {
                return Err(ctx.corrupt("wrong scanline width"));
            }
            read_scanline(ctx, &mut reader, &mut planes, w)?;
            for x in 0..w {
                push(&mut out, [planes[x], planes[w + x], planes[2 * w + x], planes[3 * w + x]]);
            }
        }
    }
    if xyz {
        for px in out.chunks_exact_mut(3) {
            px.copy_from_slice(&xyz_to_rgb([px[0], px[1], px[2]]));
        }
    }
    Ok((Image { width, height, channels: 3, samples: Samples::F32(out), srgb: false }, reservation))
}

/// One header line without its line ending.
fn line<R: BufRead>(ctx: &Ctx, reader: &mut R) -> Result<String, TextureError> {
    let mut buf = Vec::new();
    let n = reader.by_ref().take(MAX_LINE).read_until(b'\n', &mut buf).map_err(|e| ctx.corrupt(e))?;
    if n == 0 {
        return Err(ctx.corrupt("header ends before the -Y H +X W resolution line"));
    }
    if buf.last() != Some(&b'\n') && n as u64 == MAX_LINE {
        return Err(ctx.corrupt("header line too long"));
    }
    Ok(String::from_utf8_lossy(&buf).trim_end_matches(['\n', '\r']).to_string())
}

/// The four channel planes of one RLE scanline: runs (count > 128) and literal spans.
fn read_scanline<R: BufRead>(ctx: &Ctx, reader: &mut R, planes: &mut [u8], w: usize) -> Result<(), TextureError> {
    let truncated = |_| ctx.corrupt("truncated pixel data");
    for plane in planes.chunks_exact_mut(w) {
        let mut pos = 0;
        while pos < w {
            let mut head = [0u8; 2];
            reader.read_exact(&mut head).map_err(truncated)?;
            let (run, count) = if head[0] > 128 { (true, head[0] as usize - 128) } else { (false, head[0] as usize) };
            if count == 0 || count > w - pos {
                return Err(ctx.corrupt("bad scanline data"));
            }
            if run {
                plane[pos..pos + count].fill(head[1]);
            } else {
                plane[pos] = head[1];
                reader.read_exact(&mut plane[pos + 1..pos + count]).map_err(truncated)?;
            }
            pos += count;
        }
    }
    Ok(())
}

fn read_flat<R: BufRead>(reader: &mut R, pixels: usize, out: &mut Vec<f32>) -> std::io::Result<()> {
    let mut px = [0u8; 4];
    for _ in 0..pixels {
        reader.read_exact(&mut px)?;
        push(out, px);
    }
    Ok(())
}

/// Mitsuba's RGBE → float: mantissa · 2^(e − 136), exactly (a power of two), 0 when e = 0.
fn push(out: &mut Vec<f32>, px: [u8; 4]) {
    if px[3] == 0 {
        out.extend([0.0; 3]);
    } else {
        // in f64 the power of two and the products are exact, as Mitsuba's f32 ldexp is
        let f = 2f64.powi(px[3] as i32 - 136);
        out.extend([(px[0] as f64 * f) as f32, (px[1] as f64 * f) as f32, (px[2] as f64 * f) as f32]);
    }
}
