//! Calibration of the cost heuristic's constants from measured render times
//! (docs/emis.md, D8: the constants fitted to measured times on this renderer).
//!
//! Every term of [`pixel_cost`] is a constant times a feature of the
//! candidate and the scene's statistics, so a measured cost (a configuration's time per
//! iteration divided by the time of one camera vertex) is linear in the constants. Given such
//! measurements over several scenes and configurations, [`fit_constants`] finds the
//! constants (the camera vertex stays the unit) that minimise the squared *relative* error,
//! keeping every constant non-negative.

use tessera_common::emis::candidate::Candidate;
use tessera_common::emis::cost::{CostConstants, PathStatistics, pixel_cost};

/// How many constants the fit determines (all but the camera vertex, the unit, and path
/// tracing's, which is a measured ratio of its own).
pub const FITTED_TERMS: usize = 7;

/// Term `pick` of `k`, in [`cost_features`]' order.
fn term_mut(k: &mut CostConstants, pick: usize) -> &mut f64 {
    match pick {
        0 => &mut k.light_vertex,
        1 => &mut k.light_vertex_walk,
        2 => &mut k.connection,
        3 => &mut k.connection_walk,
        4 => &mut k.build,
        5 => &mut k.query,
        _ => &mut k.photon_shading,
    }
}

/// The constants with term `pick` at `value` and every other, the unit included, at 0.
fn with_term(pick: usize, value: f64) -> CostConstants {
    let mut k = CostConstants {
        camera_vertex: 0.0,
        light_vertex: 0.0,
        connection: 0.0,
        photon_shading: 0.0,
        query: 0.0,
        build: 0.0,
        light_vertex_walk: 0.0,
        connection_walk: 0.0,
        path_tracing: 0.0,
    };
    *term_mut(&mut k, pick) = value;
    k
}

/// The fitted terms' features of a (bidirectional) candidate on a scene, in the order light
/// vertex, light-vertex walk, connection, connection walk, build, query, photon shading.
pub fn cost_features(s: &PathStatistics, candidate: &Candidate, pixels: u32) -> [f64; FITTED_TERMS] {
    let chi = if candidate.merge { 1.0 } else { 0.0 };
    std::array::from_fn(|pick| pixel_cost(&with_term(pick, 1.0), s, candidate, chi, candidate.merge, pixels))
}

/// The configurations to time on every scene (the timing runs of docs/emis.md §2): the
/// bidirectional engine at ν = 0 first (the unit), light tracing at ν = 0.25, 1 and 2,
/// connections c = 1 and 4 (at ν = 1) and c = 4 (at ν = 0.25), merging at ν = 0.5, 1 and 2, and
/// connections with merging. Path tracing's own integrator is timed beside them for
/// [`CostConstants::path_tracing`].
pub fn calibration_configurations() -> Vec<Candidate> {
    let c = |nu: f32, connections: u32, merge: bool| Candidate { nu, connections, merge };
    vec![
        c(0.0, 0, false),
        c(0.25, 0, false),
        c(1.0, 0, false),
        c(2.0, 0, false),
        c(1.0, 1, false),
        c(1.0, 4, false),
        c(0.25, 4, false),
        c(0.5, 0, true),
        c(1.0, 0, true),
        c(2.0, 0, true),
        c(1.0, 1, true),
    ]
}

/// One measurement: the scene's statistics, the candidate, and its measured cost per pixel in
/// camera-vertex units.
#[derive(Clone, Debug, PartialEq)]
pub struct CostSample {
    /// The scene's path statistics.
    pub statistics: PathStatistics,
    /// What was rendered.
    pub candidate: Candidate,
    /// Pixels of the image.
    pub pixels: u32,
    /// Measured cost per pixel, in units of one camera vertex.
    pub measured: f64,
}

/// Least-squares fit of the non-unit constants to `samples` (bidirectional candidates; path
/// tracing samples are skipped), weighting every residual by the measured cost (relative
/// errors). Constants that would come out negative are fixed at 0 and the rest refitted.
/// `path_tracing` is passed through. `None` without samples or with a singular system.
pub fn fit_constants(samples: &[CostSample], path_tracing: f64) -> Option<CostConstants> {
    let samples: Vec<CostSample> = samples.iter().filter(|s| !s.candidate.is_path_tracing()).cloned().collect();
    let mut active = [true; FITTED_TERMS];
    loop {
        let k = solve(&samples, &active)?;
        match (0..FITTED_TERMS).find(|&i| active[i] && k[i] < 0.0) {
            Some(i) => active[i] = false,
            None => {
                let mut fitted = CostConstants { camera_vertex: 1.0, path_tracing, ..with_term(0, 0.0) };
                for (pick, &value) in k.iter().enumerate() {
                    *term_mut(&mut fitted, pick) = value;
                }
                return Some(fitted);
            }
        }
    }
}

