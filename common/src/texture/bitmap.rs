//! Mitsuba's `bitmap` texture: an image file looked up at a surface's uv, with Mitsuba 3.9.1's
//! exact conventions (`src/textures/bitmap.cpp`, Dr.Jit's texture lookup):
//!
//! * uv' = `to_uv`·uv; texel (i, j) is centred at ((i+½)/W, (j+½)/H); **row 0 is the top row of
//!   the file, so v = 0 is the image top** (no flip).
//! * `bilinear` (default) blends the four texels around uv'·(W,H) − ½ with weights p − ⌊p⌋;
//!   `nearest` takes texel ⌊uv'·(W,H)⌋. `wrap_mode` `repeat` (default), `mirror` or `clamp`
//!   decides which texel an index outside the image stands for.
//! * 8-bit images keep their bytes; sRGB files are decoded texel by texel **before** blending.
//!   16-bit images are decoded to linear half floats at load; float images are used as they are.
//!   `raw` turns sRGB decoding off.
//! * Single-channel images are scalar textures (the value in all three channels); alpha is
//!   dropped, not premultiplied; images smaller than 2×2 are padded by repeating the last
//!   column and row.
//!
//! ```no_run
//! use tessera_common::texture::{Bitmap, BitmapOptions, TextureLimits, WrapMode};
//! let options = BitmapOptions { wrap: WrapMode::Clamp, ..Default::default() };
//! let tex = Bitmap::load("wood.png".as_ref(), options, &TextureLimits::default()).unwrap();
//! let colour = tex.eval(glam::Vec2::new(0.25, 0.75));
//! ```

use super::decode::{self, Samples};
use super::{TextureError, TextureLimits, UvTransform};
use crate::math::Rgb;
use glam::Vec2;
use half::f16;
use std::path::Path;
use std::sync::LazyLock;

/// How texels are interpolated (`filter_type`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FilterType {
    /// Blend the four nearest texel centres (Mitsuba's default).
    #[default]
    Bilinear,
    /// The texel containing the point.
    Nearest,
}

/// What a texel index outside the image stands for (`wrap_mode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum WrapMode {
    /// Periodic: u = 0 blends the last and first columns equally (Mitsuba's default).
    #[default]
    Repeat,
    /// Reflected at each edge, the edge texel repeated once.
    Mirror,
    /// The nearest edge texel.
    Clamp,
}

/// The parameters of a `bitmap` besides its file.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BitmapOptions {
    /// `raw`: use the stored values as they are, without sRGB decoding.
    pub raw: bool,
    /// `filter_type`.
    pub filter: FilterType,
    /// `wrap_mode`.
    pub wrap: WrapMode,
    /// `to_uv`.
    pub to_uv: UvTransform,
}

/// How a bitmap keeps its texels, as Mitsuba's `format="auto"` does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Storage {
    /// One byte per sample, decoded through the sRGB curve at lookup.
    U8Srgb,
    /// One byte per sample, value/255 at lookup (linear files or `raw`).
    U8Linear,
    /// Half floats, linear: 16-bit files and half-float EXRs.
    F16,
    /// Floats, linear: float EXRs, Radiance HDR, PFM, in-memory data.
    F32,
}

/// Texel arrays, interleaved channels, row 0 at the top. Each source keeps its precision, as in
/// Mitsuba: bytes stay bytes (sRGB decoding per texel needs the byte), 16-bit sources become
/// half floats (the precision Mitsuba stores, so lookups round the same way, at half the
/// memory of f32), and float sources stay f32 (a half EXR stays half). Evidence in
/// `docs/decisions/0012-bitmap-storage-and-decoders.md`.
#[derive(Clone)]
enum Texels {
    U8 { data: Box<[u8]>, srgb: bool },
    F16(Box<[f16]>),
    F32(Box<[f32]>),
}

