//! Cost constants measured per job (docs/emis.md, D8; issue 21, item 6): the work
//! times the pilot's own iterations record ([`WorkTimes`], on the machine that renders them,
//! the observer's time left out) turned into the heuristic's constants, in units of that
//! machine's camera vertex, so that decisions rest on what this scene costs here rather than
//! on constants fitted once on other scenes.
//!
//! - camera vertex: the unit (intersection, emitter hit, next-event estimate, next direction);
//! - light vertex: tracing and splatting time per stored vertex (the walk term folded in, as
//!   the job's L̄l is fixed);
//! - connection: time per connection tried (walk folded in likewise);
//! - merge: time per query fitted as a + b·photons by least squares over the timed queries:
//!   b is the per-photon shading cost, a the query's, per ln(map size) as the heuristic has it;
//! - photon-map build: time per photon per ln(map size);
//! - path tracing: the `pt` integrator's time per camera vertex in the probe the job's first
//!   pilot call renders beside it (the vertices counted by the bidirectional engine in the
//!   same iteration).
//!
//! A term with too few timed events keeps the fallback's value for this job's statistics.

use super::cost::CostConstants;
use crate::integrator::observer::WorkTimes;

/// Fewest timed events a term is measured from.
pub const MIN_EVENTS: u64 = 64;

/// The constants `times` measure, the terms they cannot measure taken from `fallback`; `None`
/// without enough timed camera vertices.
pub fn measured_constants(times: &WorkTimes, fallback: &CostConstants) -> Option<CostConstants> {
    if times.camera_vertices < MIN_EVENTS || times.camera_ns == 0 {
        return None;
    }
    let unit = times.camera_ns as f64 / times.camera_vertices as f64;
    let per = |ns: u64, events: u64| (events >= MIN_EVENTS).then(|| ns as f64 / events as f64 / unit);
    let mut k = *fallback;
    k.camera_vertex = 1.0;
    if let Some(v) = per(times.light_ns, times.light_vertices) {
        (k.light_vertex, k.light_vertex_walk) = (v, 0.0);
    }
    if let Some(v) = per(times.connection_ns, times.connections) {
        (k.connection, k.connection_walk) = (v, 0.0);
    }
    if let Some(v) = per(times.path_tracing_ns, times.path_tracing_vertices) {
        k.path_tracing = v;
    }
    // the map holds the selectable photons of an iteration
    let map = if times.iterations > 0 { times.photons_built as f64 / times.iterations as f64 } else { 0.0 };
    let log = if map > 1.0 { map.ln() } else { 0.0 };
    if times.photons_built >= MIN_EVENTS && log > 0.0 {
        k.build = times.build_ns as f64 / times.photons_built as f64 / log / unit;
    }
    if times.queries >= MIN_EVENTS {
        let (a, b) = query_and_photon_ns(times);
        k.photon_shading = b / unit;
        k.query = if log > 0.0 { a / log / unit } else { 0.0 };
        if log == 0.0 {
            // no per-query term without a map size to scale it: the photons carry it
            k.photon_shading +=
                if times.photons > 0 { a * times.queries as f64 / times.photons as f64 / unit } else { 0.0 };
        }
    }
    Some(k)
}

