//! Chi² goodness-of-fit for direction samplers (in the manner of Mitsuba's `test03_chi2`).
//!
//! The sphere is divided into equal-solid-angle cells (uniform in cos θ and φ). Samples are
//! binned into a histogram; the expected count of each cell is the pdf integrated over it
//! numerically. Cells with small expectations are pooled, then Pearson's statistic gives a
//! p-value that a test compares with a significance level.

use glam::Vec3;
use std::f64::consts::PI;

/// Result of a chi² test.
#[derive(Debug, Clone)]
pub struct Chi2Result {
    /// Pearson's statistic.
    pub statistic: f64,
    /// Degrees of freedom after pooling.
    pub dof: usize,
    /// Probability of a statistic at least this large if the sampler matches the pdf.
    pub p_value: f64,
    /// Integral of the pdf over the sphere.
    pub pdf_integral: f64,
    /// Fraction of sample attempts that produced a (non-delta) direction.
    pub sample_fraction: f64,
    /// More than 0.1 % of the samples landed in cells that, with all their neighbours, have
    /// (almost) zero pdf: samples far from the support.
    pub sample_outside_support: bool,
}

impl Chi2Result {
    /// Whether the sampler passes at significance `alpha`: p ≥ alpha, no samples outside the
    /// support, and the sample fraction equals the pdf's total mass (the pdf accounts for every
    /// produced direction).
    pub fn passes(&self, alpha: f64) -> bool {
        self.p_value >= alpha && !self.sample_outside_support && (self.pdf_integral - self.sample_fraction).abs() < 0.02
    }
}

/// Runs the test. `sample(u)` maps a sample index to an optional direction (None for failed or
/// delta samples); `pdf(w)` is the solid-angle density of directions.
pub fn chi2_test(
    n_samples: usize,
    res_cos: usize,
    res_phi: usize,
    mut sample: impl FnMut(usize) -> Option<Vec3>,
    pdf: impl Fn(Vec3) -> f32,
) -> Chi2Result {
    let cells = res_cos * res_phi;
    let cell_of = |w: Vec3| -> usize {
        let c = ((w.z as f64 + 1.0) * 0.5 * res_cos as f64).floor().clamp(0.0, res_cos as f64 - 1.0) as usize;
        let mut phi = (w.y as f64).atan2(w.x as f64);
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        let p = (phi / (2.0 * PI) * res_phi as f64).floor().clamp(0.0, res_phi as f64 - 1.0) as usize;
        c * res_phi + p
    };
    let mut observed = vec![0.0f64; cells];
    let mut produced = 0usize;
    for i in 0..n_samples {
        if let Some(w) = sample(i) {
            if w.is_finite() && (w.length() - 1.0).abs() < 1e-3 {
                observed[cell_of(w)] += 1.0;
                produced += 1;
            }
        }
    }
    // expected counts: the pdf integrated over each cell by a midpoint rule whose grid is
    // refined until it converges, so that peaked lobes (e.g. at the poles) are integrated well
    let cell_area = 4.0 * PI / cells as f64;
    let integrate_cell = |c: usize, p: usize, sub: usize| -> f64 {
        let mut acc = 0.0f64;
        for i in 0..sub {
            for j in 0..sub {
                let z = -1.0 + 2.0 * (c as f64 + (i as f64 + 0.5) / sub as f64) / res_cos as f64;
                let phi = 2.0 * PI * (p as f64 + (j as f64 + 0.5) / sub as f64) / res_phi as f64;
                let r = (1.0 - z * z).max(0.0).sqrt();
                acc += pdf(Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32)) as f64;
            }
        }
        acc / (sub * sub) as f64 * cell_area
    };
    let mut expected = vec![0.0f64; cells];
    for c in 0..res_cos {
        for p in 0..res_phi {
            // at least a 24 × 24 grid, so that slivers of small supports are not missed
            let mut sub = 12;
            let mut value = integrate_cell(c, p, sub);
            while sub < 384 {
                let finer = integrate_cell(c, p, sub * 2);
                sub *= 2;
                let converged = (finer - value).abs() <= 1e-3 * finer.abs() + 1e-9 / cells as f64;
                value = finer;
                if converged && sub >= 24 {
                    break;
                }
            }
            expected[c * res_phi + p] = value;
        }
    }
    let pdf_integral: f64 = expected.iter().sum();
    // a cell is outside the support when it and all its neighbours have (almost) no expected
    // samples: a sampler bug puts samples far from the support, not in slivers at its edge
    let empty = |c: usize, p: usize| expected[c * res_phi + p] * n_samples as f64 <= 1e-3;
    let mut outside = 0.0;
    for c in 0..res_cos {
        for p in 0..res_phi {
            let far = (c.saturating_sub(1)..=(c + 1).min(res_cos - 1))
                .all(|cc| [res_phi - 1, 0, 1].iter().all(|dp| empty(cc, (p + dp) % res_phi)));
            if far {
                outside += observed[c * res_phi + p];
            }
        }
    }
    let sample_outside_support = outside > 1e-3 * n_samples as f64;
    // sort cells by expectation and pool the smallest until the pool reaches 5
    let mut order: Vec<usize> = (0..cells).collect();
    order.sort_by(|&a, &b| expected[a].partial_cmp(&expected[b]).unwrap_or(std::cmp::Ordering::Equal));
    let (mut pool_o, mut pool_e) = (0.0, 0.0);
    let mut statistic = 0.0;
    let mut bins = 0usize;
    for &i in &order {
        let e = expected[i] * n_samples as f64;
        let o = observed[i];
        if e < 5.0 {
            pool_o += o;
            pool_e += e;
            if pool_e >= 5.0 {
                statistic += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
                bins += 1;
                pool_o = 0.0;
                pool_e = 0.0;
            }
        } else {
            statistic += (o - e) * (o - e) / e;
            bins += 1;
        }
    }
    if pool_e > 0.0 {
        statistic += (pool_o - pool_e) * (pool_o - pool_e) / pool_e.max(1.0);
        bins += 1;
    }
    let dof = bins.saturating_sub(1).max(1);
    let p_value = gamma_q(dof as f64 / 2.0, statistic / 2.0);
    Chi2Result {
        statistic,
        dof,
        p_value,
        pdf_integral,
        sample_fraction: produced as f64 / n_samples as f64,
        sample_outside_support,
    }
}

