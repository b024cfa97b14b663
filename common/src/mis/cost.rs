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

impl Default for CostConstants {
    fn default() -> Self {
        CostConstants {
            camera_vertex: 1.0,
            light_vertex: 1.0,
            connection: 0.3,
            photon_shading: 0.25,
            query: 0.045,
            build: 0.175,
        }
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
    fn hand_computed_value() {
        let k = CostConstants::default();
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
        let k = CostConstants::default();
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
