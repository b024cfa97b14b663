//! Image filters of the optimiser (docs/emis.md §5.1), on single-channel row-major images:
//!
//! * box: 3×3 mean whose divisor at the border is the number of in-image taps; radius r means r
//!   successive passes;
//! * dilation: 3×3 maximum with out-of-image taps counting as −∞; radius r means r passes;
//! * quantile: a linear histogram with one bin per pixel over [min, max], returning the centre
//!   of the bin holding the requested quantile.
//!
//! The passes are computed as the definition says, one rounding per tap sum as in r single
//! passes, but in an order that keeps the data in cache: all row passes of a row while it sits
//! in L1, then all column passes of a strip of columns while it sits in L2
//! (docs/decisions/0021-optimiser-at-1080p.md). The optimiser's moment planes use the same
//! passes through [`PassScratch`] with hooks before and after, one plane per thread.

use super::quantile::{QuantileStream, histogram_keep};
use rayon::prelude::*;

/// A single-channel image.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width.
    pub width: usize,
    /// Height.
    pub height: usize,
    /// Pixels, row-major.
    pub data: Vec<f32>,
}

impl Image {
    /// An image filled with `value`.
    pub fn filled(width: usize, height: usize, value: f32) -> Self {
        Image { width, height, data: vec![value; width * height] }
    }

    /// From row-major data.
    pub fn from_data(width: usize, height: usize, data: Vec<f32>) -> Self {
        assert_eq!(data.len(), width * height, "invariant: data matches the size");
        Image { width, height, data }
    }

    /// The mean value (0 for an empty image).
    pub fn mean(&self) -> f64 {
        self.data.iter().map(|&v| v as f64).sum::<f64>() / self.data.len().max(1) as f64
    }

    /// One 3×3 box pass with border renormalisation (its divisor, the number of in-image taps,
    /// factorises into row taps × column taps, so a row pass and a column pass compute it).
    pub fn box3(&self) -> Image {
        self.box_blur(1)
    }

    /// One 3×3 max pass (out-of-image taps are −∞, i.e. ignored).
    pub fn dilate3(&self) -> Image {
        self.dilate(1)
    }

    /// `radius` successive box passes, computed as `radius` row passes then `radius` column
    /// passes (the row and column operators commute, so this equals `radius` applications of
    /// [`Image::box3`] up to float rounding).
    pub fn box_blur(&self, radius: usize) -> Image {
        self.repeated(radius, Pass::Mean)
    }

    /// `radius` successive dilation passes (exactly `radius` applications of
    /// [`Image::dilate3`]).
    pub fn dilate(&self, radius: usize) -> Image {
        if self.data.iter().all(|v| v.to_bits() == 0 || v.to_bits() == 1f32.to_bits()) {
            return self.dilate_binary(radius);
        }
        self.repeated(radius, Pass::Max)
    }

