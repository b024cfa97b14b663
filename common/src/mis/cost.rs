//! The cost heuristic (emis-spec §2, "current heuristic"): the cost of a pixel under a
//! candidate, in units of one camera-path vertex with its NEE shadow ray, including the
//! image-wide work (light tracing, photon-map build) amortised over the pixels.
//!
//! C_j = L̄c·k_cam + L̄c·c·k_con + k_lt·L̄l·ν + [map built]·(B + χ·(Q + S)), with
//! B = k_build·L̄l·ν·ln(N·L̄l), Q = k_query·L̄c·ln(N·L̄l) (both 0 when N·L̄l ≤ 1) and
//! S = k_shade·φ·L̄c·N.

use super::candidate::Candidate;
use serde::{Deserialize, Serialize};

/// The heuristic's relative weights.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CostConstants {
    /// A camera vertex with its NEE shadow ray (the unit).
    pub camera_vertex: f64,
    /// A light vertex with its light-tracing shadow ray.
    pub light_vertex: f64,
    /// One connection (shadow ray and two BSDF evaluations).
    pub connection: f64,
    /// Shading one photon found by a merge query.
    pub photon_shading: f64,
    /// A merge query, per ln(photons).
    pub query: f64,
    /// Building the photon map, per photon per ln(photons).
    pub build: f64,
}

/// Which constants the heuristic uses.
///
/// The default is the reference's, although the calibrated constants predict the measured cost
/// far better: at equal time (`tessera bench --equal-time 20 --threads 1`, six scenes,
/// 2026-11-21, the second core busy, baselines from the first of two runs) the reference
/// constants gave emis-vcm 1.26× over vcm and emis-bdpt 1.10× over bdpt (geometric means), the
/// calibrated ones 1.22× and 0.99×. The reference constants overprice bidirectional work,
/// which happens to offset the pilot's overestimate of path tracing's second moment in the
/// scenes where path tracing wins (veach-mis, cornell-box, env-lit); with honest costs that
/// overestimate decides.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CostModel {
    /// [`CostConstants::calibrated`]: fitted to this renderer's measured times.
    Calibrated,
    /// [`CostConstants::reference`]: the reference implementation's constants (emis-spec §2).
    #[default]
    Reference,
}

impl CostModel {
    /// The constants of this model.
    pub fn constants(self) -> CostConstants {
        match self {
            CostModel::Calibrated => CostConstants::calibrated(),
            CostModel::Reference => CostConstants::reference(),
        }
    }
}

impl CostConstants {
    /// The reference implementation's "current heuristic" constants (emis-spec §2).
    pub fn reference() -> Self {
        CostConstants {
            camera_vertex: 1.0,
            light_vertex: 1.0,
            connection: 0.3,
            photon_shading: 0.25,
            query: 0.045,
            build: 0.175,
        }
    }

    /// Constants fitted to this renderer (decision 8) by `tessera bench --calibrate-costs`
    /// (2 iterations × fastest of 2 interleaved rounds per configuration, 1 thread, the six
    /// test scenes, 2026-11-21, with another benchmark loading the second core). Against the
    /// measured cost of 9 configurations × 6 scenes, the reference constants are off by
    /// 105 % rms (max 335 %: they make merging 2–4× too expensive in simple scenes and light
    /// vertices ~1.8× too expensive); these are off by 23 % rms (max 57 %, connections at
    /// c = 4 in the long-path scenes, whose cost grows with path length, which the formula does
    /// not model). The fit puts the photon-map build and query terms at 0: their cost is
    /// indistinguishable from (and absorbed by) the per-photon term here.
    pub fn calibrated() -> Self {
        CostConstants {
            camera_vertex: 1.0,
            light_vertex: 0.56,
            connection: 0.44,
            photon_shading: 1.86,
            query: 0.0,
            build: 0.0,
        }
    }
}

impl Default for CostConstants {
    fn default() -> Self {
        CostModel::default().constants()
    }
}

/// Path statistics measured during the pilot (with the reference's fallbacks).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PathStatistics {
    /// Mean camera-path vertices per pixel (L̄c; 5 when unknown).
    pub camera_vertices: f64,
    /// Mean stored vertices per light path, the emitter vertex included (L̄l; L̄c when no light
    /// paths were traced).
    pub light_vertices: f64,
    /// Photons found per merge query per light path (φ; 1e-7 when unknown).
    pub photons_per_query_per_path: f64,
}

impl Default for PathStatistics {
    fn default() -> Self {
        PathStatistics { camera_vertices: 5.0, light_vertices: 5.0, photons_per_query_per_path: 1e-7 }
    }
}

/// Path statistics summed over iterations (and over workers: every field adds up).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StatisticsSums {
    /// Iterations summed.
    pub iterations: u64,
    /// Σ camera-path surface vertices.
    pub camera_vertices: u64,
    /// Σ light paths traced.
    pub light_paths: u64,
    /// Σ light vertices stored, emitter vertices included.
    pub light_vertices: u64,
    /// Σ merge queries that ran.
    pub merge_queries: u64,
    /// Σ over iterations of photons found / N of that iteration.
    pub photons_per_path: f64,
}

impl StatisticsSums {
    /// Adds one iteration with `light_paths` light paths storing `light_vertices` vertices.
    pub fn add_iteration(
        &mut self,
        light_paths: u32,
        light_vertices: u64,
        counters: &crate::integrator::observer::PathCounters,
    ) {
        self.iterations += 1;
        self.camera_vertices += counters.camera_vertices;
        self.light_paths += light_paths as u64;
        self.light_vertices += light_vertices;
        self.merge_queries += counters.merge_queries;
        if light_paths > 0 {
            self.photons_per_path += counters.photons_found as f64 / light_paths as f64;
        }
    }

