//! OpenEXR textures through the `exr` crate, following Mitsuba's `Bitmap::read_exr`: the
//! first part, channels recognised by the suffix after the last `.` (any case), and one sample
//! type for all channels, that of the alphabetically first channel. Half files stay half.

use super::budget::Reservation;
use super::{Ctx, Image, Samples, xyz_to_rgb};
use crate::texture::TextureError;
use exr::meta::MetaData;
use exr::meta::attribute::SampleType;
use exr::prelude::*;
use std::io::{BufRead, Seek, SeekFrom};
// the exr prelude brings its own `Result`
use std::result::Result;

/// Reads the first part of an EXR file as Y or RGB.

/// Peak allocation over the samples the header declares: the crate's channels, the f32
/// interleaving, half files' conversion back to f16 and the texels' own copy.
const PEAK: u64 = 6;
pub(super) fn read_exr<R: BufRead + Seek>(ctx: &Ctx, mut reader: R) -> Result<(Image, Reservation), TextureError> {
    let meta = MetaData::read_from_buffered(&mut reader, false).map_err(|e| ctx.corrupt(e))?;
    let header = meta.headers.first().ok_or_else(|| ctx.corrupt("no image part"))?;
    if header.deep {
        return Err(ctx.unsupported("deep data"));
    }
    // the reader allocates an offset table of 8 bytes per chunk, which the file must hold
    let chunks: u64 = meta.headers.iter().map(|h| h.chunk_count as u64).sum();
    if chunks.saturating_mul(8) > ctx.file_len {
        return Err(ctx.corrupt(format!(
            "the header claims {chunks} chunks, more than the file's {} bytes can list",
            ctx.file_len
        )));
    }
    let channels = &header.channels.list;
    let (width, height) = (header.layer_size.x(), header.layer_size.y());
    let (w32, h32) = (u32::try_from(width), u32::try_from(height));
    let (Ok(w32), Ok(h32)) = (w32, h32) else { return Err(ctx.unsupported("image too large")) };
    let bytes_per_pixel: u64 = channels.iter().map(|c| sample_bytes(c.sample_type)).sum();
    let reservation = ctx.reserve(w32, h32, bytes_per_pixel, PEAK)?;

    let names: Vec<String> = channels.iter().map(|c| c.name.to_string()).collect();
    let layout = classify(&names)
        .ok_or_else(|| ctx.unsupported(format!("channels {} are not Y[A], RGB[A] or XYZ[A]", names.join(","))))?;
    let first = channels.iter().min_by(|a, b| a.name.bytes().cmp(b.name.bytes())).map(|c| c.sample_type);
    let half = match first {
        Some(SampleType::F16) => true,
        Some(SampleType::F32) => false,
        _ => return Err(ctx.unsupported("uint channels")),
    };

    reader.seek(SeekFrom::Start(0)).map_err(|e| ctx.corrupt(e))?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(reader)
        .map_err(|e| ctx.corrupt(e))?;
    let data = &image.layer_data.channel_data.list;
    let find =
        |class: Class| data.iter().find(|c| channel_class(&c.name.to_string()) == Some(class)).map(|c| &c.sample_data);
    let wanted: &[Class] = if layout == Layout::Y { &[Class::Y] } else { &layout.classes() };
    let mut sources = Vec::with_capacity(3);
    for &class in wanted {
        let samples = find(class).ok_or_else(|| ctx.corrupt("a channel listed in the header is missing"))?;
        if samples.len() != width * height {
            return Err(ctx.unsupported("sub-sampled channels"));
        }
        sources.push(samples);
    }
    let count = width * height * sources.len();
    let value = |c: usize, i: usize| -> f32 {
        match sources[c] {
            FlatSamples::F16(v) => v[i].to_f32(),
            FlatSamples::F32(v) => v[i],
            FlatSamples::U32(v) => v[i] as f32,
        }
    };
    let mut linear = Vec::with_capacity(count);
    for i in 0..width * height {
        if layout == Layout::Xyz {
            linear.extend(xyz_to_rgb([value(0, i), value(1, i), value(2, i)]));
        } else {
            linear.extend((0..sources.len()).map(|c| value(c, i)));
        }
    }
    // half → f32 → half is exact, so routing every channel through f32 loses nothing
    let samples =
        if half { Samples::F16(linear.into_iter().map(f16::from_f32).collect()) } else { Samples::F32(linear) };
    Ok((Image { width: w32, height: h32, channels: sources.len().min(3), samples, srgb: false }, reservation))
}

fn sample_bytes(t: SampleType) -> u64 {
    match t {
        SampleType::F16 => 2,
        SampleType::F32 | SampleType::U32 => 4,
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Class {
    R,
    G,
    B,
    X,
    Y,
    Z,
    A,
    Chroma,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Layout {
    Y,
    Rgb,
    Xyz,
}

impl Layout {
    fn classes(self) -> [Class; 3] {
        match self {
            Layout::Rgb => [Class::R, Class::G, Class::B],
            Layout::Xyz => [Class::X, Class::Y, Class::Z],
            Layout::Y => [Class::Y, Class::Y, Class::Y],
        }
    }
}

fn channel_class(name: &str) -> Option<Class> {
    let suffix = name.rsplit('.').next().unwrap_or(name).to_ascii_lowercase();
    Some(match suffix.as_str() {
        "r" => Class::R,
        "g" => Class::G,
        "b" => Class::B,
        "x" => Class::X,
        "y" => Class::Y,
        "z" => Class::Z,
        "a" => Class::A,
        "ry" | "by" => Class::Chroma,
        _ => return None,
    })
}

/// Mitsuba's recognition of standard channel sets: exactly the three colour channels, or
/// those plus one alpha channel; anything else is a multi-channel image textures cannot use.
/// Luminance-chroma files are refused.
fn classify(names: &[String]) -> Option<Layout> {
    let classes: Vec<Option<Class>> = names.iter().map(|n| channel_class(n)).collect();
    let has = |c: Class| classes.contains(&Some(c));
    let fits = |colour: usize| names.len() == colour || (names.len() == colour + 1 && has(Class::A));
    if has(Class::R) && has(Class::G) && has(Class::B) {
        fits(3).then_some(Layout::Rgb)
    } else if has(Class::X) && has(Class::Y) && has(Class::Z) {
        fits(3).then_some(Layout::Xyz)
    } else if has(Class::Chroma) {
        None
    } else if has(Class::Y) {
        fits(1).then_some(Layout::Y)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(list: &[&str]) -> Vec<String> {
        list.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn exr_classify_follows_mitsuba_channel_sets() {
        assert_eq!(classify(&names(&["B", "G", "R"])), Some(Layout::Rgb));
        assert_eq!(classify(&names(&["A", "B", "G", "R"])), Some(Layout::Rgb));
        assert_eq!(classify(&names(&["beauty.b", "beauty.g", "beauty.r"])), Some(Layout::Rgb));
        assert_eq!(classify(&names(&["Y"])), Some(Layout::Y));
        assert_eq!(classify(&names(&["A", "Y"])), Some(Layout::Y));
        assert_eq!(classify(&names(&["X", "Y", "Z"])), Some(Layout::Xyz));
        assert_eq!(classify(&names(&["B", "G", "R", "depth"])), None);
        assert_eq!(classify(&names(&["BY", "RY", "Y"])), None);
        assert_eq!(classify(&names(&["depth"])), None);
    }
}
