//! MIS weights on random paths: each in [0, 1], summing to 1 over the techniques that can
//! sample the path, equal to a brute-force balance heuristic, with and without
//! correlation-aware merges and delta vertices.

use super::*;
use crate::sampler::Sampler;

/// A random path of `len` vertices with positive densities, occasionally delta vertices.
pub(crate) fn random_path(seed: u32, len: usize, with_deltas: bool) -> PathPdfs {
    let mut s = Sampler::for_pixel(77, seed, len as u32);
    let mut p = PathPdfs::new(len);
    for i in 0..len {
        p.from_light[i] = 0.01 + 10.0 * s.next_1d() * s.next_1d();
        p.from_camera[i] = 0.01 + 10.0 * s.next_1d() * s.next_1d();
    }
    p.from_camera[len - 1] = 1.0;
    p.next_event0 = 0.01 + 5.0 * s.next_1d();
    if with_deltas {
        // a specular vertex somewhere in the middle: densities sampled through it are deltas
        for i in 1..len - 1 {
            if s.next_1d() < 0.25 {
                p.delta[i] = true;
                p.from_light[i + 1] = 0.0;
                p.from_camera[i - 1] = 0.0;
            }
        }
    }
    p
}

fn all_techniques(len: usize, merges: bool) -> Vec<Technique> {
    let k = len - 1;
    let mut t = vec![Technique::EmitterHit, Technique::LightTrace];
    if k >= 2 {
        t.push(Technique::NextEvent);
    }
    t.extend((2..k).map(Technique::Connect));
    if merges {
        t.extend((1..k.saturating_sub(1)).map(Technique::Merge));
    }
    t
}

fn counts_variants() -> Vec<SampleCounts> {
    let mut v = vec![SampleCounts::PATH_TRACING];
    for (nu, c, chi) in [(1.0f32, 1.0f32, 1.0f32), (0.25, 4.0, 0.3), (2.0, 0.0, 1.0), (0.5, 8.0, 0.0)] {
        let n = nu * 256.0 * 256.0;
        let cache = n * 4.0;
        for correlation_aware in [false, true] {
            v.push(SampleCounts {
                hit: 1.0,
                next_event: 1.0,
                connect: c * n / cache,
                light_trace: n,
                merge: Some(MergeCounts {
                    area: 1e-4,
                    count: n * chi,
                    correlation_aware,
                    correlation_area: 1e-2,
                    light_paths: n,
                }),
            });
        }
        // BDPT: no merges
        v.push(SampleCounts { hit: 1.0, next_event: 1.0, connect: c * n / cache, light_trace: n, merge: None });
    }
    v
}

#[test]
fn weights_lie_in_unit_interval_and_sum_to_one() {
    for counts in counts_variants() {
        for len in 2..=14 {
            for seed in 0..200 {
                let p = random_path(seed, len, seed % 3 == 0);
                let sum: f32 = all_techniques(len, counts.merge.is_some())
                    .into_iter()
                    .map(|t| {
                        let w = weight(&p, &counts, t);
                        assert!((0.0..=1.0).contains(&w), "{t:?} weight {w}");
                        w
                    })
                    .sum();
                // a path that no enabled technique can sample has all weights 0
                let mut d = [0.0; 2 * MAX_VERTICES];
                let n = technique_densities(&p, &counts, &mut d);
                let samplable = d[..n].iter().any(|&x| x > 0.0);
                if samplable {
                    assert!((sum - 1.0).abs() < 1e-4, "len {len} seed {seed} {counts:?}: sum {sum}");
                } else {
                    assert_eq!(sum, 0.0);
                }
            }
        }
    }
}

/// Path pdf of technique s computed directly as a product (no ratios).
pub(crate) fn brute_force_pdf(p: &PathPdfs, s: usize) -> f64 {
    let mut pdf = 1.0f64;
    for i in 0..p.len {
        let d = if i < s { if s == 1 && i == 0 { p.next_event0 } else { p.from_light[i] } } else { p.from_camera[i] };
        pdf *= d as f64;
    }
    pdf
}

#[test]
fn weights_equal_brute_force_balance_heuristic_without_deltas() {
    for len in 3..=10 {
        for seed in 0..100 {
            let p = random_path(seed, len, false);
            let k = len - 1;
            let (n_lt, n_conn) = (5000.0f64, 0.37f64);
            let counts = SampleCounts {
                hit: 1.0,
                next_event: 1.0,
                connect: n_conn as f32,
                light_trace: n_lt as f32,
                merge: None,
            };
            let n_of = |s: usize| {
                if s <= 1 {
                    1.0
                } else if s == k {
                    n_lt
                } else {
                    n_conn
                }
            };
            let total: f64 = (0..=k).map(|s| n_of(s) * brute_force_pdf(&p, s)).sum();
            for s in 0..=k {
                let t = match s {
                    0 => Technique::EmitterHit,
                    1 => Technique::NextEvent,
                    s if s == k => Technique::LightTrace,
                    s => Technique::Connect(s),
                };
                let expected = n_of(s) * brute_force_pdf(&p, s) / total;
                let w = weight(&p, &counts, t) as f64;
                assert!((w - expected).abs() < 1e-4 * expected.max(1e-3), "len {len} s {s}: {w} vs {expected}");
            }
        }
    }
}