/// Natural log of the gamma function (Lanczos approximation, g = 7, n = 9).
pub fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        return (PI / (PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Regularised upper incomplete gamma function Q(a, x) = Γ(a, x) / Γ(a): the chi² survival
/// function is `gamma_q(dof / 2, x / 2)`. Series for x < a + 1, continued fraction otherwise.
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let gln = ln_gamma(a);
    if x < a + 1.0 {
        let (mut sum, mut term, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        1.0 - sum * (-x + a * x.ln() - gln).exp()
    } else {
        // modified Lentz evaluation of the continued fraction
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (-x + a * x.ln() - gln).exp() * h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_q_matches_known_chi2_quantiles() {
        // chi² with 10 dof: P(X > 18.307) = 0.05; with 1 dof: P(X > 3.841) = 0.05
        assert!((gamma_q(5.0, 18.307 / 2.0) - 0.05).abs() < 1e-3);
        assert!((gamma_q(0.5, 3.841 / 2.0) - 0.05).abs() < 1e-3);
        assert!((gamma_q(50.0, 50.0) - 0.4812).abs() < 2e-3);
        assert!((ln_gamma(5.0) - 24f64.ln()).abs() < 1e-10);
    }

    #[test]
    fn chi2_detects_a_wrong_pdf() {
        use crate::math::warp;
        use crate::sampler::Sampler;
        let draw = |i: usize| {
            let mut s = Sampler::for_pixel(3, i as u32, 0);
            Some(warp::square_to_cosine_hemisphere(s.next_2d()))
        };
        let right = chi2_test(200_000, 16, 32, draw, warp::cosine_hemisphere_pdf);
        assert!(right.passes(0.01), "{right:?}");
        // uniform-hemisphere pdf for cosine samples must fail
        let wrong = chi2_test(200_000, 16, 32, draw, |w| if w.z > 0.0 { 0.5 / std::f32::consts::PI } else { 0.0 });
        assert!(!wrong.passes(0.01), "{wrong:?}");
    }
}
