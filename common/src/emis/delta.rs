//! The correction factor δ_{n,m}(x) (docs/emis.md §3.2): it re-weights a pilot sample, drawn
//! with strategy m, so that it estimates candidate n's second moment. Evaluated through a proxy
//! strategy a whose techniques all have non-zero counts, from five aggregated proxy weights:
//!
//! S(k) = Σ_t (k_t/a_t)·w̄_t, T(k) = Σ_t (k_t/a_t)·c_t·w̄_t, δ = S(m)²·T(n) / (S(n)²·T(m)).
//!
//! With c ≡ 1 (no correlation-aware factor) δ = S(m) / S(n). A candidate that cannot sample
//! the path (S(n) = 0) gets an infinite moment, flagged, never NaN (docs/emis.md, D4).

use super::proxy::ProxyWeights;

/// A strategy's counts relative to the proxy's, per technique group.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CountRatios {
    /// Path tracing: 1, or 0 for a strategy without camera techniques.
    pub pt: f64,
    /// Light tracing: ν (N/P against the proxy's P light paths).
    pub lt: f64,
    /// Connections: c/4 against the proxy's 4.
    pub con: f64,
    /// Merges: χ (the reference code) or χ·ν (principled; docs/emis.md, D3a).
    pub vm: f64,
}

/// The correction factor of one sample for one candidate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Delta {
    /// A finite factor.
    Finite(f64),
    /// The candidate cannot sample the path: its moment is infinite.
    Infinite,
}

/// S(k) and T(k) of a strategy.
#[inline]
pub fn s_and_t(w: &ProxyWeights, k: &CountRatios) -> (f64, f64) {
    let common = k.pt * w.pt + k.lt * w.lt + k.con * w.con;
    (common + k.vm * w.vm, common + k.vm * w.vm_correlated)
}

/// δ_{n,m} for candidate `n` and pilot strategy `m`.
#[inline]
pub fn correction(w: &ProxyWeights, n: &CountRatios, m: &CountRatios) -> Delta {
    let (s_n, t_n) = s_and_t(w, n);
    let (s_m, t_m) = s_and_t(w, m);
    if s_n <= 0.0 {
        return Delta::Infinite;
    }
    if s_m <= 0.0 || t_m <= 0.0 {
        // the pilot cannot produce this path at all, so no sample reaches here
        return Delta::Finite(0.0);
    }
    let d = s_m * s_m * t_n / (s_n * s_n * t_m);
    if d.is_finite() { Delta::Finite(d) } else { Delta::Infinite }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::Sampler;

    fn weights(pt: f64, lt: f64, con: f64, vm: f64, c: f64) -> ProxyWeights {
        ProxyWeights { pt, lt, con, vm, vm_correlated: c * vm }
    }

    #[test]
    fn delta_is_one_for_the_pilot_itself_and_reduces_without_correlation() {
        let w = weights(0.2, 0.3, 0.1, 0.4, 0.35);
        let m = CountRatios { pt: 1.0, lt: 1.0, con: 0.25, vm: 1.0 };
        assert!(matches!(correction(&w, &m, &m), Delta::Finite(d) if (d - 1.0).abs() < 1e-12));
        let w1 = weights(0.2, 0.3, 0.1, 0.4, 1.0);
        let n = CountRatios { pt: 1.0, lt: 0.5, con: 1.0, vm: 0.3 };
        let (s_m, _) = s_and_t(&w1, &m);
        let (s_n, _) = s_and_t(&w1, &n);
        assert!(matches!(correction(&w1, &n, &m), Delta::Finite(d) if (d - s_m / s_n).abs() < 1e-12));
    }

    #[test]
    fn a_candidate_that_cannot_sample_the_path_is_infinite() {
        // only light tracing could sample this path; the path-tracing candidate cannot
        let w = weights(0.0, 1.0, 0.0, 0.0, 0.0);
        let pt_only = CountRatios { pt: 1.0, lt: 0.0, con: 0.0, vm: 0.0 };
        let pilot = CountRatios { pt: 1.0, lt: 1.0, con: 0.25, vm: 1.0 };
        assert_eq!(correction(&w, &pt_only, &pilot), Delta::Infinite);
    }

    /// The 1-D toy of docs/emis.md, checklist 5: two techniques with pdfs p1 = 1 and p2 = 2x on
    /// [0, 1], f(x) = x² + 0.1. Pilot m = (1, 1); for candidates n the pilot's Σ δ·y² estimates
    /// M[n] = ∫ f² / (n1 p1 + n2 p2) within 3σ.
    #[test]
    fn pilot_estimates_match_analytic_second_moments() {
        let f = |x: f64| x * x + 0.1;
        let p = [|_x: f64| 1.0, |x: f64| 2.0 * x];
        let m = [1.0, 1.0];
        let a = [1.0, 1.0]; // proxy counts
        let analytic = |n: [f64; 2]| {
            let steps = 200_000;
            (0..steps)
                .map(|i| {
                    let x = (i as f64 + 0.5) / steps as f64;
                    f(x) * f(x) / (n[0] * p[0](x) + n[1] * p[1](x))
                })
                .sum::<f64>()
                / steps as f64
        };
        for n in [[1.0, 1.0], [2.0, 0.5], [1.0, 3.0], [0.5, 0.0]] {
            let iterations = 40_000u32;
            let (mut sum, mut sum2) = (0.0f64, 0.0f64);
            for it in 0..iterations {
                let mut s = Sampler::for_pixel(13, it, 0);
                let mut per_iteration = 0.0;
                for t in 0..2 {
                    // one sample from technique t (m_t = 1): inverse cdf of p_t
                    let u = s.next_1d() as f64;
                    let x = if t == 0 { u } else { u.sqrt() }.clamp(1e-9, 1.0);
                    let denom_m = m[0] * p[0](x) + m[1] * p[1](x);
                    let y = f(x) / denom_m; // balance-weighted contribution
                    let proxy_sum = a[0] * p[0](x) + a[1] * p[1](x);
                    // proxy weights, grouped: technique 0 as "pt", technique 1 as "lt"
                    let w = ProxyWeights {
                        pt: a[0] * p[0](x) / proxy_sum,
                        lt: a[1] * p[1](x) / proxy_sum,
                        con: 0.0,
                        vm: 0.0,
                        vm_correlated: 0.0,
                    };
                    let ratio = |k: [f64; 2]| CountRatios { pt: k[0] / a[0], lt: k[1] / a[1], con: 0.0, vm: 0.0 };
                    match correction(&w, &ratio(n), &ratio(m)) {
                        Delta::Finite(d) => per_iteration += d * y * y,
                        Delta::Infinite => panic!("every candidate here can sample every x"),
                    }
                }
                sum += per_iteration;
                sum2 += per_iteration * per_iteration;
            }
            let mean = sum / iterations as f64;
            let sigma = ((sum2 / iterations as f64 - mean * mean) / iterations as f64).sqrt();
            let expected = analytic(n);
            assert!((mean - expected).abs() < 3.0 * sigma, "n = {n:?}: estimate {mean} ± {sigma}, analytic {expected}");
        }
    }
}
