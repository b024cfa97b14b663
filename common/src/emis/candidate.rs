//! Candidate strategies (docs/emis.md, D1): image level ν ∈ {0.25, 0.5, 0.75, 1, 2}
//! light paths per pixel and c ∈ {0, 1, 2, 4, 8} connections per camera vertex; pixel level
//! merging on or off; plus pure path tracing. 51 candidates for VCM, 26 for BDPT. The sets are
//! configuration, not constants.

use serde::{Deserialize, Serialize};

/// One strategy: how many samples each technique takes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// Light paths per pixel per iteration (0 for path tracing).
    pub nu: f32,
    /// Connections per camera vertex.
    pub connections: u32,
    /// Merging at camera vertices.
    pub merge: bool,
}

impl Candidate {
    /// Pure path tracing: no light paths, no connections, no merging.
    pub const PATH_TRACING: Candidate = Candidate { nu: 0.0, connections: 0, merge: false };

    /// Whether this is pure path tracing.
    pub fn is_path_tracing(&self) -> bool {
        self.nu == 0.0
    }

    /// N = ⌊ν·P⌋ light paths for `pixels` pixels.
    pub fn light_paths(&self, pixels: u32) -> u32 {
        (self.nu as f64 * pixels as f64).floor() as u32
    }
}

/// The values the candidates are built from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CandidateConfig {
    /// Light paths per pixel (each > 0).
    pub nu: Vec<f32>,
    /// Connections per camera vertex.
    pub connections: Vec<u32>,
    /// Whether merging candidates exist (VCM) or not (BDPT).
    pub merging: bool,
}

impl CandidateConfig {
    /// The VCM set of docs/emis.md, D1.
    pub fn vcm() -> Self {
        CandidateConfig { nu: vec![0.25, 0.5, 0.75, 1.0, 2.0], connections: vec![0, 1, 2, 4, 8], merging: true }
    }

    /// The BDPT set of docs/emis.md, D1.
    pub fn bdpt() -> Self {
        CandidateConfig { merging: false, ..Self::vcm() }
    }

    /// The path-tracing start's reduced set (docs/emis.md §1.2, the reference's `OnDemandVcm`):
    /// ν ∈ {0.5, 1}, c ∈ {0, 1}, merging as in `self`, plus path tracing: 9 candidates for
    /// VCM, 5 for BDPT. A few strategies likely to beat path tracing where anything does,
    /// judged from path-tracing moments alone.
    pub fn reduced(&self) -> Self {
        CandidateConfig { nu: vec![0.5, 1.0], connections: vec![0, 1], merging: self.merging }
    }

    /// The most light paths per pixel a candidate traces.
    pub fn max_nu(&self) -> f64 {
        self.nu.iter().fold(0.0f64, |m, &nu| m.max(nu as f64))
    }

    /// The Cartesian product ν × c × {merge off, on}, then pure path tracing (exactly once).
    pub fn candidates(&self) -> Vec<Candidate> {
        let merges: &[bool] = if self.merging { &[false, true] } else { &[false] };
        let mut out = Vec::new();
        for &nu in &self.nu {
            for &connections in &self.connections {
                for &merge in merges {
                    out.push(Candidate { nu, connections, merge });
                }
            }
        }
        out.push(Candidate::PATH_TRACING);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decision_one_gives_51_and_26_candidates_with_one_path_tracer() {
        let vcm = CandidateConfig::vcm().candidates();
        let bdpt = CandidateConfig::bdpt().candidates();
        assert_eq!(vcm.len(), 51);
        assert_eq!(bdpt.len(), 26);
        assert_eq!(vcm.iter().filter(|c| c.is_path_tracing()).count(), 1);
        assert_eq!(bdpt.iter().filter(|c| c.is_path_tracing()).count(), 1);
        assert!(bdpt.iter().all(|c| !c.merge));
        let unique: std::collections::HashSet<String> = vcm.iter().map(|c| format!("{c:?}")).collect();
        assert_eq!(unique.len(), 51, "no duplicates");
    }

    #[test]
    fn the_reduced_set_has_9_and_5_candidates_with_one_path_tracer() {
        let vcm = CandidateConfig::vcm().reduced().candidates();
        let bdpt = CandidateConfig::bdpt().reduced().candidates();
        assert_eq!((vcm.len(), bdpt.len()), (9, 5));
        assert!(vcm.iter().chain(&bdpt).all(|c| [0.0, 0.5, 1.0].contains(&c.nu) && c.connections <= 1));
        assert_eq!(vcm.iter().filter(|c| c.merge).count(), 4);
        assert!(bdpt.iter().all(|c| !c.merge));
        assert_eq!(vcm.iter().chain(&bdpt).filter(|c| c.is_path_tracing()).count(), 2);
    }

    #[test]
    fn light_path_count_is_floor_of_nu_times_pixels() {
        let c = Candidate { nu: 0.75, connections: 1, merge: false };
        assert_eq!(c.light_paths(256 * 256), 49152);
        assert_eq!(Candidate { nu: 0.25, ..c }.light_paths(3), 0);
        assert_eq!(Candidate::PATH_TRACING.light_paths(1000), 0);
    }
}
