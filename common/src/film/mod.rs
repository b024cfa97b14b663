//! The film: per-pixel unnormalised sums, so that tiles and partial renders merge by addition
//! (on one machine or across a farm). A pixel holds Σ w·L of the camera samples that reach it
//! through the reconstruction filter ([`filter`]), Σ w, the number of camera samples generated
//! in it, and, apart, the light-tracing splats. With Mitsuba's box filter every sample lands in
//! its own pixel with weight 1, so Σ w is the count, splats share the camera sums, and a pixel
//! is the plain average of its samples; other filters reach `border` pixels beyond a tile's
//! rectangle, and a tile's sums cover that border too.

pub mod compare;
pub mod exr;
pub mod filter;
pub mod png;
mod rows;

use crate::math::Rgb;
use filter::Filter;
use glam::Vec2;
use std::sync::Arc;

/// A pixel rectangle `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Rect {
    /// Left column.
    pub x0: u32,
    /// Top row.
    pub y0: u32,
    /// One past the right column.
    pub x1: u32,
    /// One past the bottom row.
    pub y1: u32,
}

impl Rect {
    /// The whole `width × height` frame.
    pub fn full(width: u32, height: u32) -> Rect {
        Rect { x0: 0, y0: 0, x1: width, y1: height }
    }

    /// Number of pixels.
    pub fn area(&self) -> usize {
        ((self.x1 - self.x0) * (self.y1 - self.y0)) as usize
    }

    /// Whether `(x, y)` lies inside.
    #[inline]
    pub fn contains(&self, x: u32, y: u32) -> bool {
        x >= self.x0 && x < self.x1 && y >= self.y0 && y < self.y1
    }

    /// Width in pixels.
    #[inline]
    pub fn width(&self) -> u32 {
        self.x1 - self.x0
    }

    /// Splits a `width × height` image into tiles of at most `size × size`, row-major.
    pub fn tiles(width: u32, height: u32, size: u32) -> Vec<Rect> {
        let size = size.max(1);
        let mut out = Vec::new();
        for y0 in (0..height).step_by(size as usize) {
            for x0 in (0..width).step_by(size as usize) {
                out.push(Rect { x0, y0, x1: (x0 + size).min(width), y1: (y0 + size).min(height) });
            }
        }
        out
    }
}

/// The film's geometry and filter, shared by every tile of a render: the image size, the
/// reconstruction filter and its per-column and per-row integrals for splats.
#[derive(Clone, Debug, PartialEq)]
pub struct FilmSpec {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// The reconstruction filter.
    pub filter: Filter,
    norm_x: Arc<[f32]>,
    norm_y: Arc<[f32]>,
}

impl FilmSpec {
    /// A `width × height` film with `filter`.
    pub fn new(width: u32, height: u32, filter: Filter) -> Self {
        let (norm_x, norm_y) = if filter.is_box() {
            (Arc::from([]), Arc::from([]))
        } else {
            (filter.splat_norm(width).into(), filter.splat_norm(height).into())
        };
        FilmSpec { width, height, filter, norm_x, norm_y }
    }

    /// A film with the box filter.
    pub fn boxed(width: u32, height: u32) -> Self {
        Self::new(width, height, Filter::BOX)
    }

    /// The whole frame.
    pub fn full(&self) -> Rect {
        Rect::full(self.width, self.height)
    }

    /// The pixels that samples generated in `rect` reach: `rect` grown by the filter's border,
    /// clipped to the image.
    pub fn bounds(&self, rect: Rect) -> Rect {
        self.layout(rect).bounds
    }

    /// Which channels the sums of samples generated in `rect` carry.
    pub fn layout(&self, rect: Rect) -> Layout {
        Layout::of(rect, self.width, self.height, &self.filter)
    }
}

/// The channels a tile's (or a film's) sums carry, over which pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// The pixels the sums cover.
    pub bounds: Rect,
    /// Σ w per pixel is stored (any filter but the box, where it equals the count).
    pub weights: bool,
    /// Light-tracing splats are kept apart from the camera sums (full-frame tiles with a
    /// filter other than the box; with the box they share the camera sums).
    pub splats: bool,
}

impl Layout {
    /// The layout of the samples generated in `rect` of a `width × height` film with `filter`:
    /// `rect` grown by the filter's border and clipped to the image.
    pub fn of(rect: Rect, width: u32, height: u32, filter: &Filter) -> Layout {
        let b = filter.border();
        let bounds = Rect {
            x0: rect.x0.saturating_sub(b),
            y0: rect.y0.saturating_sub(b),
            x1: rect.x1.saturating_add(b).min(width),
            y1: rect.y1.saturating_add(b).min(height),
        };
        let weighted = !filter.is_box();
        Layout { bounds, weights: weighted, splats: weighted && rect == Rect::full(width, height) }
    }
}

