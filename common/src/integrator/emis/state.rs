//! The coordinator's side of `emis-*`: merges the pilot data of full-frame iteration ranges,
//! and at each update barrier denoises the image, runs the optimiser and switches the strategy.
//! Pure and synchronous (the farm calls it between passes); reports every update.

use super::{EmisConfig, EmisMethod, PilotData, Strategy};
use crate::integrator::guides::GuideBuffer;
use crate::integrator::vcm::MergeMask;
use crate::mis::candidate::Candidate;
use crate::mis::cost::{PathStatistics, StatisticsSums};
use crate::mis::denoise::{Guides, denoised_intensity};
use crate::mis::filter::Image;
use crate::mis::moments::MomentBuffer;
use crate::mis::optimize::{ImageLevelScore, OptimizerInput, optimize};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Instant;

/// One update, as reported in the JSON report.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct UpdateReport {
    /// Iterations rendered before the update.
    pub iteration: u32,
    /// Chosen light paths per pixel (0: path tracing).
    pub nu: f32,
    /// Chosen connections per camera vertex.
    pub connections: u32,
    /// Mean merge probability χ over the image.
    pub mean_merge_probability: f64,
    /// Fraction of pixels with χ > 0.1.
    pub merging_pixels: f64,
    /// The statistics the costs were computed with.
    pub statistics: PathStatistics,
    /// Every image-level candidate: mean relative moment, mean cost, and their product.
    pub candidates: Vec<ScoreReport>,
    /// Time of the denoiser, ms.
    pub denoise_ms: f64,
    /// Time of the optimiser, ms.
    pub optimize_ms: f64,
}

/// One image-level candidate's prediction.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ScoreReport {
    /// ν (0: path tracing).
    pub nu: f32,
    /// c.
    pub connections: u32,
    /// Predicted mean relative second moment.
    pub relative_moment: f64,
    /// Mean cost per pixel (camera-vertex units).
    pub cost: f64,
    /// Their product (lower is better).
    pub work_normalised: f64,
}

impl From<&ImageLevelScore> for ScoreReport {
    fn from(s: &ImageLevelScore) -> Self {
        ScoreReport {
            nu: s.nu,
            connections: s.connections,
            relative_moment: s.relative_moment,
            cost: s.cost,
            work_normalised: s.relative_moment * s.cost,
        }
    }
}

/// Merged pilot data, the current strategy and the decisions so far.
pub struct EmisState {
    /// The configuration.
    pub config: EmisConfig,
    /// The candidates, in the moment buffer's order.
    pub candidates: Vec<Candidate>,
    /// What the next iterations render with.
    pub strategy: Strategy,
    /// Merged moments.
    pub moments: MomentBuffer,
    /// Merged statistics.
    pub statistics: StatisticsSums,
    /// Merged guides.
    pub guides: GuideBuffer,
    /// Updates run so far.
    pub updates_done: usize,
    /// Whether moments are still being collected.
    collecting: bool,
    /// The last update's per-pixel relative moment of the chosen strategy.
    pub relative_moment: Option<Image>,
    /// One report per update.
    pub reports: Vec<UpdateReport>,
}

impl EmisState {
    /// The state before the pilot.
    pub fn new(config: EmisConfig, width: u32, height: u32) -> Self {
        let candidates = config.candidates.candidates();
        let collecting = !config.updates.is_empty();
        EmisState {
            strategy: Strategy::pilot(config.method),
            moments: MomentBuffer::new(width, height, candidates.len()),
            statistics: StatisticsSums::default(),
            guides: GuideBuffer::new(width, height),
            candidates,
            config,
            updates_done: 0,
            collecting,
            relative_moment: None,
            reports: Vec::new(),
        }
    }

    /// Whether the next iterations should collect moments.
    pub fn collecting(&self) -> bool {
        self.collecting
    }

    /// Stops collecting (no update will follow).
    pub fn stop_collecting(&mut self) {
        self.collecting = false;
    }

    /// The iteration count of the next update barrier, if any.
    pub fn next_update(&self) -> Option<u32> {
        if self.collecting { self.config.updates.get(self.updates_done).copied() } else { None }
    }

    /// Whether an update is due once `iterations` iterations are done.
    pub fn update_due(&self, iterations: u32) -> bool {
        self.next_update() == Some(iterations)
    }

    /// Adds a pilot range's data.
    pub fn absorb(&mut self, pilot: &PilotData) -> Result<(), String> {
        self.moments.merge(&pilot.moments)?;
        self.guides.merge(&pilot.guides)?;
        self.statistics.merge(&pilot.statistics);
        Ok(())
    }

    /// Runs an update on the image so far (per-pixel means, row-major): denoise, optimise,
    /// switch the strategy. After the last configured update, moments are no longer collected.
    pub fn update(&mut self, image: &[[f32; 3]], iteration: u32) -> &UpdateReport {
        let (w, h) = (self.moments.width as usize, self.moments.height as usize);
        let t0 = Instant::now();
        let (albedo, normal, depth) = self.guides.means();
        let guides = Guides { albedo: &albedo, normal: &normal, depth: &depth };
        let intensity = denoised_intensity(w, h, image, &guides, &self.config.denoise);
        let denoise_ms = t0.elapsed().as_secs_f64() * 1e3;
        let t1 = Instant::now();
        let statistics = self.statistics.statistics((w * h) as u32);
        let decision = optimize(&OptimizerInput {
            candidates: &self.candidates,
            moments: &self.moments,
            image: &intensity,
            statistics,
            constants: self.config.constants,
            filters: self.config.filters,
        });
        let optimize_ms = t1.elapsed().as_secs_f64() * 1e3;
        let mask = &decision.merge_mask.data;
        let report = UpdateReport {
            iteration,
            nu: decision.nu,
            connections: decision.connections,
            mean_merge_probability: mask.iter().map(|&v| v as f64).sum::<f64>() / mask.len().max(1) as f64,
            merging_pixels: mask.iter().filter(|&&v| v > 0.1).count() as f64 / mask.len().max(1) as f64,
            statistics,
            candidates: decision.scores.iter().map(ScoreReport::from).collect(),
            denoise_ms,
            optimize_ms,
        };
        tracing::info!(
            iteration,
            nu = decision.nu,
            connections = decision.connections,
            merging = report.merging_pixels,
            "emis update"
        );
        self.strategy = Strategy {
            nu: decision.nu,
            connections: decision.connections,
            merge: match self.config.method {
                EmisMethod::Bdpt => None,
                EmisMethod::Vcm => Some(MergeMask::PerPixel(Arc::new(decision.merge_mask.data.clone()))),
            },
        };
        self.relative_moment = Some(decision.relative_moment);
        self.updates_done += 1;
        if self.updates_done >= self.config.updates.len() {
            self.collecting = false;
        }
        self.reports.push(report);
        self.reports.last().expect("invariant: just pushed")
    }

    /// The per-pixel merge probability the final strategy uses (0 without merging).
    pub fn merge_mask(&self) -> Vec<f32> {
        let n = (self.moments.width * self.moments.height) as usize;
        match &self.strategy.merge {
            None => vec![0.0; n],
            Some(m) => (0..n as u32).map(|p| m.at(p)).collect(),
        }
    }
}