    /// [`Image::dilate`] of an image of +0 and 1 only: a pixel becomes 1 where a 1 lies within
    /// `radius` rows and columns of it, which is what `radius` max passes give, with a
    /// running count instead of a pass per radius.
    fn dilate_binary(&self, radius: usize) -> Image {
        let (w, h) = (self.width, self.height);
        if radius == 0 || w == 0 || h == 0 {
            return self.clone();
        }
        let mut rows = self.data.clone();
        rows.par_chunks_mut(w).for_each(|row| {
            let ones: Vec<u32> = std::iter::once(0)
                .chain(row.iter().scan(0u32, |n, &v| {
                    *n += (v == 1.0) as u32;
                    Some(*n)
                }))
                .collect();
            for (x, v) in row.iter_mut().enumerate() {
                let (a, b) = (x.saturating_sub(radius), (x + radius + 1).min(w));
                *v = if ones[b] > ones[a] { 1.0 } else { 0.0 };
            }
        });
        // per column, the count of ones in the rows above each row
        let mut above = vec![0u32; (h + 1) * w];
        for y in 0..h {
            let (done, next) = above.split_at_mut((y + 1) * w);
            for ((n, &prev), &v) in next[..w].iter_mut().zip(&done[y * w..]).zip(&rows[y * w..(y + 1) * w]) {
                *n = prev + (v == 1.0) as u32;
            }
        }
        let mut data = vec![0.0f32; w * h];
        data.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
            let (a, b) = (y.saturating_sub(radius), (y + radius + 1).min(h));
            for ((v, &top), &bottom) in out.iter_mut().zip(&above[a * w..]).zip(&above[b * w..(b + 1) * w]) {
                *v = if bottom > top { 1.0 } else { 0.0 };
            }
        });
        Image { width: w, height: h, data }
    }

    /// `radius` passes of `pass`: the rows in parallel, then strips of columns in parallel.
    fn repeated(&self, radius: usize, pass: Pass) -> Image {
        let (w, h) = (self.width, self.height);
        if radius == 0 || w == 0 || h == 0 {
            return self.clone();
        }
        let mut rows = self.data.clone();
        rows.par_chunks_mut(w).for_each_init(|| vec![0.0f32; w], |tmp, row| pass.rows_in_place(row, tmp, radius));
        let strips: Vec<Vec<f32>> = (0..w.div_ceil(STRIP))
            .into_par_iter()
            .map_init(PassScratch::default, |scratch, s| {
                let x0 = s * STRIP;
                scratch.columns(&rows, w, h, x0..(x0 + STRIP).min(w), radius, pass).to_vec()
            })
            .collect();
        let mut data = vec![0.0f32; w * h];
        data.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
            for (s, strip) in strips.iter().enumerate() {
                let x0 = s * STRIP;
                let sw = (x0 + STRIP).min(w) - x0;
                out[x0..x0 + sw].copy_from_slice(&strip[y * sw..(y + 1) * sw]);
            }
        });
        Image { width: w, height: h, data }
    }

    /// The `q` quantile (0..1) by a linear histogram with one bin per pixel over [min, max],
    /// returning the centre of the bin (the reference implementation's approximation).
    pub fn histogram_quantile(&self, q: f64) -> f32 {
        let mut stream = QuantileStream::new(histogram_keep(q, self.data.len()));
        for chunk in self.data.chunks(STRIP) {
            stream.push_slice(chunk);
        }
        stream.histogram_quantile(q).unwrap_or_else(|| histogram_quantile_by_counts(&self.data, q))
    }
}

/// [`Image::histogram_quantile`] by its definition: count every finite value into its bin.
/// What [`QuantileStream`] falls back on when it kept too few values to answer.
pub(crate) fn histogram_quantile_by_counts(data: &[f32], q: f64) -> f32 {
    let finite = || data.iter().copied().filter(|v| v.is_finite());
    let (lo, hi, n) = finite().fold((f32::MAX, f32::MIN, 0usize), |(a, b, n), v| (a.min(v), b.max(v), n + 1));
    if n == 0 {
        return 0.0;
    }
    if hi <= lo {
        return lo;
    }
    let bins = n;
    let width = (hi - lo) as f64 / bins as f64;
    let mut counts = vec![0u32; bins];
    for v in finite() {
        counts[(((v - lo) as f64 / width) as usize).min(bins - 1)] += 1;
    }
    let target = (q * n as f64).ceil().max(1.0) as u64;
    let mut acc = 0u64;
    for (i, &c) in counts.iter().enumerate() {
        acc += c as u64;
        if acc >= target {
            return (lo as f64 + (i as f64 + 0.5) * width) as f32;
        }
    }
    hi
}

/// Columns per strip of the column passes: a strip of a 1080-row image and its second buffer
/// (2 × 276 KB) stay in a core's L2.
pub(crate) const STRIP: usize = 64;

/// One thread's buffers for filter passes.
#[derive(Default)]
pub(crate) struct PassScratch {
    row: Vec<f32>,
    strip: [Vec<f32>; 2],
}

