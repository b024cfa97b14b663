//! Exact high quantiles of large images in one streaming pass, for the optimiser's outlier
//! thresholds (docs/emis.md §5.5): the 99.9 % quantile of 2 million values is decided by the
//! largest two thousand of them, so a [`QuantileStream`] keeps only the largest values seen,
//! plus the count and range of the finite ones, and answers both quantile rules from those.
//!
//! Both rules give the value a full sort or count would: the histogram rule's bin index is a
//! non-decreasing function of the value, so the bin where the cumulative count first reaches
//! the target is the bin of the target-th smallest value; only that value is needed, and it is
//! among the kept ones whenever the quantile is high enough (otherwise the stream says so and
//! the caller counts the full image).

/// Values kept beyond the minimum before the kept set is cut back (amortises the selection).
const SLACK: usize = 4096;

/// The finite values' count, minimum and maximum, and the largest of them, streamed.
pub(crate) struct QuantileStream {
    /// How many of the largest values answer the quantile (the kept set is cut to this size).
    keep: usize,
    /// The largest values so far: every finite value above `cutoff`, and some equal to it.
    kept: Vec<f32>,
    /// Values at or below it are not needed (−∞ until the first cut).
    cutoff: f32,
    count: usize,
    lo: f32,
    hi: f32,
}

/// How many of the largest values the histogram rule at `q` needs for up to `n` values: the
/// target-th smallest, target = ⌈q·n⌉, is the (n − target + 1)-th largest, a count that does
/// not decrease with n.
pub(crate) fn histogram_keep(q: f64, n: usize) -> usize {
    let target = ((q * n as f64).ceil().max(1.0) as usize).min(n.max(1));
    n + 1 - target
}

/// How many of the largest values the selection rule at `q` needs for up to `n` values (the
/// value at 0-based rank ⌈q·n⌉ − 1 is the (n − rank)-th largest).
pub(crate) fn selection_keep(q: f64, n: usize) -> usize {
    n.max(1) - selection_rank(q, n.max(1))
}

/// The 0-based rank in ascending order of the selection rule's value among `n` ≥ 1 values.
fn selection_rank(q: f64, n: usize) -> usize {
    ((q * n as f64).ceil() as usize).clamp(1, n) - 1
}

impl QuantileStream {
    /// A stream that answers exactly whenever its quantile's rank from the top is at most
    /// `keep` (see [`histogram_keep`] and [`selection_keep`]).
    pub(crate) fn new(keep: usize) -> Self {
        let keep = keep.max(1);
        QuantileStream {
            keep,
            kept: Vec::new(),
            cutoff: f32::NEG_INFINITY,
            count: 0,
            lo: f32::INFINITY,
            hi: f32::NEG_INFINITY,
        }
    }

    /// Adds `values` (non-finite ones are skipped, as the quantile rules skip them). The range
    /// runs in eight lanes that ignore NaN, so that the loop compiles to vector code; a slice
    /// with an infinity takes [`QuantileStream::push_each`], and a slice's values are only
    /// looked at one by one when its maximum passes the cutoff.
    pub(crate) fn push_slice(&mut self, values: &[f32]) {
        let (mut lo, mut hi, mut nan) = ([f32::INFINITY; 8], [f32::NEG_INFINITY; 8], [0u32; 8]);
        let (chunks, rest) = values.as_chunks::<8>();
        // `min` and `max` ignore NaN; which zero of ±0 they keep does not change a quantile
        let mut lane = |l: usize, v: f32| {
            lo[l] = lo[l].min(v);
            hi[l] = hi[l].max(v);
            nan[l] += v.is_nan() as u32;
        };
        for chunk in chunks {
            for (l, &v) in chunk.iter().enumerate() {
                lane(l, v);
            }
        }
        for (l, &v) in rest.iter().enumerate() {
            lane(l, v);
        }
        let lo = lo.iter().fold(f32::INFINITY, |a, &b| if b < a { b } else { a });
        let hi = hi.iter().fold(f32::NEG_INFINITY, |a, &b| if b > a { b } else { a });
        if lo == f32::NEG_INFINITY || hi == f32::INFINITY {
            return self.push_each(values);
        }
        self.count += values.len() - nan.iter().sum::<u32>() as usize;
        self.lo = if lo < self.lo { lo } else { self.lo };
        self.hi = if hi > self.hi { hi } else { self.hi };
        if hi > self.cutoff {
            for &v in values {
                if v > self.cutoff {
                    self.kept.push(v);
                }
            }
            self.cut_if_full();
        }
    }

