//! OpenEXR output and input through the `exr` crate. Tessera writes one part with channels
//! R, G, B (f32, the beauty image) and `sample_count.Y` (u32), ZIP-compressed, plus text
//! attributes describing the render.

use exr::prelude::*;
use std::path::Path;

/// EXR reading or writing failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ExrError {
    /// The exr crate reported an error.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// What went wrong.
        message: String,
    },
}

fn err(path: &Path, e: impl std::fmt::Display) -> ExrError {
    ExrError::Io { path: path.display().to_string(), message: e.to_string() }
}

/// An EXR attribute value.
#[derive(Clone, Debug, PartialEq)]
pub enum Attribute {
    /// Text.
    Text(String),
    /// A 32-bit float.
    Float(f32),
    /// A 32-bit integer.
    Int(i32),
}

/// What one EXR file holds besides the beauty image.
#[derive(Clone, Debug, Default)]
pub struct ExrExtras<'a> {
    /// Per-pixel sample counts (`sample_count.Y`, u32).
    pub counts: Option<&'a [u32]>,
    /// Further single-channel f32 layers, written as `NAME.Y`.
    pub layers: Vec<(&'a str, &'a [f32])>,
    /// Header attributes.
    pub attributes: Vec<(String, Attribute)>,
}

/// Writes the beauty image, per-pixel sample counts, extra layers and attributes.
pub fn write_exr(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[[f32; 3]],
    extras: &ExrExtras,
) -> std::result::Result<(), ExrError> {
    let (w, h) = (width as usize, height as usize);
    let mut channels = smallvec::SmallVec::<[AnyChannel<FlatSamples>; 4]>::new();
    for (c, name) in ["R", "G", "B"].iter().enumerate() {
        channels.push(AnyChannel::new(*name, FlatSamples::F32(rgb.iter().map(|p| finite(p[c])).collect())));
    }
    if let Some(counts) = extras.counts {
        channels.push(AnyChannel::new("sample_count.Y", FlatSamples::U32(counts.to_vec())));
    }
    for (name, data) in &extras.layers {
        if data.len() != w * h {
            return Err(err(path, format!("layer {name} has {} values for {w}x{h} pixels", data.len())));
        }
        channels.push(AnyChannel::new(
            format!("{name}.Y").as_str(),
            FlatSamples::F32(data.iter().map(|&v| finite(v)).collect()),
        ));
    }
    let layer =
        Layer::new(Vec2(w, h), LayerAttributes::default(), Encoding::SMALL_LOSSLESS, AnyChannels::sort(channels));
    let mut attrs = ImageAttributes::new(IntegerBounds::from_dimensions(Vec2(w, h)));
    for (k, v) in &extras.attributes {
        let value = match v {
            Attribute::Text(t) => AttributeValue::Text(Text::from(t.as_str())),
            Attribute::Float(f) => AttributeValue::F32(*f),
            Attribute::Int(i) => AttributeValue::I32(*i),
        };
        attrs.other.insert(Text::from(k.as_str()), value);
    }
    Image::empty(attrs).with_layer(layer).write().to_file(path).map_err(|e| err(path, e))
}

/// `v` as written to a file: no Inf or NaN reaches one, whatever sums a film holds (a value
/// past f32's range is clamped to it, one that is not a number shows as 0).
pub fn finite(v: f32) -> f32 {
    if v.is_nan() { 0.0 } else { v.clamp(f32::MIN, f32::MAX) }
}

/// Reads one single-channel f32 layer (`NAME.Y`) of a Tessera EXR.
pub fn read_layer(path: &Path, name: &str) -> std::result::Result<Vec<f32>, ExrError> {
    let image = read_all(path)?;
    let layer = image.layer_data.first().ok_or_else(|| err(path, "no layer"))?;
    let wanted = format!("{name}.Y");
    let channel = layer
        .channel_data
        .list
        .iter()
        .find(|c| c.name == Text::from(wanted.as_str()))
        .ok_or_else(|| err(path, format!("no channel {wanted}")))?;
    Ok(channel.sample_data.values_as_f32().collect())
}

/// Reads a numeric header attribute written by [`write_exr`].
pub fn read_attribute(path: &Path, name: &str) -> std::result::Result<Option<f64>, ExrError> {
    let image = read_all(path)?;
    // a single-part file's custom attributes may come back as the image's or the layer's
    let key = Text::from(name);
    let value =
        image.attributes.other.get(&key).or_else(|| image.layer_data.iter().find_map(|l| l.attributes.other.get(&key)));
    Ok(value.and_then(|v| match v {
        AttributeValue::F32(f) => Some(*f as f64),
        AttributeValue::I32(i) => Some(*i as f64),
        _ => None,
    }))
}

/// An RGB image read from an EXR file.
#[derive(Clone, Debug)]
pub struct RgbImage {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Pixels, row-major, row 0 at the top.
    pub pixels: Vec<[f32; 3]>,
}

/// Reads every part, channel and attribute of an EXR file.
fn read_all(path: &Path) -> std::result::Result<Image<Layers<AnyChannels<FlatSamples>>>, ExrError> {
    read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_file(path)
        .map_err(|e| err(path, e))
}

/// Reads R, G, B from the part named `beauty` if there is one, else the first part (the rule
/// of `exrcompare.py`). Channels may be plain or prefixed with `beauty.`.
pub fn read_rgb(path: &Path) -> std::result::Result<RgbImage, ExrError> {
    let image = read_all(path)?;
    let layer = image
        .layer_data
        .iter()
        .find(|l| l.attributes.layer_name.as_ref().is_some_and(|n| n.to_string() == "beauty"))
        .or_else(|| image.layer_data.first())
        .ok_or_else(|| err(path, "no image part"))?;
    let size = layer.size;
    let find = |c: &str| {
        layer
            .channel_data
            .list
            .iter()
            .find(|ch| {
                let n = ch.name.to_string();
                n == c || n == format!("beauty.{c}")
            })
            .ok_or_else(|| err(path, format!("no channel {c}")))
    };
    let (r, g, b) = (find("R")?, find("G")?, find("B")?);
    let n = size.0 * size.1;
    let pixels = (0..n)
        .map(|i| {
            [
                r.sample_data.value_by_flat_index(i).to_f32(),
                g.sample_data.value_by_flat_index(i).to_f32(),
                b.sample_data.value_by_flat_index(i).to_f32(),
            ]
        })
        .collect();
    Ok(RgbImage { width: size.0 as u32, height: size.1 as u32, pixels })
}

/// Reads the `sample_count.Y` channel of a Tessera EXR.
pub fn read_sample_counts(path: &Path) -> std::result::Result<Vec<u32>, ExrError> {
    let image = read_all(path)?;
    let layer = image.layer_data.first().ok_or_else(|| err(path, "no image part"))?;
    let ch = layer
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == "sample_count.Y")
        .ok_or_else(|| err(path, "no channel sample_count.Y"))?;
    Ok((0..layer.size.0 * layer.size.1).map(|i| ch.sample_data.value_by_flat_index(i).to_u32()).collect())
}