impl PassScratch {
    /// `radius` box passes over a `w`×`h` plane in place, with `before` applied to each row
    /// (`y`, the row) ahead of the row passes and `after` to each row segment (`y`, its first
    /// column, the segment) of the result before it is stored.
    pub(crate) fn box_blur_in_place(
        &mut self,
        data: &mut [f32],
        (w, h): (usize, usize),
        radius: usize,
        mut before: impl FnMut(usize, &mut [f32]),
        mut after: impl FnMut(usize, usize, &mut [f32]),
    ) {
        if w == 0 || h == 0 {
            return;
        }
        self.row.resize(w, 0.0);
        for (y, row) in data.chunks_exact_mut(w).enumerate() {
            before(y, row);
            Pass::Mean.rows_in_place(row, &mut self.row, radius);
        }
        for x0 in (0..w).step_by(STRIP) {
            let x1 = (x0 + STRIP).min(w);
            let sw = x1 - x0;
            let result = self.columns(data, w, h, x0..x1, radius, Pass::Mean);
            for (y, (seg, out)) in result.chunks_exact_mut(sw).zip(data.chunks_exact_mut(w)).enumerate() {
                after(y, x0, seg);
                out[x0..x1].copy_from_slice(seg);
            }
        }
    }

    /// `radius` passes down the columns `xs` of the `w`-wide `data` with `h` rows; the result,
    /// `h` rows of `xs.len()`, in one of the strip buffers.
    fn columns(
        &mut self,
        data: &[f32],
        w: usize,
        h: usize,
        xs: std::ops::Range<usize>,
        radius: usize,
        pass: Pass,
    ) -> &mut [f32] {
        let sw = xs.len();
        let [a, b] = &mut self.strip;
        a.resize(sw * h, 0.0);
        b.resize(sw * h, 0.0);
        for (dst, src) in a.chunks_exact_mut(sw).zip(data.chunks_exact(w)) {
            dst.copy_from_slice(&src[xs.clone()]);
        }
        for _ in 0..radius {
            pass.columns(a, b, sw);
            std::mem::swap(a, b);
        }
        a
    }
}

/// A 3-tap pass: the mean of the in-image taps, or their maximum.
#[derive(Clone, Copy)]
enum Pass {
    Mean,
    Max,
}

impl Pass {
    /// `radius` passes along `row` in place (`tmp`: a row of scratch).
    fn rows_in_place(self, row: &mut [f32], tmp: &mut [f32], radius: usize) {
        let tmp = &mut tmp[..row.len()];
        for _ in 0..radius / 2 {
            self.row(row, tmp);
            self.row(tmp, row);
        }
        if radius % 2 == 1 {
            self.row(row, tmp);
            row.copy_from_slice(tmp);
        }
    }

    /// One pass along a row.
    fn row(self, row: &[f32], out: &mut [f32]) {
        match self {
            Pass::Mean => row_pass(row, out, |a, b, c| (a + b + c) / 3.0, |a, b| (a + b) / 2.0),
            Pass::Max => row_pass(row, out, |a, b, c| a.max(b).max(c), |a, b| a.max(b)),
        }
    }

    /// One pass down the columns of `src` (rows of `sw`) into `dst`.
    fn columns(self, src: &[f32], dst: &mut [f32], sw: usize) {
        match self {
            Pass::Mean => column_pass(src, dst, sw, |a, b, c| (a + b + c) / 3.0, |a, b| (a + b) / 2.0),
            Pass::Max => column_pass(src, dst, sw, |a, b, c| a.max(b).max(c), |a, b| a.max(b)),
        }
    }
}

