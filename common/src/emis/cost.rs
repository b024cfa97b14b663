//! The cost heuristic (docs/emis.md §2, "current heuristic"): the cost of a pixel under a
//! candidate, in units of one camera-path vertex with its NEE shadow ray, including the
//! image-wide work (light tracing, photon-map build) amortised over the pixels.
//!
//! C_j = L̄c·k_cam + L̄c·c·(k_con + k_con_walk·(L̄c + L̄l)) + ν·L̄l·(k_lt + k_lt_walk·L̄l)
//!       + [map built]·(B + χ·(Q + S)), with
//! B = k_build·L̄l·ν·ln(N·L̄l), Q = k_query·L̄c·ln(N·L̄l) (both 0 when N·L̄l ≤ 1) and
//! S = k_shade·φ·L̄c·N; pure path tracing costs L̄c·k_pt.
//!
//! The two walk terms and k_pt go beyond the reference (docs/emis.md, D8): Tessera
//! computes MIS weights by walking the path's full pdf arrays, so every light-tracing splat
//! costs in proportion to the light path's length and every connection to the whole path's;
//! and when path tracing wins it is rendered by the `pt` integrator, cheaper per camera vertex
//! than the bidirectional engine the other candidates run in. The reference constants set the
//! walks to 0 and k_pt to 1, which is exactly the reference formula.

use super::candidate::Candidate;
use crate::integrator::observer::WorkTimes;
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
    /// A light vertex's MIS walk, per vertex of its light path (L̄l).
    pub light_vertex_walk: f64,
    /// A connection's MIS walk, per vertex of the joined path (L̄c + L̄l).
    pub connection_walk: f64,
    /// A camera vertex of pure path tracing, rendered by the `pt` integrator.
    pub path_tracing: f64,
}

/// Which constants the heuristic uses. The default is [`CostModel::Calibrated`] (see
/// [`CostConstants::calibrated`] for why). The reference implementation's constants
/// ([`CostConstants::reference`]) chose worse and were retired as a model (decision 0002).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum CostModel {
    /// [`CostConstants::calibrated`]: fitted to this renderer's measured times.
    #[default]
    #[cfg_attr(
        feature = "clap",
        value(help = "Fitted to this renderer's measured times (`tessera bench calibrate-costs`)")
    )]
    Calibrated,
    /// Measured per job from the pilot's own work times ([`super::measured`]), with
    /// [`CostConstants::calibrated`] for what they cannot measure. Decisions then vary with
    /// the machine's timing from run to run, and a farm's with its workers'.
    #[cfg_attr(
        feature = "clap",
        value(
            help = "Measured per job from the pilot's own work times on the machine that renders it, the calibrated constants filling in what cannot be measured; decisions then vary with timing from run to run"
        )
    )]
    Measured,
}

impl CostModel {
    /// The constants of this model (for [`CostModel::Measured`], those it falls back on).
    pub fn constants(self) -> CostConstants {
        match self {
            CostModel::Calibrated | CostModel::Measured => CostConstants::calibrated(),
        }
    }
}

impl CostConstants {
    /// The reference implementation's "current heuristic" constants (docs/emis.md §2): no
    /// longer a model renders use, kept as the baseline `tessera bench calibrate-costs` and the
    /// optimiser's tests compare against.
    pub fn reference() -> Self {
        CostConstants {
            camera_vertex: 1.0,
            light_vertex: 1.0,
            connection: 0.3,
            photon_shading: 0.25,
            query: 0.045,
            build: 0.175,
            light_vertex_walk: 0.0,
            connection_walk: 0.0,
            path_tracing: 1.0,
        }
    }