/// The least-squares line time = a + b·photons over the timed merge queries, both terms kept
/// non-negative (through the origin when the intercept would be negative, flat when the slope
/// would be).
pub fn query_and_photon_ns(t: &WorkTimes) -> (f64, f64) {
    let n = t.queries as f64;
    if n == 0.0 {
        return (0.0, 0.0);
    }
    let (mean_p, mean_t) = (t.photons as f64 / n, t.merge_ns as f64 / n);
    let var = t.photons_squared / n - mean_p * mean_p;
    let cov = t.merge_ns_photons / n - mean_t * mean_p;
    let b = if var > 1e-9 * t.photons_squared.max(1.0) / n { cov / var } else { 0.0 };
    match (b, mean_t - b * mean_p) {
        (b, _) if b <= 0.0 => (mean_t, 0.0),
        (_, a) if a < 0.0 => (0.0, if t.photons_squared > 0.0 { t.merge_ns_photons / t.photons_squared } else { 0.0 }),
        (b, a) => (a, b),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Times made from known per-event costs come back as those costs over the camera
    /// vertex's: 100 ns per vertex, 50 per light vertex, 30 per connection, 200 per build
    /// photon per ln(map), queries of 40 + 7·photons.
    #[test]
    fn known_costs_come_back_as_constants() {
        let queries: Vec<u64> = (0..200).map(|i| i % 13).collect();
        let merge: Vec<u64> = queries.iter().map(|p| 40 + 7 * p).collect();
        let map = 1000u64;
        let t = WorkTimes {
            iterations: 2,
            light_vertices: 3000,
            light_ns: 3000 * 50,
            photons_built: 2 * map,
            build_ns: (2.0 * map as f64 * 200.0 * (map as f64).ln()) as u64,
            camera_vertices: 5000,
            camera_ns: 5000 * 100,
            connections: 4000,
            connection_ns: 4000 * 30,
            queries: queries.len() as u64,
            photons: queries.iter().sum(),
            photons_squared: queries.iter().map(|&p| (p * p) as f64).sum(),
            merge_ns: merge.iter().sum(),
            merge_ns_photons: queries.iter().zip(&merge).map(|(&p, &t)| (p * t) as f64).sum(),
            observer_ns: 12345,
            path_tracing_vertices: 2000,
            path_tracing_ns: 2000 * 70,
        };
        let fallback = CostConstants::calibrated();
        let k = measured_constants(&t, &fallback).unwrap();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1e-9);
        assert!(close(k.camera_vertex, 1.0) && close(k.light_vertex, 0.5) && close(k.connection, 0.3), "{k:?}");
        assert_eq!((k.light_vertex_walk, k.connection_walk), (0.0, 0.0));
        assert!(close(k.photon_shading, 0.07), "{k:?}");
        assert!(close(k.query, 0.4 / (map as f64).ln()), "{k:?}");
        assert!((k.build - 2.0).abs() < 1e-3, "{k:?}");
        assert!(close(k.path_tracing, 0.7), "{k:?}");
        let unprobed = WorkTimes { path_tracing_vertices: 0, path_tracing_ns: 0, ..t };
        let k = measured_constants(&unprobed, &fallback).unwrap();
        assert_eq!(k.path_tracing, fallback.path_tracing, "without a probe path tracing keeps the fallback's ratio");
    }

    /// Too few timed events keep the fallback's terms; too few camera vertices, nothing.
    #[test]
    fn sparse_times_fall_back() {
        let fallback = CostConstants::calibrated();
        let t = WorkTimes {
            camera_vertices: 1000,
            camera_ns: 1000 * 80,
            connections: 10,
            connection_ns: 999,
            ..Default::default()
        };
        let k = measured_constants(&t, &fallback).unwrap();
        assert_eq!(
            (k.connection, k.connection_walk, k.light_vertex, k.photon_shading),
            (fallback.connection, fallback.connection_walk, fallback.light_vertex, fallback.photon_shading)
        );
        assert!(measured_constants(&WorkTimes { camera_vertices: 10, camera_ns: 500, ..t }, &fallback).is_none());
    }

    #[test]
    fn the_query_fit_keeps_both_terms_non_negative() {
        let fit = |pairs: &[(u64, u64)]| {
            let t = WorkTimes {
                queries: pairs.len() as u64,
                photons: pairs.iter().map(|p| p.0).sum(),
                photons_squared: pairs.iter().map(|p| (p.0 * p.0) as f64).sum(),
                merge_ns: pairs.iter().map(|p| p.1).sum(),
                merge_ns_photons: pairs.iter().map(|p| (p.0 * p.1) as f64).sum(),
                ..Default::default()
            };
            query_and_photon_ns(&t)
        };
        assert_eq!(fit(&[(1, 30), (3, 10)]), (20.0, 0.0), "a falling line is flat");
        let (a, b) = fit(&[(1, 10), (3, 60)]);
        assert!(a == 0.0 && b > 0.0, "a negative intercept goes through the origin: {a} {b}");
        assert_eq!(fit(&[(2, 10), (2, 30)]), (20.0, 0.0), "one photon count: the mean");
    }
}