/// One pass along a row: `three(left, centre, right)` inside, `two` of the two taps at the
/// ends (slices zipped so that the loop has no bounds checks and compiles to vector code).
#[inline(always)]
fn row_pass(row: &[f32], out: &mut [f32], three: impl Fn(f32, f32, f32) -> f32, two: impl Fn(f32, f32) -> f32) {
    let w = row.len();
    if w == 1 {
        out[0] = row[0];
        return;
    }
    out[0] = two(row[0], row[1]);
    for (o, ((&l, &c), &r)) in out[1..w - 1].iter_mut().zip(row.iter().zip(&row[1..]).zip(&row[2..])) {
        *o = three(l, c, r);
    }
    out[w - 1] = two(row[w - 2], row[w - 1]);
}

/// One pass down the columns of a strip: `three(up, here, down)` inside, `two(neighbour,
/// here)` in the first and last rows.
#[inline(always)]
fn column_pass(
    src: &[f32],
    dst: &mut [f32],
    sw: usize,
    three: impl Fn(f32, f32, f32) -> f32,
    two: impl Fn(f32, f32) -> f32,
) {
    let h = src.len() / sw;
    if h == 1 {
        dst.copy_from_slice(src);
        return;
    }
    let edge = |o: &[f32], here: &[f32], out: &mut [f32]| {
        for ((d, &o), &c) in out.iter_mut().zip(o).zip(here) {
            *d = two(o, c);
        }
    };
    edge(&src[sw..2 * sw], &src[..sw], &mut dst[..sw]);
    for ((out, up), (here, down)) in dst[sw..(h - 1) * sw]
        .chunks_exact_mut(sw)
        .zip(src.chunks_exact(sw))
        .zip(src[sw..].chunks_exact(sw).zip(src[2 * sw..].chunks_exact(sw)))
    {
        for (((d, &u), &c), &n) in out.iter_mut().zip(up).zip(here).zip(down) {
            *d = three(u, c, n);
        }
    }
    edge(&src[(h - 2) * sw..(h - 1) * sw], &src[(h - 1) * sw..], &mut dst[(h - 1) * sw..]);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn single(w: usize, h: usize, x: usize, y: usize) -> Image {
        let mut img = Image::filled(w, h, 0.0);
        img.data[y * w + x] = 9.0;
        img
    }

    #[test]
    fn box_golden_values() {
        // a single 9 in the middle of 5x5 spreads to a 3x3 block of 1s
        let b = single(5, 5, 2, 2).box3();
        for y in 0..5 {
            for x in 0..5 {
                let expected = if (1..=3).contains(&x) && (1..=3).contains(&y) { 1.0 } else { 0.0 };
                assert!((b.data[y * 5 + x] - expected).abs() < 1e-6, "({x},{y})");
            }
        }
        // in a corner only 4 taps exist: the corner pixel becomes 9/4
        let c = single(5, 5, 0, 0).box3();
        assert!((c.data[0] - 9.0 / 4.0).abs() < 1e-6);
        // on an edge 6 taps exist
        let e = single(5, 5, 2, 0).box3();
        assert!((e.data[2] - 9.0 / 6.0).abs() < 1e-6);
        // a constant image is unchanged, border included
        let k = Image::filled(4, 3, 2.5).box_blur(3);
        assert!(k.data.iter().all(|&v| (v - 2.5).abs() < 1e-6));
    }

    #[test]
    fn dilation_golden_values() {
        let d = single(7, 7, 3, 3).dilate(2);
        for y in 0..7 {
            for x in 0..7 {
                let inside = (1..=5).contains(&x) && (1..=5).contains(&y);
                assert_eq!(d.data[y * 7 + x], if inside { 9.0 } else { 0.0 }, "({x},{y})");
            }
        }
        // the border does not leak in: a corner value dilates only inwards
        let c = single(4, 4, 0, 0).dilate3();
        assert_eq!(c.data.iter().filter(|&&v| v == 9.0).count(), 4);
    }

    #[test]
    fn repeated_passes_equal_single_applications() {
        let img = Image::from_data(6, 5, (0..30).map(|i| ((i * 7919) % 13) as f32).collect());
        let three = img.box3().box3().box3();
        for (a, b) in img.box_blur(3).data.iter().zip(&three.data) {
            assert!((a - b).abs() <= 1e-5 * b.abs().max(1.0), "{a} vs {b}");
        }
        assert_eq!(img.dilate(2), img.dilate3().dilate3());
    }

    /// The definition: `radius` row passes over the whole image, then `radius` column passes,
    /// one pass at a time.
    fn passes_one_by_one(img: &Image, radius: usize, pass: Pass) -> Image {
        let (w, h) = (img.width, img.height);
        let mut data = img.data.clone();
        for _ in 0..radius {
            for row in data.chunks_exact_mut(w) {
                let mut out = vec![0.0; w];
                pass.row(row, &mut out);
                row.copy_from_slice(&out);
            }
        }
        for _ in 0..radius {
            let prev = data.clone();
            for y in 0..h {
                for x in 0..w {
                    let at = |y: usize| prev[y * w + x];
                    let three = |a: f32, b: f32, c: f32| match pass {
                        Pass::Mean => (a + b + c) / 3.0,
                        Pass::Max => a.max(b).max(c),
                    };
                    let two = |a: f32, b: f32| match pass {
                        Pass::Mean => (a + b) / 2.0,
                        Pass::Max => a.max(b),
                    };
                    data[y * w + x] = match (y > 0, y + 1 < h) {
                        (true, true) => three(at(y - 1), at(y), at(y + 1)),
                        (true, false) => two(at(y - 1), at(y)),
                        (false, true) => two(at(y + 1), at(y)),
                        (false, false) => at(y),
                    };
                }
            }
        }
        Image::from_data(w, h, data)
    }

    /// Rows wider than a strip and not a multiple of it, single rows and columns, radii 0 to
    /// 9: the cache-ordered passes give the one-by-one passes' values bit for bit, and the
    /// binary dilation the max passes' values.
    #[test]
    fn cache_ordered_passes_equal_the_definition_bit_for_bit() {
        for (w, h) in [(1, 1), (1, 9), (9, 1), (2, 2), (STRIP + 13, 11), (3 * STRIP, 4), (37, 23)] {
            let mut s = crate::sampler::Sampler::for_pixel(7, (w * h) as u32, 0);
            let img = Image::from_data(w, h, (0..w * h).map(|_| (0.001 / s.next_1d().max(1e-6)).powi(2)).collect());
            let bits = Image::from_data(w, h, (0..w * h).map(|_| (s.next_1d() < 0.05) as u8 as f32).collect());
            for radius in [0, 1, 2, 3, 9] {
                let expected = passes_one_by_one(&img, radius, Pass::Mean);
                assert_eq!(img.box_blur(radius), expected, "box {w}×{h} r {radius}");
                let mut in_place = img.clone();
                PassScratch::default().box_blur_in_place(&mut in_place.data, (w, h), radius, |_, _| (), |_, _, _| ());
                assert_eq!(in_place, expected, "in place {w}×{h} r {radius}");
                assert_eq!(bits.dilate(radius), passes_one_by_one(&bits, radius, Pass::Max), "{w}×{h} r {radius}");
                assert_eq!(img.dilate(radius), passes_one_by_one(&img, radius, Pass::Max), "{w}×{h} r {radius}");
            }
        }
    }

    #[test]
    fn histogram_quantile_returns_bin_centres() {
        let img = Image::from_data(10, 10, (0..100).map(|i| i as f32).collect());
        // 100 bins of width 0.99 over [0, 99]: the 99.9 % quantile lies in the last bin
        let q = img.histogram_quantile(0.999);
        assert!((q - (99.0 - 0.495)).abs() < 1e-3, "{q}");
        let median = img.histogram_quantile(0.5);
        assert!((median - 49.5).abs() < 1.0, "{median}");
        assert_eq!(Image::filled(3, 3, 4.0).histogram_quantile(0.9), 4.0);
    }
}