    /// Constants fitted to this renderer (docs/emis.md, D8) by
    /// `tessera bench calibrate-costs`. The build and query terms fit to 0: their cost is
    /// absorbed by the per-photon term. Why they are the default: on this renderer the
    /// reference constants price merging too high and connections too low, and these choose
    /// better against measured errors and at equal time
    /// (docs/decisions/0002-calibrated-cost-constants.md).
    pub fn calibrated() -> Self {
        CostConstants {
            camera_vertex: 1.0,
            light_vertex: 0.202,
            connection: 0.086,
            photon_shading: 1.821,
            query: 0.0,
            build: 0.0,
            light_vertex_walk: 0.196,
            connection_walk: 0.062,
            path_tracing: 0.762,
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
    /// The time the work took (for costs measured per job; not part of equality across
    /// runs).
    pub times: WorkTimes,
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
        self.times += counters.times;
    }

    /// Adds another worker's sums.
    pub fn merge(&mut self, o: &StatisticsSums) {
        // saturating: sums of sent counts must not wrap (the coordinator bounds each as well)
        self.iterations = self.iterations.saturating_add(o.iterations);
        self.camera_vertices = self.camera_vertices.saturating_add(o.camera_vertices);
        self.light_paths = self.light_paths.saturating_add(o.light_paths);
        self.light_vertices = self.light_vertices.saturating_add(o.light_vertices);
        self.merge_queries = self.merge_queries.saturating_add(o.merge_queries);
        self.photons_per_path += o.photons_per_path;
        self.times += o.times;
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
    CostTerms::new(k, s, candidate, map_built, pixels).at(chi)
}

/// [`pixel_cost`] as a function of χ, with everything else evaluated once: the optimiser
/// prices every pixel of every image-level candidate, and the map terms take a logarithm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CostTerms {
    /// Camera vertices, connections and light paths.
    fixed: f64,
    /// Building the photon map.
    build: f64,
    /// Querying it and shading the photons found, at χ = 1.
    merge: f64,
}

impl CostTerms {
    /// The terms of `candidate`'s cost (see [`pixel_cost`]).
    pub fn new(k: &CostConstants, s: &PathStatistics, candidate: &Candidate, map_built: bool, pixels: u32) -> Self {
        let (lc, ll) = (s.camera_vertices, s.light_vertices);
        if candidate.is_path_tracing() {
            return CostTerms { fixed: lc * k.path_tracing, build: 0.0, merge: 0.0 };
        }
        let nu = candidate.nu as f64;
        let n = candidate.light_paths(pixels) as f64;
        let connection = k.connection + k.connection_walk * (lc + ll);
        let light_vertex = k.light_vertex + k.light_vertex_walk * ll;
        let fixed = lc * k.camera_vertex + lc * candidate.connections as f64 * connection + light_vertex * ll * nu;
        if !(map_built && n > 0.0) {
            return CostTerms { fixed, build: 0.0, merge: 0.0 };
        }
        let log = if n * ll > 1.0 { (n * ll).ln() } else { 0.0 };
        let query = k.query * lc * log;
        let shade = k.photon_shading * s.photons_per_query_per_path * lc * n;
        CostTerms { fixed, build: k.build * ll * nu * log, merge: query + shade }
    }

    /// The terms of each of `candidates` as the optimiser prices them: the photon map is built
    /// for a candidate that merges and for no other (as the calibration fits it), so BDPT's
    /// candidates, and VCM's non-merging ones, pay nothing for it.
    pub fn of_candidates(k: &CostConstants, s: &PathStatistics, candidates: &[Candidate], pixels: u32) -> Vec<Self> {
        candidates.iter().map(|c| CostTerms::new(k, s, c, c.merge, pixels)).collect()
    }

    /// The cost of building the photon map (0 for a candidate that builds none).
    pub fn build(&self) -> f64 {
        self.build
    }

    /// The cost at merge probability `chi`.
    #[inline]
    pub fn at(&self, chi: f64) -> f64 {
        self.fixed + (self.build + chi * self.merge)
    }
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
        s.add_iteration(
            50,
            150,
            &PathCounters { camera_vertices: 350, merge_queries: 10, photons_found: 40, ..Default::default() },
        );
        s.add_iteration(
            100,
            250,
            &PathCounters { camera_vertices: 250, merge_queries: 30, photons_found: 60, ..Default::default() },
        );
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
    fn walk_terms_and_path_tracing_by_hand() {
        let k = CostConstants {
            camera_vertex: 1.0,
            light_vertex: 0.2,
            connection: 0.1,
            photon_shading: 0.0,
            query: 0.0,
            build: 0.0,
            light_vertex_walk: 0.05,
            connection_walk: 0.03,
            path_tracing: 0.75,
        };
        let s = PathStatistics { camera_vertices: 4.0, light_vertices: 3.0, photons_per_query_per_path: 1e-5 };
        let c = Candidate { nu: 0.5, connections: 2, merge: false };
        // camera 4; connections 4·2·(0.1 + 0.03·7); light vertices 0.5·3·(0.2 + 0.05·3)
        let expected = 4.0 + 8.0 * (0.1 + 0.03 * 7.0) + 1.5 * (0.2 + 0.05 * 3.0);
        assert!((pixel_cost(&k, &s, &c, 0.0, false, 1000) - expected).abs() < 1e-12);
        assert!((pixel_cost(&k, &s, &Candidate::PATH_TRACING, 0.0, false, 1000) - 3.0).abs() < 1e-12);
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
            let pt = pixel_cost(&k, &s, &Candidate::PATH_TRACING, 1.0, true, 65536);
            assert!((pt - 6.0 * k.path_tracing).abs() < 1e-12);
        }
    }
}