    /// Adds another worker's sums.
    pub fn merge(&mut self, o: &StatisticsSums) {
        self.iterations += o.iterations;
        self.camera_vertices += o.camera_vertices;
        self.light_paths += o.light_paths;
        self.light_vertices += o.light_vertices;
        self.merge_queries += o.merge_queries;
        self.photons_per_path += o.photons_per_path;
    }

    /// The means for `pixels` pixels, with the reference's fallbacks: L̄c = 5 without
    /// statistics, L̄l = L̄c without light paths, φ = 1e-7 without merges.
    pub fn statistics(&self, pixels: u32) -> PathStatistics {
        let camera_vertices = if self.iterations > 0 && self.camera_vertices > 0 {
            self.camera_vertices as f64 / (self.iterations as f64 * pixels as f64)
        } else {
            5.0
        };
        let light_vertices =
            if self.light_paths > 0 { self.light_vertices as f64 / self.light_paths as f64 } else { camera_vertices };
        let phi = if self.merge_queries > 0 && self.photons_per_path > 0.0 {
            self.photons_per_path / self.merge_queries as f64
        } else {
            1e-7
        };
        PathStatistics { camera_vertices, light_vertices, photons_per_query_per_path: phi }
    }
}

/// Cost of one pixel under `candidate` with merge probability `chi`, for `pixels` pixels;
/// `map_built` says whether the photon map is built at all this iteration.
pub fn pixel_cost(
    k: &CostConstants,
    s: &PathStatistics,
    candidate: &Candidate,
    chi: f64,
    map_built: bool,
    pixels: u32,
) -> f64 {
    let nu = candidate.nu as f64;
    let n = candidate.light_paths(pixels) as f64;
    let (lc, ll) = (s.camera_vertices, s.light_vertices);
    let mut cost = lc * k.camera_vertex + lc * candidate.connections as f64 * k.connection + k.light_vertex * ll * nu;
    if map_built && n > 0.0 {
        let log = if n * ll > 1.0 { (n * ll).ln() } else { 0.0 };
        let build = k.build * ll * nu * log;
        let query = k.query * lc * log;
        let shade = k.photon_shading * s.photons_per_query_per_path * lc * n;
        cost += build + chi * (query + shade);
    }
    cost
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statistics_are_means_with_fallbacks() {
        use crate::integrator::observer::PathCounters;
        let mut s = StatisticsSums::default();
        assert_eq!(s.statistics(100), PathStatistics::default());
        // two iterations of 100 pixels: 350 and 250 camera vertices; 50 and 100 light paths
        // storing 150 and 250 vertices; 10 queries finding 40 photons, then 30 finding 60
        s.add_iteration(50, 150, &PathCounters { camera_vertices: 350, merge_queries: 10, photons_found: 40 });
        s.add_iteration(100, 250, &PathCounters { camera_vertices: 250, merge_queries: 30, photons_found: 60 });
        let st = s.statistics(100);
        assert!((st.camera_vertices - 3.0).abs() < 1e-12);
        assert!((st.light_vertices - 400.0 / 150.0).abs() < 1e-12);
        assert!((st.photons_per_query_per_path - (40.0 / 50.0 + 60.0 / 100.0) / 40.0).abs() < 1e-12);
        // a path-tracing pilot: no light paths, no merges
        let mut pt = StatisticsSums::default();
        pt.add_iteration(0, 0, &PathCounters { camera_vertices: 420, ..Default::default() });
        let st = pt.statistics(100);
        assert_eq!((st.camera_vertices, st.light_vertices, st.photons_per_query_per_path), (4.2, 4.2, 1e-7));
        // merging sums equals summing everything
        let mut a = StatisticsSums::default();
        a.merge(&s);
        a.merge(&pt);
        assert_eq!(a.iterations, 3);
        assert_eq!(a.camera_vertices, 1020);
    }

    #[test]
    fn hand_computed_value() {
        let k = CostConstants::reference();
        let s = PathStatistics { camera_vertices: 4.0, light_vertices: 3.0, photons_per_query_per_path: 1e-5 };
        let c = Candidate { nu: 1.0, connections: 2, merge: true };
        let pixels = 1000;
        let log = (1000.0f64 * 3.0).ln();
        let expected =
            4.0 + 4.0 * 2.0 * 0.3 + 3.0 + 0.175 * 3.0 * log + 0.5 * (0.045 * 4.0 * log + 0.25 * 1e-5 * 4.0 * 1000.0);
        assert!((pixel_cost(&k, &s, &c, 0.5, true, pixels) - expected).abs() < 1e-9);
    }

    #[test]
    fn cost_grows_with_every_count_and_path_tracing_has_no_map_terms() {
        for k in [CostConstants::reference(), CostConstants::calibrated()] {
            let s = PathStatistics { camera_vertices: 6.0, light_vertices: 4.0, photons_per_query_per_path: 1e-6 };
            let base = Candidate { nu: 0.5, connections: 1, merge: true };
            let cost = |c: Candidate, chi: f64| pixel_cost(&k, &s, &c, chi, true, 65536);
            assert!(cost(Candidate { nu: 1.0, ..base }, 1.0) > cost(base, 1.0));
            assert!(cost(Candidate { connections: 4, ..base }, 1.0) > cost(base, 1.0));
            assert!(cost(base, 1.0) > cost(base, 0.2));
            // pure path tracing: camera vertices only, no build or query term even with a map
            assert!((pixel_cost(&k, &s, &Candidate::PATH_TRACING, 1.0, true, 65536) - 6.0).abs() < 1e-12);
        }
    }
}