/// Solves the weighted normal equations over the active constants (inactive ones are 0).
fn solve(samples: &[CostSample], active: &[bool; FITTED_TERMS]) -> Option<[f64; FITTED_TERMS]> {
    let idx: Vec<usize> = (0..FITTED_TERMS).filter(|&i| active[i]).collect();
    let n = idx.len();
    let mut a = vec![vec![0.0; n + 1]; n];
    for s in samples.iter().filter(|s| s.measured > 0.0) {
        let f = cost_features(&s.statistics, &s.candidate, s.pixels);
        // residual (L̄c + f·k − m) / m: regress f/m on (m − L̄c)/m
        let w = 1.0 / s.measured;
        let target = (s.measured - s.statistics.camera_vertices) * w;
        for (r, &i) in idx.iter().enumerate() {
            for (c, &j) in idx.iter().enumerate() {
                a[r][c] += f[i] * w * f[j] * w;
            }
            a[r][n] += f[i] * w * target;
        }
    }
    // Gauss–Jordan elimination with partial pivoting
    for col in 0..n {
        let pivot = (col..n).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))?;
        if a[pivot][col].abs() < 1e-12 {
            return None;
        }
        a.swap(col, pivot);
        for row in 0..n {
            if row != col {
                let factor = a[row][col] / a[col][col];
                for c in col..=n {
                    a[row][c] -= factor * a[col][c];
                }
            }
        }
    }
    let mut k = [0.0; FITTED_TERMS];
    for (r, &i) in idx.iter().enumerate() {
        k[i] = a[r][n] / a[r][r];
    }
    Some(k)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenes() -> Vec<PathStatistics> {
        vec![
            PathStatistics { camera_vertices: 3.0, light_vertices: 4.0, photons_per_query_per_path: 2e-5 },
            PathStatistics { camera_vertices: 6.0, light_vertices: 2.5, photons_per_query_per_path: 1e-4 },
            PathStatistics { camera_vertices: 4.5, light_vertices: 6.0, photons_per_query_per_path: 5e-6 },
        ]
    }

    #[test]
    fn fit_recovers_the_constants_that_made_the_measurements() {
        let truth = CostConstants {
            camera_vertex: 1.0,
            light_vertex: 0.7,
            connection: 0.45,
            photon_shading: 0.3,
            query: 0.08,
            build: 0.12,
            light_vertex_walk: 0.2,
            connection_walk: 0.05,
            path_tracing: 0.8,
        };
        let pixels = 4096;
        let samples: Vec<CostSample> = scenes()
            .iter()
            .flat_map(|s| {
                calibration_configurations().into_iter().map(move |c| CostSample {
                    statistics: *s,
                    candidate: c,
                    pixels,
                    measured: pixel_cost(&truth, s, &c, if c.merge { 1.0 } else { 0.0 }, c.merge, pixels),
                })
            })
            .collect();
        let fit = fit_constants(&samples, 0.8).unwrap();
        for (a, b) in [
            (fit.light_vertex, truth.light_vertex),
            (fit.connection, truth.connection),
            (fit.photon_shading, truth.photon_shading),
            (fit.query, truth.query),
            (fit.build, truth.build),
            (fit.light_vertex_walk, truth.light_vertex_walk),
            (fit.connection_walk, truth.connection_walk),
            (fit.path_tracing, truth.path_tracing),
        ] {
            assert!((a - b).abs() < 1e-6, "fitted {a}, true {b}");
        }
        // a term the data say is free comes out 0, not negative
        let free = CostConstants { connection: 0.0, ..truth };
        let samples: Vec<CostSample> = samples
            .iter()
            .map(|s| {
                let chi = if s.candidate.merge { 1.0 } else { 0.0 };
                let measured = pixel_cost(&free, &s.statistics, &s.candidate, chi, s.candidate.merge, pixels) * 0.98;
                CostSample { measured, ..s.clone() }
            })
            .collect();
        let fit = fit_constants(&samples, 0.8).unwrap();
        assert!(fit.connection >= 0.0 && fit.connection < 0.05, "{fit:?}");
        assert!(fit_constants(&[], 1.0).is_none());
    }
}