    /// [`QuantileStream::push_slice`] value by value.
    fn push_each(&mut self, values: &[f32]) {
        for &v in values.iter().filter(|v| v.is_finite()) {
            self.count += 1;
            self.lo = if v < self.lo { v } else { self.lo };
            self.hi = if v > self.hi { v } else { self.hi };
            if v > self.cutoff {
                self.kept.push(v);
            }
        }
        self.cut_if_full();
    }

    fn cut_if_full(&mut self) {
        if self.kept.len() >= 2 * self.keep + SLACK {
            self.cut();
        }
    }

    /// Keeps only the `keep` largest values and raises the cutoff to the smallest of them.
    fn cut(&mut self) {
        let drop = self.kept.len() - self.keep;
        self.kept.select_nth_unstable_by(drop, f32::total_cmp);
        self.kept.drain(..drop);
        self.cutoff = self.kept[0];
    }

    /// The `m`-th largest finite value (1-based), if the kept values decide it.
    fn largest(&mut self, m: usize) -> Option<f32> {
        let n = self.kept.len();
        if m == 0 || m > n {
            return None;
        }
        Some(*self.kept.select_nth_unstable_by(n - m, f32::total_cmp).1)
    }

    /// The histogram rule of [`crate::emis::filter::Image::histogram_quantile`]: one bin per
    /// finite value over [min, max], the centre of the bin where the cumulative count reaches
    /// ⌈q·n⌉. `None` when the kept values do not decide it.
    pub(crate) fn histogram_quantile(&mut self, q: f64) -> Option<f32> {
        let (lo, hi, n) = (self.lo, self.hi, self.count);
        if n == 0 {
            return Some(0.0);
        }
        if hi <= lo {
            return Some(lo);
        }
        let target = (q * n as f64).ceil().max(1.0) as u64;
        if target > n as u64 {
            return Some(hi);
        }
        let value = self.largest(n - target as usize + 1)?;
        let bins = n;
        let width = (hi - lo) as f64 / bins as f64;
        let bin = (((value - lo) as f64 / width) as usize).min(bins - 1);
        Some((lo as f64 + (bin as f64 + 0.5) * width) as f32)
    }

    /// The value at rank ⌈q·n⌉ − 1 of the n finite values in ascending order, +∞ if there are
    /// none. `None` when the kept values do not decide it.
    pub(crate) fn selection_quantile(&mut self, q: f64) -> Option<f32> {
        let n = self.count;
        if n == 0 {
            return Some(f32::INFINITY);
        }
        self.largest(n - selection_rank(q, n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emis::filter::histogram_quantile_by_counts;
    use crate::sampler::Sampler;

    /// Heavy-tailed values with infinities, NaN, ties and a sorted run, streamed in uneven
    /// slices, at several quantiles and sizes: both rules equal their full-array definitions.
    #[test]
    fn streamed_quantiles_equal_the_full_definitions() {
        for n in [1usize, 7, 100, 5000, 40_000] {
            let mut s = Sampler::for_pixel(5, n as u32, 0);
            let mut values: Vec<f32> = (0..n)
                .map(|i| match i % 97 {
                    0 => f32::INFINITY,
                    1 => f32::NAN,
                    2 | 3 => 4.0,
                    _ => (0.01 / s.next_1d().max(1e-6)).powi(2),
                })
                .collect();
            values[n / 2..].iter_mut().enumerate().for_each(|(i, v)| *v = if i % 5 == 0 { i as f32 } else { *v });
            for q in [0.0, 0.3, 0.9, 0.999, 1.0] {
                let mut h = QuantileStream::new(histogram_keep(q, n));
                let mut r = QuantileStream::new(selection_keep(q, n));
                for chunk in values.chunks(61) {
                    h.push_slice(chunk);
                    r.push_slice(chunk);
                }
                assert_eq!(
                    h.histogram_quantile(q).map(f32::to_bits),
                    Some(histogram_quantile_by_counts(&values, q).to_bits()),
                    "n {n} q {q}"
                );
                let mut finite: Vec<f32> = values.iter().copied().filter(|v| v.is_finite()).collect();
                finite.sort_by(f32::total_cmp);
                let expected = if finite.is_empty() { f32::INFINITY } else { finite[selection_rank(q, finite.len())] };
                assert_eq!(r.selection_quantile(q).map(f32::to_bits), Some(expected.to_bits()), "n {n} q {q}");
            }
        }
    }

    #[test]
    fn a_stream_that_kept_too_few_values_says_so() {
        let mut s = QuantileStream::new(2);
        let values: Vec<f32> = (0..20_000).map(|i| i as f32).collect();
        s.push_slice(&values);
        assert!(s.selection_quantile(0.5).is_none());
        assert_eq!(s.selection_quantile(1.0), Some(19_999.0));
    }
}
