//! Statistical comparison of a render with a reference image: a port of the shared
//! `tools/exrcompare.py` so that tests and benchmarks apply the same method without Python.
//!
//! * `bias`: relative difference of the image means per channel;
//! * `relmse`: mean over pixels and channels of (x − ref)² / (ref² + 1e-4), with the top 0.1 %
//!   of per-pixel errors dropped;
//! * with a second independent render: `noise_relmse` (half the relMSE between the two renders,
//!   the part of `relmse` that noise explains), `ratio` = relmse / noise_relmse, and `bias_z`,
//!   the bias of the mean of both renders in units of its standard error (including the
//!   reference's own error of the mean).

/// The outcome of [`compare`].
#[derive(Clone, Debug, serde::Serialize)]
pub struct Comparison {
    /// Mean of each channel of the render (of both renders when two are given).
    pub mean_rgb: [f64; 3],
    /// Mean of each channel of the reference.
    pub reference_mean_rgb: [f64; 3],
    /// Relative bias of the mean per channel.
    pub bias: [f64; 3],
    /// relMSE of the first render against the reference.
    pub relmse: f64,
    /// Half the relMSE between the two renders.
    pub noise_relmse: Option<f64>,
    /// relmse / noise_relmse.
    pub ratio: Option<f64>,
    /// Bias in standard errors per channel.
    pub bias_z: Option<[f64; 3]>,
    /// Non-finite values in the render(s).
    pub non_finite: usize,
}

impl Comparison {
    /// `exrcompare.py`'s bias check: each channel has |bias| ≤ `max_bias` or |z| ≤ 4.
    pub fn bias_ok(&self, max_bias: f64) -> bool {
        let z = self.bias_z.unwrap_or([f64::INFINITY; 3]);
        (0..3).all(|c| self.bias[c].abs() <= max_bias || z[c].abs() <= 4.0)
    }
}

/// The fraction of per-pixel errors the equal-time benchmark drops: a firefly or two must not
/// decide a comparison of whole images.
pub const DROPPED_FRACTION: f64 = 0.001;

/// relMSE with the top `drop` fraction of per-pixel errors removed (numpy's linear quantile).
pub fn relmse(a: &[[f32; 3]], reference: &[[f32; 3]], drop: f64) -> f64 {
    mean_without_top(a.iter().zip(reference).map(|(x, r)| pixel_error(x, r)).collect(), drop)
}

/// [`relmse`] with the reference's own noise taken out: over the pixels `relmse` keeps, the
/// mean of ((x − r)² − se²) / (r² + 1e-4), `se` the reference's per-pixel standard error. For a
/// render independent of the reference E[(x − r)²] = E[(x − truth)²] + se², so this estimates
/// the error against the truth, which a noisy reference pulls towards the same value for every
/// render (docs/decisions/0047-reference-noise-in-equal-time.md). The reference's noise in
/// the denominator is left in: a second-order effect (3·se²/r² of the result). It can come out
/// negative.
pub fn relmse_against_truth(a: &[[f32; 3]], reference: &[[f32; 3]], reference_se: &[[f32; 3]], drop: f64) -> f64 {
    assert!(a.len() == reference.len() && a.len() == reference_se.len(), "invariant: images of equal size");
    let err: Vec<f64> = a.iter().zip(reference).map(|(x, r)| pixel_error(x, r)).collect();
    let cut = top_cut(&err, drop);
    let (mut sum, mut n) = (0.0, 0usize);
    for ((e, r), se) in err.iter().zip(reference).zip(reference_se) {
        if cut.is_none_or(|cut| *e <= cut) {
            let floor = (0..3).map(|c| (se[c] as f64).powi(2) / ((r[c] as f64).powi(2) + 1e-4)).sum::<f64>() / 3.0;
            sum += e - floor;
            n += 1;
        }
    }
    sum / n.max(1) as f64
}

/// One pixel's relative squared error, the mean over channels of (x − r)² / (r² + 1e-4).
fn pixel_error(x: &[f32; 3], r: &[f32; 3]) -> f64 {
    (0..3)
        .map(|c| {
            let (x, r) = (x[c] as f64, r[c] as f64);
            (x - r) * (x - r) / (r * r + 1e-4)
        })
        .sum::<f64>()
        / 3.0
}

/// The `1 − drop` quantile of `err` (numpy's linear quantile) above which errors are dropped,
/// or `None` when nothing is dropped (no `drop`, or 1000 values or fewer).
fn top_cut(err: &[f64], drop: f64) -> Option<f64> {
    if drop <= 0.0 || err.len() <= 1000 {
        return None;
    }
    let mut sorted = err.to_vec();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let pos = (1.0 - drop) * (sorted.len() - 1) as f64;
    let (lo, frac) = (pos.floor() as usize, pos - pos.floor());
    Some(sorted[lo] + (sorted[(lo + 1).min(sorted.len() - 1)] - sorted[lo]) * frac)
}

/// The mean of per-pixel errors above the `1 − drop` quantile removed (numpy's linear
/// quantile), as [`relmse`] drops them; nothing is dropped from 1000 values or fewer.
pub fn mean_without_top(mut err: Vec<f64>, drop: f64) -> f64 {
    if let Some(cut) = top_cut(&err, drop) {
        err.retain(|&e| e <= cut);
    }
    err.iter().sum::<f64>() / err.len().max(1) as f64
}

