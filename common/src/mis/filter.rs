//! Image filters of the optimiser (emis-spec §5), on single-channel row-major images:
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

    /// A separable 3-tap pass: `combine(a, b, c, taps)` along rows, then along columns, where
    /// out-of-image taps are `None` (exact for the mean with border renormalisation, whose
    /// divisor factorises into row taps × column taps, and for the maximum).
    fn separable(&self, combine: impl Fn(f32, Option<f32>, Option<f32>) -> f32 + Sync) -> Image {
        use rayon::prelude::*;
        let (w, h) = (self.width, self.height);
        let mut rows = vec![0.0f32; w * h];
        rows.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, out)| {
            let row = &self.data[y * w..(y + 1) * w];
            for x in 0..w {
                let left = x.checked_sub(1).map(|i| row[i]);
                let right = row.get(x + 1).copied();
                out[x] = combine(row[x], left, right);
            }
        });
        let mut out = vec![0.0f32; w * h];
        out.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, out)| {
            for x in 0..w {
                let up = y.checked_sub(1).map(|i| rows[i * w + x]);
                let down = (y + 1 < h).then(|| rows[(y + 1) * w + x]);
                out[x] = combine(rows[y * w + x], up, down);
            }
        });
        Image { width: w, height: h, data: out }
    }

    /// One 3×3 box pass with border renormalisation.
    pub fn box3(&self) -> Image {
        self.separable(|c, a, b| {
            let n = 1.0 + a.is_some() as u32 as f32 + b.is_some() as u32 as f32;
            (c + a.unwrap_or(0.0) + b.unwrap_or(0.0)) / n
        })
    }

    /// One 3×3 max pass (out-of-image taps are −∞, i.e. ignored).
    pub fn dilate3(&self) -> Image {
        self.separable(|c, a, b| c.max(a.unwrap_or(f32::NEG_INFINITY)).max(b.unwrap_or(f32::NEG_INFINITY)))
    }

    /// `radius` successive box passes.
    pub fn box_blur(&self, radius: usize) -> Image {
        (0..radius).fold(self.clone(), |img, _| img.box3())
    }

    /// `radius` successive dilation passes.
    pub fn dilate(&self, radius: usize) -> Image {
        (0..radius).fold(self.clone(), |img, _| img.dilate3())
    }

    /// The `q` quantile (0..1) by a linear histogram with one bin per pixel over [min, max],
    /// returning the centre of the bin (the reference implementation's approximation).
    pub fn histogram_quantile(&self, q: f64) -> f32 {
        let finite: Vec<f32> = self.data.iter().copied().filter(|v| v.is_finite()).collect();
        if finite.is_empty() {
            return 0.0;
        }
        let (lo, hi) = finite.iter().fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        if hi <= lo {
            return lo;
        }
        let bins = finite.len();
        let width = (hi - lo) as f64 / bins as f64;
        let mut counts = vec![0u32; bins];
        for &v in &finite {
            counts[(((v - lo) as f64 / width) as usize).min(bins - 1)] += 1;
        }
        let target = (q * finite.len() as f64).ceil().max(1.0) as u64;
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
        assert_eq!(img.box_blur(3), img.box3().box3().box3());
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