/// The sRGB decoding of each byte value, evaluated in f64 (Dr.Jit uses a rational fit that
/// agrees to 4e-7).
static SRGB_TO_LINEAR: LazyLock<[f32; 256]> =
    LazyLock::new(|| std::array::from_fn(|i| srgb_to_linear(i as f64 / 255.0) as f32));

fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 { v / 12.92 } else { ((v + 0.055) / 1.055).powf(2.4) }
}

/// Mitsuba's `luminance` (Rec. 709 Y of linear sRGB), in its evaluation order.
#[inline]
pub(crate) fn luminance(c: Rgb) -> f32 {
    c.x * 0.212671 + (c.y * 0.715160 + c.z * 0.072169)
}

/// An image texture. Built once at scene load; lookups read only.
#[derive(Clone)]
pub struct Bitmap {
    width: u32,
    height: u32,
    channels: usize,
    texels: Texels,
    options: BitmapOptions,
    mean: f32,
    mean_rgb: Rgb,
}

impl std::fmt::Debug for Bitmap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bitmap")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("channels", &self.channels)
            .field("storage", &self.storage())
            .field("options", &self.options)
            .field("mean", &self.mean)
            .finish()
    }
}

impl Bitmap {
    /// Loads an image file (PNG 8/16-bit, JPEG, OpenEXR, Radiance HDR, BMP, TGA, PFM, PPM).
    /// The image's size is read from its header first and a file whose decoded pixels would
    /// exceed `limits.max_decoded_bytes` is refused before decoding.
    pub fn load(path: &Path, options: BitmapOptions, limits: &TextureLimits) -> Result<Bitmap, TextureError> {
        // the reservation holds the decode's memory until the texels are made
        let (image, _reservation) = decode::read(path, limits)?;
        let decode_srgb = image.srgb && !options.raw;
        let texels = match image.samples {
            Samples::U8(data) => Texels::U8 { data: data.into(), srgb: decode_srgb },
            Samples::U16(data) => Texels::F16(
                data.into_iter()
                    .map(|v| {
                        let x = v as f32 / 65535.0;
                        if decode_srgb { f16::from_f64(srgb_to_linear(x as f64)) } else { f16::from_f32(x) }
                    })
                    .collect(),
            ),
            Samples::F16(data) => Texels::F16(data.into()),
            Samples::F32(data) => Texels::F32(data.into()),
        };
        Ok(Bitmap::build(image.width, image.height, image.channels, texels, options))
    }

    /// A bitmap from linear float data (Mitsuba's `data` tensor): `width`×`height` pixels of
    /// `channels` (1 or 3) interleaved values, row 0 at the top. `options.raw` has no effect.
    pub fn from_linear(
        width: u32,
        height: u32,
        channels: usize,
        data: Vec<f32>,
        options: BitmapOptions,
    ) -> Result<Bitmap, TextureError> {
        let expected = width as usize * height as usize * channels;
        if !(channels == 1 || channels == 3) || data.len() != expected || expected == 0 {
            return Err(TextureError::DataSize { len: data.len(), expected, width, height, channels });
        }
        Ok(Bitmap::build(width, height, channels, Texels::F32(data.into()), options))
    }

    fn build(width: u32, height: u32, channels: usize, texels: Texels, options: BitmapOptions) -> Bitmap {
        // Mitsuba pads anything smaller than 2×2 so that bilinear lookups have a cell
        let (w2, h2) = (width.max(2), height.max(2));
        let texels = match texels {
            Texels::U8 { data, srgb } => Texels::U8 { data: pad(data, width, height, channels), srgb },
            Texels::F16(data) => Texels::F16(pad(data, width, height, channels)),
            Texels::F32(data) => Texels::F32(pad(data, width, height, channels)),
        };
        let mut bitmap = Bitmap { width: w2, height: h2, channels, texels, options, mean: 0.0, mean_rgb: Rgb::ZERO };
        bitmap.compute_means();
        bitmap
    }

