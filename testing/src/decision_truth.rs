//! The brute-force truth the decision-quality tests judge the optimiser by
//! (docs/decisions/0018-decision-quality-tests.md): per scene, every image-level candidate of
//! `emis-vcm` (each (ν, c) with one fixed merge mask, and path tracing) rendered on its own.
//!
//! A candidate's truth is its work-normalised error, the relMSE × time an equal-time render
//! sees: the per-iteration variance of each pixel relative to the converged reference,
//! (σ² / (ref² + 1e-4)) averaged over channels, then over pixels without the top 0.1 % as the
//! equal-time benchmark averages relMSE, times the CPU seconds one iteration takes. The mean
//! over every pixel is kept beside it: a few pixels' rare, bright paths decide that one, and
//! it moves several-fold with the seed. `tessera bench decision-truth` measures both once
//! and writes them as JSON; the tests read that file, so they neither render the candidates
//! nor time anything.
//!
//! ```
//! use tessera_testing::decision_truth::{CandidateTruth, SceneTruth};
//! let c = |nu, connections, relative_variance, seconds| CandidateTruth {
//!     nu, connections, relative_variance, trimmed_variance: relative_variance,
//!     seeds: Vec::new(), relmse_k: relative_variance, seconds, model_cost: 1.0,
//! };
//! let scene = SceneTruth {
//!     scene: "toy".into(),
//!     mean_merge_probability: 0.0,
//!     candidates: vec![c(0.0, 0, 2.0, 1.0), c(1.0, 1, 1.0, 3.0)],
//! };
//! assert_eq!(scene.regret(0.0, 0), Some(1.0));
//! assert_eq!(scene.regret(1.0, 1), Some(1.5));
//! ```

use serde::{Deserialize, Serialize};

/// The cached truth of every scene, and how it was made.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DecisionTruth {
    /// Image width the scenes were rendered at.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Iterations each candidate rendered for its variance, per seed.
    pub iterations: u32,
    /// Independent runs of those iterations per candidate, pooled into its variance.
    pub seeds: u32,
    /// Iterations each candidate rendered per timing round.
    pub timed_iterations: u32,
    /// Iterations of the `vcm` pilot whose moments chose the fixed merge mask.
    pub pilot_iterations: u32,
    /// The command that wrote the file.
    pub command: String,
    /// Per scene.
    pub scenes: Vec<SceneTruth>,
}

/// One scene's candidates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneTruth {
    /// The scene's folder name (`scenes/NAME/scene.xml`).
    pub scene: String,
    /// Mean χ of the merge mask every bidirectional candidate rendered with.
    pub mean_merge_probability: f64,
    /// Every image-level candidate.
    pub candidates: Vec<CandidateTruth>,
}

/// One image-level candidate, measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CandidateTruth {
    /// Light paths per pixel (0: path tracing).
    pub nu: f32,
    /// Connections per camera vertex.
    pub connections: u32,
    /// Per-iteration variance relative to the reference, the relMSE × iterations it converges
    /// to, over every seed's iterations and every pixel.
    pub relative_variance: f64,
    /// The same without the pixels above the 99.9th percentile, as the equal-time benchmark
    /// drops them: the figure regrets are judged by.
    pub trimmed_variance: f64,
    /// Both figures from each seed's iterations alone: how noisy they are.
    pub seeds: Vec<SeedVariance>,
    /// relMSE of the candidate's image against the reference × iterations: the relative
    /// variance plus the bias and the reference's own noise, as a cross-check.
    pub relmse_k: f64,
    /// CPU seconds per iteration (the least over the timing rounds).
    pub seconds: f64,
    /// The cost model's mean pixel cost with the pilot's statistics (camera-vertex units).
    pub model_cost: f64,
}

/// One seed's share of a candidate's iterations.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeedVariance {
    /// [`CandidateTruth::relative_variance`] from this seed's iterations.
    pub relative_variance: f64,
    /// [`CandidateTruth::trimmed_variance`] from this seed's iterations.
    pub trimmed_variance: f64,
}

impl CandidateTruth {
    /// relMSE × time, with the benchmark's dropped pixels: lower is better.
    pub fn work_normalised(&self) -> f64 {
        self.trimmed_variance * self.seconds
    }

    /// relMSE over every pixel × time.
    pub fn untrimmed_work_normalised(&self) -> f64 {
        self.relative_variance * self.seconds
    }

    /// relMSE × the cost model's cost, the figure the optimiser predicts.
    pub fn model_normalised(&self) -> f64 {
        self.trimmed_variance * self.model_cost
    }
}

impl SceneTruth {
    /// The candidate (ν, c), if the scene has it.
    pub fn candidate(&self, nu: f32, connections: u32) -> Option<&CandidateTruth> {
        let pt = nu == 0.0;
        self.candidates.iter().find(|c| c.nu == nu && (pt || c.connections == connections))
    }

    /// The work-normalised error of (ν, c) over the best candidate's (1 = the best choice).
    pub fn regret(&self, nu: f32, connections: u32) -> Option<f64> {
        self.regret_by(nu, connections, CandidateTruth::work_normalised)
    }

    /// [`SceneTruth::regret`] with every pixel counted.
    pub fn untrimmed_regret(&self, nu: f32, connections: u32) -> Option<f64> {
        self.regret_by(nu, connections, CandidateTruth::untrimmed_work_normalised)
    }

    /// [`SceneTruth::regret`] with time replaced by the cost model's cost.
    pub fn model_regret(&self, nu: f32, connections: u32) -> Option<f64> {
        self.regret_by(nu, connections, CandidateTruth::model_normalised)
    }

    fn regret_by(&self, nu: f32, connections: u32, figure: fn(&CandidateTruth) -> f64) -> Option<f64> {
        let best = self.candidates.iter().map(figure).fold(f64::INFINITY, f64::min);
        self.candidate(nu, connections).map(|c| figure(c) / best)
    }

    /// The candidate with the lowest work-normalised error.
    pub fn best(&self) -> Option<&CandidateTruth> {
        self.candidates.iter().min_by(|a, b| a.work_normalised().total_cmp(&b.work_normalised()))
    }
}

impl DecisionTruth {
    /// The scene called `name`.
    pub fn scene(&self, name: &str) -> Option<&SceneTruth> {
        self.scenes.iter().find(|s| s.scene == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn candidate(nu: f32, connections: u32, relative_variance: f64, seconds: f64) -> CandidateTruth {
        CandidateTruth {
            nu,
            connections,
            relative_variance: 2.0 * relative_variance,
            trimmed_variance: relative_variance,
            seeds: Vec::new(),
            relmse_k: relative_variance,
            seconds,
            model_cost: 2.0 * seconds,
        }
    }

    #[test]
    fn regret_is_relative_to_the_best_work_normalised_error() {
        let scene = SceneTruth {
            scene: "toy".into(),
            mean_merge_probability: 0.0,
            candidates: vec![candidate(0.0, 0, 4.0, 1.0), candidate(0.5, 1, 1.0, 2.0), candidate(1.0, 1, 1.0, 5.0)],
        };
        assert_eq!(scene.regret(0.5, 1), Some(1.0));
        assert_eq!(scene.regret(1.0, 1), Some(2.5));
        // path tracing is found whatever c the decision reports with it
        assert_eq!(scene.regret(0.0, 3), Some(2.0));
        assert_eq!(scene.model_regret(0.0, 0), Some(2.0));
        assert_eq!(scene.untrimmed_regret(1.0, 1), Some(2.5));
        assert_eq!(scene.regret(2.0, 1), None);
        assert_eq!(scene.best().map(|c| c.nu), Some(0.5));
    }
}