/// With all counts 1 and no merges, the weights are the classic balance heuristic of BDPT.
#[test]
fn unit_counts_give_classic_balance_weights() {
    let counts = SampleCounts { hit: 1.0, next_event: 1.0, connect: 1.0, light_trace: 1.0, merge: None };
    for seed in 0..50 {
        let p = random_path(seed, 6, false);
        let total: f64 = (0..6).map(|s| brute_force_pdf(&p, s)).sum();
        let w = weight(&p, &counts, Technique::Connect(3)) as f64;
        assert!((w - brute_force_pdf(&p, 3) / total).abs() < 1e-5);
    }
}

#[test]
fn merge_weight_uses_density_times_area_times_count() {
    let p = random_path(3, 6, false);
    let m =
        MergeCounts { area: 2e-3, count: 1000.0, correlation_aware: false, correlation_area: 0.0, light_paths: 1000.0 };
    let counts = SampleCounts { hit: 1.0, next_event: 1.0, connect: 0.5, light_trace: 1000.0, merge: Some(m) };
    let k = 5;
    let n_of = |s: usize| {
        if s <= 1 {
            1.0
        } else if s == k {
            1000.0
        } else {
            0.5
        }
    };
    let mut total: f64 = (0..=k).map(|s| n_of(s) * brute_force_pdf(&p, s)).sum();
    let mut merges = vec![];
    for i in 1..k - 1 {
        // light side 0..i with emission density at 0, camera side i..=k, times the photon's density and area
        let mut pdf = 1.0f64;
        for j in 0..=k {
            pdf *= if j < i { p.from_light[j] } else { p.from_camera[j] } as f64;
        }
        let v = 1000.0 * pdf * p.from_light[i] as f64 * 2e-3;
        merges.push(v);
        total += v;
    }
    for (idx, i) in (1..k - 1).enumerate() {
        let w = weight(&p, &counts, Technique::Merge(i)) as f64;
        assert!((w - merges[idx] / total).abs() < 1e-4, "merge {i}: {w} vs {}", merges[idx] / total);
    }
}

#[test]
fn delta_vertices_exclude_adjacent_connections() {
    let mut p = random_path(1, 6, false);
    p.delta[2] = true;
    p.from_light[3] = 0.0;
    p.from_camera[1] = 0.0;
    let counts = SampleCounts { hit: 1.0, next_event: 1.0, connect: 1.0, light_trace: 1.0, merge: None };
    assert_eq!(weight(&p, &counts, Technique::Connect(2)), 0.0, "connection into the delta vertex");
    assert_eq!(weight(&p, &counts, Technique::Connect(3)), 0.0, "connection out of the delta vertex");
    assert!(weight(&p, &counts, Technique::Connect(4)) > 0.0);
}

#[test]
fn a_light_that_cannot_be_hit_gives_emitter_hits_no_weight() {
    let mut p = random_path(2, 4, false);
    p.from_camera[0] = 0.0; // a point light
    p.emitter_hittable = false;
    let w = weight(&p, &SampleCounts::PATH_TRACING, Technique::NextEvent);
    assert_eq!(w, 1.0);
    assert_eq!(weight(&p, &SampleCounts::PATH_TRACING, Technique::EmitterHit), 0.0);
}

/// The O(k) correlation-aware factors equal the per-vertex definition up to rounding, on
/// paths up to the longest the integrators build.
#[test]
fn correlation_factors_match_the_per_vertex_definition() {
    for light_paths in [1.0, 1000.0] {
        let merge = MergeCounts {
            area: 1e-3,
            count: light_paths,
            correlation_aware: true,
            correlation_area: 3e-2,
            light_paths,
        };
        for len in [2, 3, 4, 7, 12, MAX_VERTICES] {
            for seed in 0..50 {
                let p = random_path(seed, len, seed % 2 == 0);
                let mut all = [0.0f32; MAX_VERTICES];
                correlation_factors(&p, &merge, &mut all);
                for i in 1..(len - 1).saturating_sub(1) {
                    let one = correlation_factor(&p, i, &merge);
                    assert!(
                        (all[i] - one).abs() <= 1e-5 * one,
                        "len {len} seed {seed} vertex {i}: {} vs {one}",
                        all[i]
                    );
                }
            }
        }
    }
}