    fn compute_means(&mut self) {
        let count = self.width as usize * self.height as usize;
        let (mut sum, mut sum_y) = ([0f64; 3], 0f64);
        for i in 0..count {
            let c = self.texel(i);
            sum[0] += c.x as f64;
            sum[1] += c.y as f64;
            sum[2] += c.z as f64;
            sum_y += if self.channels == 1 { c.x as f64 } else { luminance(c) as f64 };
        }
        let n = count.max(1) as f64;
        self.mean_rgb = Rgb::new((sum[0] / n) as f32, (sum[1] / n) as f32, (sum[2] / n) as f32);
        self.mean = (sum_y / n) as f32;
    }

    /// The decoded colour of texel `index` (row-major), for means.
    fn texel(&self, index: usize) -> Rgb {
        let base = index * self.channels;
        let get = |k: usize| match &self.texels {
            Texels::U8 { data, srgb: true } => SRGB_TO_LINEAR[data[base + k] as usize],
            Texels::U8 { data, srgb: false } => data[base + k] as f32 * (1.0 / 255.0),
            Texels::F16(data) => data[base + k].to_f32(),
            Texels::F32(data) => data[base + k],
        };
        if self.channels == 1 { Rgb::splat(get(0)) } else { Rgb::new(get(0), get(1), get(2)) }
    }

    /// Every texel's decoded linear colour, row-major from the top (environment maps read
    /// them all once).
    pub fn linear_rgb(&self) -> Vec<Rgb> {
        (0..self.width as usize * self.height as usize).map(|i| self.texel(i)).collect()
    }

    /// The colour at `uv` (a single-channel image gives its value in all three channels).
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Rgb {
        if self.channels == 1 { Rgb::splat(self.lookup::<1>(uv)[0]) } else { Rgb::from_array(self.lookup::<3>(uv)) }
    }

    /// The scalar value at `uv`: the value of a single-channel image, else the luminance
    /// 0.212671 R + 0.715160 G + 0.072169 B, as Mitsuba's `eval_1`.
    #[inline]
    pub fn eval_1(&self, uv: Vec2) -> f32 {
        if self.channels == 1 { self.lookup::<1>(uv)[0] } else { luminance(Rgb::from_array(self.lookup::<3>(uv))) }
    }

    /// Mitsuba's `mean()`: the average over texels of the value (one channel) or luminance.
    pub fn mean(&self) -> f32 {
        self.mean
    }

    /// The average colour over texels.
    pub fn mean_rgb(&self) -> Rgb {
        self.mean_rgb
    }

    /// Width in texels (after padding to at least 2).
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in texels (after padding to at least 2).
    pub fn height(&self) -> u32 {
        self.height
    }

    /// 1 (scalar image) or 3 (RGB).
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// How the texels are stored.
    pub fn storage(&self) -> Storage {
        match &self.texels {
            Texels::U8 { srgb: true, .. } => Storage::U8Srgb,
            Texels::U8 { srgb: false, .. } => Storage::U8Linear,
            Texels::F16(_) => Storage::F16,
            Texels::F32(_) => Storage::F32,
        }
    }

    /// The options it was built with.
    pub fn options(&self) -> &BitmapOptions {
        &self.options
    }

    /// Bytes of texel data held.
    pub fn decoded_bytes(&self) -> usize {
        match &self.texels {
            Texels::U8 { data, .. } => data.len(),
            Texels::F16(data) => data.len() * 2,
            Texels::F32(data) => data.len() * 4,
        }
    }

    /// The `C` channels at `uv`, decoded and filtered.
    #[inline]
    fn lookup<const C: usize>(&self, uv: Vec2) -> [f32; C] {
        let uv = if self.options.to_uv.is_identity() { uv } else { self.options.to_uv.apply(uv) };
        match &self.texels {
            Texels::U8 { data, srgb: true } => {
                let lut: &[f32; 256] = &SRGB_TO_LINEAR;
                self.filter::<C>(uv, |i| lut[data[i] as usize])
            }
            Texels::U8 { data, srgb: false } => self.filter::<C>(uv, |i| data[i] as f32 * (1.0 / 255.0)),
            Texels::F16(data) => self.filter::<C>(uv, |i| data[i].to_f32()),
            Texels::F32(data) => self.filter::<C>(uv, |i| data[i]),
        }
    }

