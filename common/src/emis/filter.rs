//! Image filters of the optimiser (docs/emis.md §5.1), on single-channel row-major images:
//!
//! * box: 3×3 mean whose divisor at the border is the number of in-image taps; radius r means r
//!   successive passes;
//! * dilation: 3×3 maximum with out-of-image taps counting as −∞; radius r means r passes;
//! * quantile: a linear histogram with one bin per pixel over [min, max], returning the centre
//!   of the bin holding the requested quantile.

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
        self.repeated(radius, Pass::Max)
    }

    fn repeated(&self, radius: usize, pass: Pass) -> Image {
        use rayon::prelude::*;
        let (w, h) = (self.width, self.height);
        if radius == 0 || w == 0 || h == 0 {
            return self.clone();
        }
        let mut data = self.data.clone();
        data.par_chunks_mut(w).for_each(|row| {
            let mut tmp = vec![0.0f32; w];
            for _ in 0..radius {
                pass.row(row, &mut tmp);
                row.copy_from_slice(&tmp);
            }
        });
        let mut next = vec![0.0f32; w * h];
        for _ in 0..radius {
            next.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
                let here = &data[y * w..(y + 1) * w];
                let up = y.checked_sub(1).map(|u| &data[u * w..(u + 1) * w]);
                let down = (y + 1 < h).then(|| &data[(y + 1) * w..(y + 2) * w]);
                pass.rows(up, here, down, out);
            });
            std::mem::swap(&mut data, &mut next);
        }
        Image { width: w, height: h, data }
    }

    /// The `q` quantile (0..1) by a linear histogram with one bin per pixel over [min, max],
    /// returning the centre of the bin (the reference implementation's approximation).
    pub fn histogram_quantile(&self, q: f64) -> f32 {
        let finite = || self.data.iter().copied().filter(|v| v.is_finite());
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
}

/// A 3-tap pass: the mean of the in-image taps, or their maximum.
#[derive(Clone, Copy)]
enum Pass {
    Mean,
    Max,
}

impl Pass {
    #[inline]
    fn three(self, a: f32, b: f32, c: f32) -> f32 {
        match self {
            Pass::Mean => (a + b + c) / 3.0,
            Pass::Max => a.max(b).max(c),
        }
    }

    #[inline]
    fn two(self, a: f32, b: f32) -> f32 {
        match self {
            Pass::Mean => (a + b) / 2.0,
            Pass::Max => a.max(b),
        }
    }

    /// One pass along a row.
    fn row(self, row: &[f32], out: &mut [f32]) {
        let w = row.len();
        if w == 1 {
            out[0] = row[0];
            return;
        }
        out[0] = self.two(row[0], row[1]);
        for x in 1..w - 1 {
            out[x] = self.three(row[x - 1], row[x], row[x + 1]);
        }
        out[w - 1] = self.two(row[w - 2], row[w - 1]);
    }

    /// One pass across rows: `out` from the rows above, here and below.
    fn rows(self, up: Option<&[f32]>, here: &[f32], down: Option<&[f32]>, out: &mut [f32]) {
        match (up, down) {
            (Some(u), Some(d)) => {
                for x in 0..here.len() {
                    out[x] = self.three(u[x], here[x], d[x]);
                }
            }
            (Some(o), None) | (None, Some(o)) => {
                for x in 0..here.len() {
                    out[x] = self.two(o[x], here[x]);
                }
            }
            (None, None) => out.copy_from_slice(here),
        }
    }
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