/// What a tile render produces: sums over the samples generated in its rectangle, over the
/// pixels they reach.
#[derive(Clone, Debug, PartialEq)]
pub struct TileAccum {
    /// The pixels whose camera samples this tile generated.
    pub rect: Rect,
    /// The pixels the sums cover: `rect` and the filter's border (clipped to the image).
    pub bounds: Rect,
    /// Σ w·L per pixel of `bounds` (row-major); with the box filter also the splats.
    pub sum: Vec<[f64; 3]>,
    /// Σ w per pixel of `bounds`; `None` for the box filter (Σ w is the count).
    pub weight: Option<Vec<f64>>,
    /// Σ of the light-tracing splats per pixel of `bounds`, when kept apart (see [`Layout`]).
    pub splat: Option<Vec<[f64; 3]>>,
    /// Camera samples generated in each pixel of `bounds` (0 outside `rect`).
    pub count: Vec<u32>,
    /// Samples whose value was NaN or infinite (they were zeroed but still counted).
    pub non_finite: u64,
    filter: Filter,
    norm_x: Arc<[f32]>,
    norm_y: Arc<[f32]>,
}

/// Adds `v` to `s`.
#[inline]
fn add3(s: &mut [f64; 3], v: Rgb) {
    s[0] += v.x as f64;
    s[1] += v.y as f64;
    s[2] += v.z as f64;
}

impl TileAccum {
    /// Empty sums for the samples generated in `rect` of `film`.
    pub fn new(rect: Rect, film: &FilmSpec) -> Self {
        Self::with_layout(rect, film.layout(rect), film)
    }

    /// Empty sums with an explicit layout (a decoded result, or a test).
    pub fn with_layout(rect: Rect, layout: Layout, film: &FilmSpec) -> Self {
        let n = layout.bounds.area();
        TileAccum {
            rect,
            bounds: layout.bounds,
            sum: vec![[0.0; 3]; n],
            weight: layout.weights.then(|| vec![0.0; n]),
            splat: layout.splats.then(|| vec![[0.0; 3]; n]),
            count: vec![0; n],
            non_finite: 0,
            filter: film.filter,
            norm_x: film.norm_x.clone(),
            norm_y: film.norm_y.clone(),
        }
    }

    /// Sums decoded from elsewhere (a worker's upload): they merge, but take no new samples.
    #[allow(clippy::too_many_arguments)]
    pub fn from_channels(
        rect: Rect,
        bounds: Rect,
        sum: Vec<[f64; 3]>,
        weight: Option<Vec<f64>>,
        splat: Option<Vec<[f64; 3]>>,
        count: Vec<u32>,
        non_finite: u64,
    ) -> Self {
        TileAccum {
            rect,
            bounds,
            sum,
            weight,
            splat,
            count,
            non_finite,
            filter: Filter::BOX,
            norm_x: Arc::from([]),
            norm_y: Arc::from([]),
        }
    }

    /// The channels these sums carry.
    pub fn layout(&self) -> Layout {
        Layout { bounds: self.bounds, weights: self.weight.is_some(), splats: self.splat.is_some() }
    }

    /// Index of image pixel `(x, y)` in the sums.
    #[inline]
    fn index(&self, x: u32, y: u32) -> usize {
        ((y - self.bounds.y0) * self.bounds.width() + (x - self.bounds.x0)) as usize
    }

    /// `value`, or zero (counted) when it is not finite.
    #[inline]
    fn finite(&mut self, value: Rgb) -> Rgb {
        if value.is_finite() {
            value
        } else {
            self.non_finite += 1;
            Rgb::ZERO
        }
    }

    /// Adds a camera sample generated in pixel `(x, y)` (inside `rect`) at continuous raster
    /// position `raster`, through the filter.
    #[inline]
    pub fn add_sample(&mut self, x: u32, y: u32, raster: Vec2, value: Rgb) {
        let v = self.finite(value);
        self.rows_mut().sample(x, y, raster, v);
    }

    /// Adds a light-tracing splat at continuous raster position `raster`: through the filter,
    /// each pixel's share divided by the filter's integral for that pixel
    /// ([`filter::Filter::splat_norm`]); with the box filter, into the pixel it lands in.
    #[inline]
    pub fn add_splat(&mut self, raster: Vec2, value: Rgb) {
        let v = self.finite(value);
        self.rows_mut().splat(raster, v);
    }