    /// Nearest or bilinear filtering with `fetch(sample index)` giving linear values. The
    /// wrapped indices always lie inside the image, so `fetch` never reads out of bounds.
    #[inline]
    fn filter<const C: usize>(&self, uv: Vec2, fetch: impl Fn(usize) -> f32) -> [f32; C] {
        let (w, h) = (self.width as i64, self.height as i64);
        let wrap = self.options.wrap;
        let base = |x: i64, y: i64| (y * w + x) as usize * C;
        match self.options.filter {
            FilterType::Nearest => {
                let x = wrap_index((uv.x * w as f32).floor() as i64, w, wrap);
                let y = wrap_index((uv.y * h as f32).floor() as i64, h, wrap);
                let b = base(x, y);
                std::array::from_fn(|c| fetch(b + c))
            }
            FilterType::Bilinear => {
                let px = uv.x * w as f32 - 0.5;
                let py = uv.y * h as f32 - 0.5;
                let (fx, fy) = (px.floor(), py.floor());
                let (x0, y0) = (fx as i64, fy as i64);
                let xs = [wrap_index(x0, w, wrap), wrap_index(x0.saturating_add(1), w, wrap)];
                let ys = [wrap_index(y0, h, wrap), wrap_index(y0.saturating_add(1), h, wrap)];
                let (wx1, wy1) = (px - fx, py - fy);
                let wx = [1.0 - wx1, wx1];
                let wy = [1.0 - wy1, wy1];
                let mut out = [0.0f32; C];
                // Dr.Jit's corner order (x fastest) and weight products, so sums round alike
                for corner in 0..4 {
                    let (dx, dy) = (corner & 1, corner >> 1);
                    let weight = wx[dx] * wy[dy];
                    let b = base(xs[dx], ys[dy]);
                    for (c, o) in out.iter_mut().enumerate() {
                        *o += fetch(b + c) * weight;
                    }
                }
                out
            }
        }
    }
}

/// Maps a texel index onto 0..n−1.
#[inline]
fn wrap_index(i: i64, n: i64, mode: WrapMode) -> i64 {
    if (0..n).contains(&i) {
        // most lookups: no division
        return i;
    }
    match mode {
        WrapMode::Clamp => i.clamp(0, n - 1),
        WrapMode::Repeat => i.rem_euclid(n),
        WrapMode::Mirror => {
            // even periods run forward, odd ones backward: n−1, 0 | 0, n−1 | n−1, 0 ...
            let m = i.rem_euclid(n);
            if i.div_euclid(n) % 2 == 0 { m } else { n - 1 - m }
        }
    }
}

