//! The film: per-pixel unnormalised sums of sample values and sample counts, so that tiles and
//! partial renders merge by addition (on one machine or across a farm). With Mitsuba's box
//! filter every sample lands in the pixel it was generated in, so a pixel is the plain average
//! of its samples.

pub mod compare;
pub mod exr;
pub mod png;

use crate::math::Rgb;

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

/// What a tile render produces: sums over its samples, per pixel of its rectangle.
#[derive(Clone, Debug, PartialEq)]
pub struct TileAccum {
    /// The rectangle.
    pub rect: Rect,
    /// Σ sample values per pixel (row-major within `rect`).
    pub sum: Vec<[f64; 3]>,
    /// Number of samples per pixel.
    pub count: Vec<u32>,
    /// Samples whose value was NaN or infinite (they were zeroed but still counted).
    pub non_finite: u64,
}

impl TileAccum {
    /// An empty accumulator for `rect`.
    pub fn new(rect: Rect) -> Self {
        let n = rect.area();
        TileAccum { rect, sum: vec![[0.0; 3]; n], count: vec![0; n], non_finite: 0 }
    }

    /// Adds one sample to pixel `local` (row-major index within the rectangle).
    #[inline]
    pub fn add(&mut self, local: usize, value: Rgb) {
        self.accumulate(local, value);
        self.count[local] += 1;
    }

    /// Adds `value` to the sums of pixel `local`, zeroing (and counting) non-finite values.
    #[inline]
    fn accumulate(&mut self, local: usize, value: Rgb) {
        let v = if value.is_finite() {
            value
        } else {
            self.non_finite += 1;
            Rgb::ZERO
        };
        let s = &mut self.sum[local];
        s[0] += v.x as f64;
        s[1] += v.y as f64;
        s[2] += v.z as f64;
    }
}

impl TileAccum {
    /// Adds a light-tracing splat to pixel `local` without counting a sample: splats are part
    /// of the iteration's estimate of every pixel, counted once per iteration by
    /// [`TileAccum::count_iterations`].
    #[inline]
    pub fn add_splat(&mut self, local: usize, value: Rgb) {
        self.accumulate(local, value);
    }

    /// Counts `n` more samples (iterations) in every pixel.
    pub fn count_iterations(&mut self, n: u32) {
        for c in &mut self.count {
            *c += n;
        }
    }
}

/// A whole image of sums and counts.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Σ sample values per pixel, row-major, row 0 at the top.
    pub sum: Vec<[f64; 3]>,
    /// Samples per pixel.
    pub count: Vec<u32>,
    /// Non-finite samples seen.
    pub non_finite: u64,
}

impl Film {
    /// An empty film.
    pub fn new(width: u32, height: u32) -> Self {
        let n = (width * height) as usize;
        Film { width, height, sum: vec![[0.0; 3]; n], count: vec![0; n], non_finite: 0 }
    }

    /// Adds a tile's sums.
    pub fn merge_tile(&mut self, tile: &TileAccum) {
        let r = tile.rect;
        let w = r.x1 - r.x0;
        for y in r.y0..r.y1 {
            for x in r.x0..r.x1 {
                let local = ((y - r.y0) * w + (x - r.x0)) as usize;
                let global = (y * self.width + x) as usize;
                for c in 0..3 {
                    self.sum[global][c] += tile.sum[local][c];
                }
                self.count[global] += tile.count[local];
            }
        }
        self.non_finite += tile.non_finite;
    }

    /// The image: per-pixel averages as f32 RGB (zero where no sample landed).
    pub fn average(&self) -> Vec<[f32; 3]> {
        self.sum
            .iter()
            .zip(&self.count)
            .map(|(s, &n)| {
                if n == 0 {
                    [0.0; 3]
                } else {
                    let inv = 1.0 / n as f64;
                    [(s[0] * inv) as f32, (s[1] * inv) as f32, (s[2] * inv) as f32]
                }
            })
            .collect()
    }

    /// Total samples.
    pub fn total_samples(&self) -> u64 {
        self.count.iter().map(|&c| c as u64).sum()
    }
}