    /// Counts `n` more samples (iterations) in every pixel of `rect`: light tracing, whose
    /// splats are each iteration's estimate of every pixel.
    pub fn count_iterations(&mut self, n: u32) {
        let r = self.rect;
        for y in r.y0..r.y1 {
            for x in r.x0..r.x1 {
                let i = self.index(x, y);
                self.count[i] += n;
            }
        }
    }

    /// Adds `other`'s sums (same channels; its bounds inside these).
    pub fn add(&mut self, other: &TileAccum) {
        let b = other.bounds;
        for y in b.y0..b.y1 {
            for x in b.x0..b.x1 {
                let (i, j) = (self.index(x, y), other.index(x, y));
                add_pixel(
                    (&mut self.sum[i], self.weight.as_mut().map(|w| &mut w[i]), self.splat.as_mut().map(|s| &mut s[i])),
                    &mut self.count[i],
                    other,
                    j,
                );
            }
        }
        self.non_finite += other.non_finite;
    }
}

/// Adds pixel `j` of `tile` to one pixel's channels.
#[inline]
fn add_pixel(
    (sum, weight, splat): (&mut [f64; 3], Option<&mut f64>, Option<&mut [f64; 3]>),
    count: &mut u32,
    tile: &TileAccum,
    j: usize,
) {
    for c in 0..3 {
        sum[c] += tile.sum[j][c];
    }
    if let (Some(w), Some(tw)) = (weight, &tile.weight) {
        *w += tw[j];
    }
    if let (Some(s), Some(ts)) = (splat, &tile.splat) {
        for c in 0..3 {
            s[c] += ts[j][c];
        }
    }
    *count += tile.count[j];
}

/// A whole image of sums.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Σ w·L per pixel, row-major, row 0 at the top (with the box filter, splats too).
    pub sum: Vec<[f64; 3]>,
    /// Σ w per pixel; `None` for the box filter, where it is the count.
    pub weight: Option<Vec<f64>>,
    /// Light-tracing splats kept apart (filters other than the box), once a tile brought some.
    pub splat: Option<Vec<[f64; 3]>>,
    /// Camera samples generated in each pixel.
    pub count: Vec<u32>,
    /// Non-finite samples seen.
    pub non_finite: u64,
}

impl Film {
    /// An empty film of `spec`.
    pub fn new(spec: &FilmSpec) -> Self {
        Self::for_filter(spec.width, spec.height, &spec.filter)
    }

    /// An empty `width × height` film for samples through `filter`.
    pub fn for_filter(width: u32, height: u32, filter: &Filter) -> Self {
        let n = width as usize * height as usize;
        Film {
            width,
            height,
            sum: vec![[0.0; 3]; n],
            weight: (!filter.is_box()).then(|| vec![0.0; n]),
            splat: None,
            count: vec![0; n],
            non_finite: 0,
        }
    }

    /// Adds a tile's sums.
    pub fn merge_tile(&mut self, tile: &TileAccum) {
        if tile.splat.is_some() && self.splat.is_none() {
            self.splat = Some(vec![[0.0; 3]; self.sum.len()]);
        }
        let b = tile.bounds;
        for y in b.y0..b.y1 {
            for x in b.x0..b.x1 {
                let i = (y * self.width + x) as usize;
                let j = tile.index(x, y);
                add_pixel(
                    (&mut self.sum[i], self.weight.as_mut().map(|w| &mut w[i]), self.splat.as_mut().map(|s| &mut s[i])),
                    &mut self.count[i],
                    tile,
                    j,
                );
            }
        }
        self.non_finite += tile.non_finite;
    }

    /// The image: per pixel Σ w·L / Σ w (zero where no weight landed) plus the splats over the
    /// pixel's iteration count, as f32 RGB.
    pub fn average(&self) -> Vec<[f32; 3]> {
        (0..self.sum.len())
            .map(|i| {
                let s = self.sum[i];
                let n = self.count[i];
                let w = self.weight.as_ref().map_or(n as f64, |w| w[i]);
                let inv = if w == 0.0 { 0.0 } else { 1.0 / w };
                let mut v = [s[0] * inv, s[1] * inv, s[2] * inv];
                if let (Some(splat), true) = (&self.splat, n > 0) {
                    for c in 0..3 {
                        v[c] += splat[i][c] / n as f64;
                    }
                }
                v.map(|c| c as f32)
            })
            .collect()
    }

    /// Total samples.
    pub fn total_samples(&self) -> u64 {
        self.count.iter().map(|&c| c as u64).sum()
    }
}

#[cfg(test)]
mod tests;