/// Extends an image to at least 2×2 by repeating its last column, then its last row.
fn pad<T: Copy>(data: Box<[T]>, width: u32, height: u32, channels: usize) -> Box<[T]> {
    if width >= 2 && height >= 2 {
        return data;
    }
    let (w, h) = (width as usize, height as usize);
    let (w2, h2) = (w.max(2), h.max(2));
    let mut out = Vec::with_capacity(w2 * h2 * channels);
    for y in 0..h2 {
        let row = &data[y.min(h - 1) * w * channels..][..w * channels];
        out.extend_from_slice(row);
        for _ in w..w2 {
            out.extend_from_slice(&row[(w - 1) * channels..]);
        }
    }
    out.into()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_index_mirror_reflects_with_edge_repeated() {
        let got: Vec<i64> = (-6..10).map(|i| wrap_index(i, 4, WrapMode::Mirror)).collect();
        assert_eq!(got, [2, 3, 3, 2, 1, 0, 0, 1, 2, 3, 3, 2, 1, 0, 0, 1]);
    }

    #[test]
    fn wrap_index_repeat_and_clamp() {
        let repeat: Vec<i64> = (-5..6).map(|i| wrap_index(i, 4, WrapMode::Repeat)).collect();
        assert_eq!(repeat, [3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1]);
        assert_eq!(wrap_index(-7, 4, WrapMode::Clamp), 0);
        assert_eq!(wrap_index(9, 4, WrapMode::Clamp), 3);
        assert!((0..3).contains(&wrap_index(i64::MAX, 3, WrapMode::Mirror)));
    }

    #[test]
    fn pad_repeats_last_column_and_row() {
        let one_row: Box<[u8]> = vec![1, 2, 3].into();
        assert_eq!(&*pad(one_row, 3, 1, 1), &[1, 2, 3, 1, 2, 3]);
        let one_px: Box<[u8]> = vec![7, 8, 9].into();
        assert_eq!(&*pad(one_px, 1, 1, 3), &[7, 8, 9, 7, 8, 9, 7, 8, 9, 7, 8, 9]);
    }

    #[test]
    fn bitmap_texel_centres_and_top_row() {
        // 2×2 grey image: row 0 (top) = 0, 1; row 1 = 2, 3
        let opts = BitmapOptions { filter: FilterType::Nearest, ..Default::default() };
        let b = Bitmap::from_linear(2, 2, 1, vec![0.0, 1.0, 2.0, 3.0], opts).unwrap();
        assert_eq!(b.eval_1(Vec2::new(0.25, 0.25)), 0.0);
        assert_eq!(b.eval_1(Vec2::new(0.75, 0.25)), 1.0);
        assert_eq!(b.eval_1(Vec2::new(0.25, 0.75)), 2.0);
        let bilinear = Bitmap::from_linear(2, 2, 1, vec![0.0, 1.0, 2.0, 3.0], BitmapOptions::default()).unwrap();
        // texel centres are exact, u = 0 blends the two columns 50/50 under repeat
        assert_eq!(bilinear.eval_1(Vec2::new(0.75, 0.75)), 3.0);
        assert_eq!(bilinear.eval_1(Vec2::new(0.0, 0.25)), 0.5);
        assert_eq!(bilinear.mean(), 1.5);
        assert_eq!(bilinear.eval(Vec2::new(0.25, 0.75)), Rgb::splat(2.0));
    }

    #[test]
    fn bitmap_non_finite_uv_does_not_panic() {
        let b = Bitmap::from_linear(2, 2, 3, vec![0.5; 12], BitmapOptions::default()).unwrap();
        for uv in [Vec2::NAN, Vec2::INFINITY, Vec2::NEG_INFINITY, Vec2::new(3e9, -3e9)] {
            for wrap in [WrapMode::Repeat, WrapMode::Mirror, WrapMode::Clamp] {
                for filter in [FilterType::Bilinear, FilterType::Nearest] {
                    let opts = BitmapOptions { wrap, filter, ..Default::default() };
                    let b = Bitmap { options: opts, ..b.clone() };
                    let _ = b.eval(uv);
                }
            }
        }
    }

    #[test]
    fn bitmap_from_linear_rejects_bad_sizes() {
        assert!(Bitmap::from_linear(2, 2, 3, vec![0.0; 11], BitmapOptions::default()).is_err());
        assert!(Bitmap::from_linear(2, 2, 2, vec![0.0; 8], BitmapOptions::default()).is_err());
        assert!(Bitmap::from_linear(0, 2, 1, vec![], BitmapOptions::default()).is_err());
    }

    #[test]
    fn srgb_table_matches_mitsuba_samples() {
        // Mitsuba 3.9.1: byte 128 → 0.21586, 255 → 1
        assert!((SRGB_TO_LINEAR[128] - 0.21586).abs() < 1e-5);
        assert_eq!(SRGB_TO_LINEAR[255], 1.0);
        assert_eq!(SRGB_TO_LINEAR[0], 0.0);
    }
}
