//! The proxy strategy's view of a pilot sample: the balance weights its techniques would give
//! the sample's path, summed by technique group. The correction factor ([`super::delta`])
//! turns them into each candidate's re-weighting. Computed here, in the EMIS layer, from the
//! technique densities the MIS code exposes, so the MIS weights know nothing of EMIS.

use crate::integrator::path::mis::{
    MAX_VERTICES, PathPdfs, PathRatios, SampleCounts, Technique, technique_densities_with, technique_index,
};

/// The proxy strategy's balance weights of one path, aggregated by technique group.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProxyWeights {
    /// Path tracing (hits and NEE together).
    pub pt: f64,
    /// Light tracing.
    pub lt: f64,
    /// All connections.
    pub con: f64,
    /// All merges.
    pub vm: f64,
    /// Σ c_t·w̄_t over merges (≤ `vm`).
    pub vm_correlated: f64,
}

/// The balance weights of the proxy strategy `proxy` (docs/emis.md §3.2), aggregated by technique
/// group: hits and next-event estimation together, light tracing, all connections, all merges,
/// and the merges' weights times their correlation-aware factors. The groups sum to 1; a path no
/// technique of the proxy can sample counts as path tracing's (the reference's convention).
pub fn proxy_weights(p: &PathPdfs, r: &PathRatios, proxy: &SampleCounts) -> ProxyWeights {
    let mut d = [0.0f32; 2 * MAX_VERTICES];
    let n = technique_densities_with(p, r, proxy, &mut d);
    let lt_index = technique_index(p, Technique::LightTrace);
    let sum = |range: std::ops::Range<usize>| d[range].iter().map(|&v| v as f64).sum::<f64>();
    let (pt, con, lt) = (sum(0..2), sum(2..lt_index), d[lt_index] as f64);
    let (mut vm, mut vm_correlated) = (0.0f64, 0.0f64);
    if let Some(m) = &proxy.merge {
        for (i, &density) in d[lt_index + 1..n].iter().enumerate() {
            vm += density as f64;
            vm_correlated += r.factor(i + 1, m) as f64 * density as f64;
        }
    }
    let total = pt + con + lt + vm;
    if !(total > 0.0 && total.is_finite()) {
        return ProxyWeights { pt: 1.0, lt: 0.0, con: 0.0, vm: 0.0, vm_correlated: 0.0 };
    }
    ProxyWeights {
        pt: pt / total,
        lt: lt / total,
        con: con / total,
        vm: vm / total,
        vm_correlated: vm_correlated / total,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrator::path::mis::tests::{brute_force_pdf, random_path};
    use crate::integrator::path::mis::{MergeCounts, correlation_factor};

    /// The proxy's acceptance test (docs/emis.md, checklist 4): its grouped weights sum to 1,
    /// the correlated merge weight never exceeds the merge weight, and each group equals the
    /// brute-force balance weights of the proxy counts (a = 1 for hits and NEE, P for light
    /// tracing, 4 connections, χ = 1 merges).
    #[test]
    fn proxy_weights_sum_to_one_and_match_brute_force() {
        let pixels = 256.0f64 * 256.0;
        for correlation_aware in [false, true] {
            let merge = MergeCounts {
                area: 3e-4,
                count: pixels as f32,
                correlation_aware,
                correlation_area: 2e-2,
                light_paths: pixels as f32,
            };
            let connect = 4.0 / 3.2;
            let proxy = SampleCounts {
                hit: 1.0,
                next_event: 1.0,
                connect: connect as f32,
                light_trace: pixels as f32,
                merge: Some(merge),
            };
            for len in 3..=10 {
                for seed in 0..100 {
                    let p = random_path(seed, len, false);
                    let w = proxy_weights(&p, &PathRatios::new(&p, proxy.merge.as_ref()), &proxy);
                    let sum = w.pt + w.lt + w.con + w.vm;
                    assert!((sum - 1.0).abs() < 1e-5, "sum {sum}");
                    assert!(w.vm_correlated <= w.vm + 1e-12);
                    // brute force over full path pdfs
                    let k = len - 1;
                    let mut groups = [0.0f64; 4]; // pt, lt, con, vm
                    let mut vm_c = 0.0;
                    for s in 0..=k {
                        let v = brute_force_pdf(&p, s);
                        match s {
                            0 | 1 => groups[0] += v,
                            s if s == k => groups[1] += pixels * v,
                            _ => groups[2] += connect * v,
                        }
                    }
                    for i in 1..k - 1 {
                        let mut pdf = 1.0f64;
                        for j in 0..=k {
                            pdf *= if j < i { p.from_light[j] } else { p.from_camera[j] } as f64;
                        }
                        let c = if correlation_aware { correlation_factor(&p, i, &merge) as f64 } else { 1.0 };
                        let v = c * pixels * pdf * p.from_light[i] as f64 * 3e-4;
                        groups[3] += v;
                        vm_c += c * v;
                    }
                    let total: f64 = groups.iter().sum();
                    let got = [w.pt, w.lt, w.con, w.vm];
                    for g in 0..4 {
                        let expected = groups[g] / total;
                        assert!(
                            (got[g] - expected).abs() < 1e-4 * expected.max(1e-2),
                            "group {g}: {} vs {expected}",
                            got[g]
                        );
                    }
                    assert!((w.vm_correlated - vm_c / total).abs() < 1e-4 * (vm_c / total).max(1e-2));
                }
            }
        }
    }

    /// The estimator re-weights a sample with the ratios its own MIS weight was computed from,
    /// under the sample's counts: the proxy's weights must not depend on those counts (the
    /// correlation-aware factor's 1/N floor differs between ν·P and P light paths).
    #[test]
    fn proxy_weights_do_not_depend_on_the_counts_the_ratios_came_with() {
        let pixels = 128.0f32 * 96.0;
        let merge = |light_paths: f32| MergeCounts {
            area: 5e-4,
            count: light_paths * 0.3,
            correlation_aware: true,
            correlation_area: 4e-2,
            light_paths,
        };
        let proxy = SampleCounts {
            hit: 1.0,
            next_event: 1.0,
            connect: 1.3,
            light_trace: pixels,
            merge: Some(MergeCounts { count: pixels, ..merge(pixels) }),
        };
        let mut floored = 0;
        for nu in [0.01f32, 0.25, 4.0] {
            let sample = merge(nu * pixels);
            for len in 4..=12 {
                for seed in 0..100 {
                    let p = random_path(seed, len, seed % 4 == 0);
                    let own = proxy_weights(&p, &PathRatios::new(&p, Some(&sample)), &proxy);
                    let fresh = proxy_weights(&p, &PathRatios::new(&p, proxy.merge.as_ref()), &proxy);
                    assert_eq!(own, fresh, "ν {nu} len {len} seed {seed}");
                    let r = PathRatios::new(&p, Some(&sample));
                    floored +=
                        (1..len - 2).filter(|&i| r.factor(i, &sample) != r.factor(i, &proxy.merge.unwrap())).count();
                }
            }
        }
        // the paths exercise the floors, else the test could not tell
        assert!(floored > 0);
    }
}
