//! How samples and splats land in a tile's sums, over a band of output rows: the serial
//! `add_sample` / `add_splat` use one band that holds every row, and a full-frame iteration
//! (bdpt, vcm) fills bands of rows in parallel. Every pixel takes its contributions in the
//! order the serial calls would give them (camera samples row by row, then splats in sequence),
//! so the sums are bit for bit those of the serial order at any thread count: a farm render
//! still equals a local one.

use super::filter::{self, Filter};
use super::{Rect, TileAccum, add3};
use crate::math::Rgb;
use glam::Vec2;
use rayon::prelude::*;
use std::ops::Range;

/// Rows per band of a parallel fill: wide enough that the samples reaching a band from its
/// neighbours' rows (the filter's border on each side) cost little, narrow enough to spread
/// a small image over the threads.
const BAND_ROWS: u32 = 16;

/// Light-tracing splats per binning chunk.
const SPLAT_CHUNK: usize = 4096;

/// The sums of the output rows `y0..y1` of a tile (all its columns).
pub(super) struct RowsMut<'a> {
    pub(super) y0: u32,
    pub(super) y1: u32,
    bounds: Rect,
    sum: &'a mut [[f64; 3]],
    weight: Option<&'a mut [f64]>,
    splat: Option<&'a mut [[f64; 3]]>,
    count: &'a mut [u32],
    filter: &'a Filter,
    norm_x: &'a [f32],
    norm_y: &'a [f32],
}

impl RowsMut<'_> {
    /// Index of image pixel `(x, y)` (a row of this band) in the band's sums.
    #[inline]
    fn index(&self, x: u32, y: u32) -> usize {
        ((y - self.y0) * self.bounds.width() + (x - self.bounds.x0)) as usize
    }

    /// The rows of this band that a sample or splat reaching `rows` adds to.
    #[inline]
    fn clip(&self, rows: Range<u32>) -> Range<u32> {
        rows.start.max(self.bounds.y0).max(self.y0)..rows.end.min(self.y1)
    }

    /// Adds a finite camera sample generated in pixel `(x, y)` at raster position `raster`.
    #[inline]
    pub(super) fn sample(&mut self, x: u32, y: u32, raster: Vec2, v: Rgb) {
        let own = (self.y0..self.y1).contains(&y);
        if own {
            let i = self.index(x, y);
            self.count[i] += 1;
        }
        if self.weight.is_none() {
            if own {
                let i = self.index(x, y);
                add3(&mut self.sum[i], v);
            }
            return;
        }
        let (cols, rows) = self.filter.footprint(raster.x, raster.y, self.bounds.x1, self.bounds.y1);
        let rows = self.clip(rows);
        if rows.is_empty() {
            return;
        }
        let cols = cols.start.max(self.bounds.x0)..cols.end;
        let mut wx = [0.0f32; filter::MAX_TAPS];
        for (k, px) in cols.clone().enumerate() {
            wx[k] = self.filter.eval(px as f32 + 0.5 - raster.x);
        }
        let (bw, bx) = (self.bounds.width(), self.bounds.x0);
        let weight = self.weight.as_mut().expect("checked above");
        for py in rows {
            let wy = self.filter.eval(py as f32 + 0.5 - raster.y);
            let row = ((py - self.y0) * bw) as usize;
            for (k, px) in cols.clone().enumerate() {
                let w = wy * wx[k];
                let j = row + (px - bx) as usize;
                add3(&mut self.sum[j], v * w);
                weight[j] += w as f64;
            }
        }
    }

    /// Adds a finite light-tracing splat at `raster` (see [`TileAccum::add_splat`]).
    #[inline]
    pub(super) fn splat(&mut self, raster: Vec2, v: Rgb) {
        let Some(splat) = &mut self.splat else {
            // the box filter: splats share the camera sums
            let (x, y) = (raster.x as u32, raster.y as u32);
            let (x, y) = (x.min(self.bounds.x1 - 1), y.min(self.bounds.y1 - 1));
            if (self.y0..self.y1).contains(&y) {
                let i = self.index(x, y);
                add3(&mut self.sum[i], v);
            }
            return;
        };
        // splats are kept apart only in full-frame sums, so bounds start at (0, 0)
        let (cols, rows) = self.filter.footprint(raster.x, raster.y, self.bounds.x1, self.bounds.y1);
        let rows = rows.start.max(self.y0)..rows.end.min(self.y1);
        if rows.is_empty() {
            return;
        }
        let mut wx = [0.0f32; filter::MAX_TAPS];
        for (k, px) in cols.clone().enumerate() {
            wx[k] = self.filter.eval(px as f32 + 0.5 - raster.x) / self.norm_x[px as usize];
        }
        let bw = self.bounds.width();
        for py in rows {
            let wy = self.filter.eval(py as f32 + 0.5 - raster.y) / self.norm_y[py as usize];
            let row = ((py - self.y0) * bw) as usize;
            for (k, px) in cols.clone().enumerate() {
                add3(&mut splat[row + px as usize], v * (wy * wx[k]));
            }
        }
    }
}