fn channel_means(img: &[[f32; 3]]) -> [f64; 3] {
    let mut m = [0.0f64; 3];
    for p in img {
        for c in 0..3 {
            m[c] += p[c] as f64;
        }
    }
    m.map(|v| v / img.len().max(1) as f64)
}

/// Compares `a` (and optionally an independent second render `b`) with `reference`;
/// `reference_rel_err` is the relative standard error of the reference's image mean.
pub fn compare(a: &[[f32; 3]], reference: &[[f32; 3]], b: Option<&[[f32; 3]]>, reference_rel_err: f64) -> Comparison {
    assert_eq!(a.len(), reference.len(), "invariant: images of equal size");
    let non_finite = a.iter().chain(b.unwrap_or(&[])).flatten().filter(|v| !v.is_finite()).count();
    let ref_mean = channel_means(reference);
    let mean_a = channel_means(a);
    let mut out = Comparison {
        mean_rgb: mean_a,
        reference_mean_rgb: ref_mean,
        bias: std::array::from_fn(|c| (mean_a[c] - ref_mean[c]) / ref_mean[c].max(1e-8)),
        relmse: relmse(a, reference, 0.001),
        noise_relmse: None,
        ratio: None,
        bias_z: None,
        non_finite,
    };
    if let Some(b) = b {
        let noise = relmse(a, b, 0.001) / 2.0;
        out.noise_relmse = Some(noise);
        out.ratio = Some(out.relmse / noise.max(1e-12));
        let p = a.len() as f64;
        let mut var_mean = [0.0f64; 3];
        let mut both_mean = [0.0f64; 3];
        for (x, y) in a.iter().zip(b) {
            for c in 0..3 {
                let (x, y) = (x[c] as f64, y[c] as f64);
                var_mean[c] += (x - y) * (x - y) / 2.0;
                both_mean[c] += (x + y) / 2.0;
            }
        }
        let mut z = [0.0f64; 3];
        for c in 0..3 {
            let v = var_mean[c] / (p * p) / 2.0 + (reference_rel_err * ref_mean[c]).powi(2);
            let diff = both_mean[c] / p - ref_mean[c];
            out.bias[c] = diff / ref_mean[c].max(1e-8);
            out.mean_rgb[c] = both_mean[c] / p;
            z[c] = diff / v.max(1e-30).sqrt();
        }
        out.bias_z = Some(z);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::Sampler;

    fn noisy(reference: &[[f32; 3]], seed: u64, sigma: f32, offset: f32) -> Vec<[f32; 3]> {
        reference
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let mut s = Sampler::for_pixel(seed, i as u32, 0);
                r.map(|v| {
                    // sum of 12 uniforms: approximately normal, unit variance
                    let g: f32 = (0..12).map(|_| s.next_1d()).sum::<f32>() - 6.0;
                    v * (1.0 + offset) + sigma * v * g
                })
            })
            .collect()
    }

    #[test]
    fn unbiased_noise_gives_ratio_near_one_and_small_z() {
        let reference: Vec<[f32; 3]> = (0..64 * 64).map(|i| [0.2 + (i % 7) as f32 * 0.1, 0.5, 0.3]).collect();
        let (a, b) = (noisy(&reference, 1, 0.1, 0.0), noisy(&reference, 2, 0.1, 0.0));
        let c = compare(&a, &reference, Some(&b), 0.0);
        assert!((c.ratio.unwrap() - 1.0).abs() < 0.1, "{c:?}");
        assert!(c.bias_ok(0.0), "{c:?}");
    }

    #[test]
    fn the_reference_noise_is_taken_out_of_the_error_against_the_truth() {
        let truth: Vec<[f32; 3]> = (0..128 * 128).map(|i| [0.2 + (i % 7) as f32 * 0.1, 0.5, 0.3]).collect();
        // a reference with half the render's noise: against it the render's relMSE is 1.25×
        let reference = noisy(&truth, 7, 0.05, 0.0);
        let se: Vec<[f32; 3]> = truth.iter().map(|t| t.map(|v| 0.05 * v)).collect();
        let a = noisy(&truth, 1, 0.1, 0.0);
        let (against_truth, raw) = (relmse(&a, &truth, 0.0), relmse(&a, &reference, 0.0));
        let corrected = relmse_against_truth(&a, &reference, &se, 0.0);
        assert!(raw > 1.2 * against_truth, "raw {raw}, truth {against_truth}");
        assert!((corrected / against_truth - 1.0).abs() < 0.03, "corrected {corrected}, truth {against_truth}");
        // with no reference noise it is relmse itself, the same pixels dropped
        let zero = vec![[0.0f32; 3]; truth.len()];
        let exact = relmse_against_truth(&a, &truth, &zero, DROPPED_FRACTION);
        assert!((exact - relmse(&a, &truth, DROPPED_FRACTION)).abs() < 1e-12);
    }

    #[test]
    fn a_two_percent_bias_is_detected() {
        let reference: Vec<[f32; 3]> = (0..64 * 64).map(|i| [0.2 + (i % 7) as f32 * 0.1, 0.5, 0.3]).collect();
        let (a, b) = (noisy(&reference, 1, 0.05, 0.02), noisy(&reference, 2, 0.05, 0.02));
        let c = compare(&a, &reference, Some(&b), 0.0);
        assert!(!c.bias_ok(0.01), "{c:?}");
        assert!(c.ratio.unwrap() > 1.1, "{c:?}");
    }
}
