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

/// Writes the beauty image and per-pixel sample counts.
pub fn write_exr(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[[f32; 3]],
    counts: Option<&[u32]>,
    attributes: &[(String, String)],
) -> std::result::Result<(), ExrError> {
    let (w, h) = (width as usize, height as usize);
    let mut channels = smallvec::SmallVec::<[AnyChannel<FlatSamples>; 4]>::new();
    for (c, name) in ["R", "G", "B"].iter().enumerate() {
        channels.push(AnyChannel::new(*name, FlatSamples::F32(rgb.iter().map(|p| p[c]).collect())));
    }
    if let Some(counts) = counts {
        channels.push(AnyChannel::new("sample_count.Y", FlatSamples::U32(counts.to_vec())));
    }
    let layer =
        Layer::new(Vec2(w, h), LayerAttributes::default(), Encoding::SMALL_LOSSLESS, AnyChannels::sort(channels));
    let mut attrs = ImageAttributes::new(IntegerBounds::from_dimensions(Vec2(w, h)));
    for (k, v) in attributes {
        attrs.other.insert(Text::from(k.as_str()), AttributeValue::Text(Text::from(v.as_str())));
    }
    Image::empty(attrs).with_layer(layer).write().to_file(path).map_err(|e| err(path, e))
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