/// The rows of a tile with `bounds` that a splat at `raster` adds to, its splats kept `apart`
/// through `filter` or sharing the camera sums.
#[inline]
fn splat_rows(filter: &Filter, bounds: Rect, apart: bool, raster: Vec2) -> Range<u32> {
    if apart {
        filter.footprint(raster.x, raster.y, bounds.x1, bounds.y1).1
    } else {
        let y = (raster.y as u32).min(bounds.y1 - 1);
        y..y + 1
    }
}

/// `value`, or zero when it is not finite (the caller counts it).
#[inline]
fn finite(value: Rgb) -> Rgb {
    if value.is_finite() { value } else { Rgb::ZERO }
}

/// One chunk of splats sorted by the bands they reach: `items[offsets[b]..offsets[b + 1]]` are
/// the chunk's indices of the splats reaching band `b`, in their order.
struct Binned {
    offsets: Vec<u32>,
    items: Vec<u32>,
    non_finite: u64,
}

impl TileAccum {
    /// The sums of all rows.
    pub(super) fn rows_mut(&mut self) -> RowsMut<'_> {
        RowsMut {
            y0: self.bounds.y0,
            y1: self.bounds.y1,
            bounds: self.bounds,
            sum: &mut self.sum,
            weight: self.weight.as_deref_mut(),
            splat: self.splat.as_deref_mut(),
            count: &mut self.count,
            filter: &self.filter,
            norm_x: &self.norm_x,
            norm_y: &self.norm_y,
        }
    }

    /// The sums cut into bands of `h` rows.
    fn bands_mut(&mut self, h: u32) -> Vec<RowsMut<'_>> {
        let (bounds, bw) = (self.bounds, self.bounds.width() as usize);
        let n = (h as usize) * bw;
        let mut weight = self.weight.as_deref_mut().map(|w| w.chunks_mut(n));
        let mut splat = self.splat.as_deref_mut().map(|s| s.chunks_mut(n));
        self.sum
            .chunks_mut(n)
            .zip(self.count.chunks_mut(n))
            .enumerate()
            .map(|(k, (sum, count))| {
                let y0 = bounds.y0 + k as u32 * h;
                RowsMut {
                    y0,
                    y1: (y0 + h).min(bounds.y1),
                    bounds,
                    sum,
                    weight: weight.as_mut().and_then(|w| w.next()),
                    splat: splat.as_mut().and_then(|s| s.next()),
                    count,
                    filter: &self.filter,
                    norm_x: &self.norm_x,
                    norm_y: &self.norm_y,
                }
            })
            .collect()
    }

    /// Adds one pass over `rect`: `rows[k][i]` is the camera sample (value, raster position)
    /// generated in pixel `(rect.x0 + i, rect.y0 + k)` (a stopped pass's rows may be short or
    /// empty), then `splats` in sequence (chunk by chunk). The sums equal those of
    /// `add_sample` over the rows in order and then `add_splat` over the splats, bit for bit,
    /// but bands of rows fill in parallel. Splats belong to full-frame sums only (their bounds
    /// start at (0, 0)), as with `add_splat`.
    pub fn add_frame(&mut self, rows: &[&[(Rgb, Vec2)]], splats: &[Vec<(Vec2, Rgb)>]) {
        let rect = self.rect;
        assert_eq!(rows.len(), (rect.y1 - rect.y0) as usize, "invariant: one row of samples per row of rect");
        assert!(rows.iter().all(|r| r.len() <= rect.width() as usize), "invariant: rows within rect");
        assert!(
            splats.iter().all(|s| s.is_empty()) || (self.bounds.x0, self.bounds.y0) == (0, 0),
            "invariant: splats go to full-frame sums"
        );
        if self.bounds.area() == 0 {
            self.non_finite += splats.iter().flatten().filter(|(_, v)| !v.is_finite()).count() as u64;
            return;
        }
        let h = BAND_ROWS.max(4 * self.filter.border());
        let y0 = self.bounds.y0;
        let bands = (self.bounds.y1 - y0).div_ceil(h) as usize;
        // a sample generated in row y reaches rows within the border of it; one row more
        // covers a raster on the pixel's far edge and the epsilon `border` leaves out
        let reach = self.filter.border() + 1;
        let binned = self.bin_splats(splats, h, bands);
        let non_finite: u64 = self
            .bands_mut(h)
            .into_par_iter()
            .enumerate()
            .map(|(b, mut band)| {
                let mut non_finite = 0;
                let first = band.y0.saturating_sub(reach).max(rect.y0);
                let last = (band.y1 + reach).min(rect.y1);
                for y in first..last {
                    for (i, &(value, raster)) in rows[(y - rect.y0) as usize].iter().enumerate() {
                        if !value.is_finite() && (band.y0..band.y1).contains(&y) {
                            non_finite += 1;
                        }
                        band.sample(rect.x0 + i as u32, y, raster, finite(value));
                    }
                }
                for (chunk, bins) in splats.iter().flat_map(|s| s.chunks(SPLAT_CHUNK)).zip(&binned) {
                    for &i in &bins.items[bins.offsets[b] as usize..bins.offsets[b + 1] as usize] {
                        let (raster, value) = chunk[i as usize];
                        band.splat(raster, finite(value));
                    }
                }
                non_finite
            })
            .sum();
        self.non_finite += non_finite + binned.iter().map(|b| b.non_finite).sum::<u64>();
    }

    /// Sorts each chunk of `splats` by the bands of `h` rows they reach (counting its
    /// non-finite ones), in parallel over chunks.
    fn bin_splats(&self, splats: &[Vec<(Vec2, Rgb)>], h: u32, bands: usize) -> Vec<Binned> {
        let (filter, bounds, apart) = (&self.filter, self.bounds, self.splat.is_some());
        let y0 = bounds.y0;
        let chunks: Vec<&[(Vec2, Rgb)]> = splats.iter().flat_map(|s| s.chunks(SPLAT_CHUNK)).collect();
        chunks
            .into_par_iter()
            .map(|chunk| {
                let band_range = |raster: Vec2| {
                    let rows = splat_rows(filter, bounds, apart, raster);
                    if rows.is_empty() {
                        0..0
                    } else {
                        ((rows.start - y0) / h) as usize..((rows.end - 1 - y0) / h) as usize + 1
                    }
                };
                let mut offsets = vec![0u32; bands + 1];
                let mut non_finite = 0;
                for &(raster, value) in chunk {
                    non_finite += !value.is_finite() as u64;
                    for b in band_range(raster) {
                        offsets[b + 1] += 1;
                    }
                }
                for b in 0..bands {
                    offsets[b + 1] += offsets[b];
                }
                let mut fill = offsets.clone();
                let mut items = vec![0u32; offsets[bands] as usize];
                for (i, &(raster, _)) in chunk.iter().enumerate() {
                    for b in band_range(raster) {
                        items[fill[b] as usize] = i as u32;
                        fill[b] += 1;
                    }
                }
                Binned { offsets, items, non_finite }
            })
            .collect()
    }
}
