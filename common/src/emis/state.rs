//! The coordinator's side of `emis-*`: merges the pilot data of full-frame iteration ranges,
//! and at each update barrier denoises the image, runs the optimiser and switches the strategy.
//! Pure and synchronous (the farm calls it between passes); reports every update.
//!
//! A path-tracing start ([`super::PilotStart::PathTracing`]) decides from the reduced candidate set
//! with global merging until a bidirectional candidate wins (when no later update could
//! weigh the start, by more than the share of the render a restart discards). That update
//! restarts: the caller starts a new image (the report says `restarted`), the moments and
//! statistics start again for the full set, [`EmisState::kept_from`] records the first
//! iteration of the new image, and [`EmisState::start`] keeps the old one, which the updates
//! after it weigh ([`super::start`]) and [`EmisState::image`] combines with the new.

use super::candidate::Candidate;
use super::cost::{CostConstants, PathStatistics, StatisticsSums};
use super::denoise::{Guides, denoised_intensity};
use super::filter::Image;
use super::guides::GuideBuffer;
use super::measured::measured_constants;
use super::moments::MomentBuffer;
use super::optimize::{Decision, ImageLevelScore, Incumbent, MergeScope, OptimizerInput, optimize};
use super::schedule::RestartTotal;
use super::start::{KeptStart, relative_mean_square, start_weight};
use super::{CandidateSet, EmisConfig, EmisMethod, PilotData, Strategy};
use crate::film::Film;
use crate::integrator::path::connections::Connections;
use crate::integrator::path::merge::MergeMask;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Instant;

/// The recorded iterations an update needs before path tracing may settle
/// ([`EmisConfig::settle_margin`]).
pub const SETTLE_RECORDINGS: u32 = 2;

/// One update, as reported in the JSON report.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct UpdateReport {
    /// Iterations rendered before the update.
    pub iteration: u32,
    /// The candidate set decided from (the path-tracing start's reduced one, or the full).
    pub reduced: bool,
    /// A path-tracing start ended: the iterations so far left the image, to be combined
    /// with it at the end by the weight later updates estimate.
    pub restarted: bool,
    /// Path tracing won this update and the one before by [`EmisConfig::settle_margin`], on
    /// [`SETTLE_RECORDINGS`] recorded iterations or more: no moments are collected and no
    /// update runs after this one.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub settled: bool,
    /// After a restart: the weight of one start iteration against one later iteration this
    /// update estimated (0: the start is left out).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_weight: Option<f64>,
    /// Full set: the margin by which a cheaper (ν, c) had to beat the one being rendered
    /// ([`EmisConfig::incumbent_margin`]); `candidates` show whether one did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub incumbent_margin: Option<f64>,
    /// Chosen light paths per pixel (0: path tracing).
    pub nu: f32,
    /// Chosen connections per camera vertex (0 with per-pixel connections).
    pub connections: u32,
    /// With per-pixel connections: the mean expected count over the image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_connections: Option<f64>,
    /// Mean merge probability χ over the image.
    pub mean_merge_probability: f64,
    /// Fraction of pixels with χ > 0.1.
    pub merging_pixels: f64,
    /// The statistics the costs were computed with.
    pub statistics: PathStatistics,
    /// With costs measured per job: the constants measured (absent while too little was
    /// timed, when the fallback's were used).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_constants: Option<CostConstants>,
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
    /// c (absent: per pixel, as the connection mask says).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub connections: Option<u32>,
    /// Reduced set only: whether the candidate merges (everywhere).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub merge: Option<bool>,
    /// Predicted mean relative second moment.
    pub relative_moment: f64,
    /// Mean cost per pixel (camera-vertex units).
    pub cost: f64,
    /// Their product (lower is better).
    pub work_normalised: f64,
}

impl UpdateReport {
    /// The reduced set's best bidirectional moment × cost over path tracing's: below 1 a
    /// bidirectional candidate wins; NaN where both are infinite or the set is the full one.
    pub fn path_tracing_margin(&self) -> f64 {
        let best = |bidirectional: bool| {
            let scores = self.candidates.iter().filter(|c| (c.nu > 0.0) == bidirectional);
            scores.map(|c| c.work_normalised).fold(f64::INFINITY, f64::min)
        };
        if self.reduced { best(true) / best(false) } else { f64::NAN }
    }
}

impl From<&ImageLevelScore> for ScoreReport {
    fn from(s: &ImageLevelScore) -> Self {
        ScoreReport {
            nu: s.nu,
            connections: s.connections,
            merge: s.merge,
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
    /// Which candidates the moments are for.
    pub candidate_set: CandidateSet,
    /// The candidates, in the moment buffer's order.
    pub candidates: Vec<Candidate>,
    /// The first iteration of the image (0 unless a path-tracing start restarted; the
    /// iterations before it are in [`EmisState::start`]).
    pub kept_from: u32,
    /// The path-tracing start's image, once a restart ended it.
    pub start: Option<KeptStart>,
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
        let (strategy, candidate_set) = config.initial();
        let candidates = config.candidates_of(candidate_set);
        let collecting = !config.updates.is_empty();
        EmisState {
            strategy,
            candidate_set,
            kept_from: 0,
            start: None,
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

    /// Whether [`EmisState::absorb`] would take `pilot`: buffers of this state's shape.
    pub fn check(&self, pilot: &PilotData) -> Result<(), String> {
        self.moments.check_shape(&pilot.moments)?;
        self.guides.check_shape(&pilot.guides)
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
    /// When the report says `restarted`, the caller must start a new film: the iterations
    /// before `iteration` now live in [`EmisState::start`]. `restart_total` is how many
    /// iterations the render would run in all if this update restarted it: when no update
    /// would follow and pay before its end to weigh the start (under a time budget, at the
    /// winner's pace), a path-tracing start switches only to a candidate that beats path
    /// tracing by more than the share of them the restart discards, and renders that
    /// candidate's own merge decision.
    pub fn update(&mut self, image: &[[f32; 3]], iteration: u32, restart_total: RestartTotal) -> &UpdateReport {
        let t0 = Instant::now();
        let intensity = self.image_estimate(image);
        let denoise_ms = t0.elapsed().as_secs_f64() * 1e3;
        let t1 = Instant::now();
        let model = self.cost_model();
        let (mut decision, followed) = self.choose(&intensity, &model, iteration, restart_total);
        let optimize_ms = t1.elapsed().as_secs_f64() * 1e3;
        let restarted = self.candidate_set == CandidateSet::Reduced && decision.nu > 0.0;
        // a restart that a full-set update follows pilots it as the method's own pilot does,
        // merging everywhere: the global decision comes from path-tracing samples that rarely
        // hold the paths merging is for, and the iterations up to that update stay in the image
        // (docs/decisions/0032-light-probe-and-restart-share.md)
        if restarted && followed && self.config.method == EmisMethod::Vcm {
            decision.merge_mask = Image::filled(intensity.width, intensity.height, 1.0);
        }
        let mut report = self.report(&decision, &intensity, &model, iteration, restarted);
        (report.denoise_ms, report.optimize_ms) = (denoise_ms, optimize_ms);
        self.adopt(decision, restarted, image, iteration);
        self.updates_done += 1;
        // a restart that no paying update follows renders its winner to the end: recording
        // the first call after it, before the render loop sees the new pace, buys nothing
        let unfollowed = restarted && !followed;
        if self.updates_done >= self.config.updates.len() || report.settled || unfollowed {
            self.collecting = false;
        }
        self.reports.push(report);
        self.reports.last().expect("invariant: just pushed")
    }

    /// The image estimate Ī the moments are made relative to: `image` (per-pixel means)
    /// denoised as the candidate set's settings say.
    fn image_estimate(&self, image: &[[f32; 3]]) -> Image {
        let (w, h) = (self.moments.width as usize, self.moments.height as usize);
        let denoise = self.config.denoise_of(self.candidate_set);
        // without à-trous levels the guides are not read (and not recorded)
        let (albedo, normal, depth) = if denoise.levels > 0 { self.guides.means() } else { Default::default() };
        let guides = Guides { albedo: &albedo, normal: &normal, depth: &depth };
        denoised_intensity(w, h, image, &guides, denoise)
    }

    /// What the optimiser prices candidates with: the path statistics, the constants (measured
    /// per job where configured and possible) and the incumbent's margin.
    fn cost_model(&self) -> CostModelInput {
        let pixels = self.moments.width * self.moments.height;
        let statistics = self.statistics.statistics(pixels);
        let measured = if self.config.measured_costs {
            measured_constants(&self.statistics.times, &self.config.constants)
        } else {
            None
        };
        let reduced = self.candidate_set == CandidateSet::Reduced;
        let incumbent = (!reduced && self.config.incumbent_margin > 0.0).then(|| Incumbent {
            nu: self.strategy.nu,
            connections: match self.strategy.connections {
                Connections::Fixed(c) => Some(c),
                Connections::PerPixel(_) => None,
            },
            margin: Incumbent::margin_after(self.config.incumbent_margin, self.moments.iterations),
        });
        CostModelInput { statistics, constants: measured.unwrap_or(self.config.constants), measured, incumbent }
    }

    /// The optimiser's decision after `iteration`, and whether an update of the full set
    /// follows a restart into it. A path-tracing start's restart discards the start unless
    /// such an update follows to weigh it; then a candidate must beat path tracing by more
    /// than the share of the render the restart discards.
    fn choose(
        &self,
        intensity: &Image,
        model: &CostModelInput,
        iteration: u32,
        restart_total: RestartTotal,
    ) -> (Decision, bool) {
        let reduced = self.candidate_set == CandidateSet::Reduced;
        let decide = |restart_share: f64| {
            optimize(&OptimizerInput {
                candidates: &self.candidates,
                moments: &self.moments,
                image: intensity,
                statistics: model.statistics,
                constants: model.constants,
                filters: self.config.filters,
                merge_scope: if reduced { MergeScope::Global } else { MergeScope::PerPixel },
                connection_scope: self.config.connection_scope,
                restart_share,
                incumbent: model.incumbent,
            })
        };
        let share = iteration as f64 / restart_total.at_current_pace().max(1) as f64;
        let weighing = self.config.updates.iter().copied().find(|&u| u > iteration);
        let kept = reduced && weighing.is_some_and(|u| restart_total.pays(u, restart_total.at_current_pace() as f64));
        let decision = decide(if reduced && !kept { share } else { 0.0 });
        let merging = self.config.method == EmisMethod::Vcm;
        if kept && decision.nu > 0.0 && !reaches(&decision, restart_total, iteration, weighing, merging) {
            // at the winner's pace the render would end before that update, or too soon
            // after it for it to pay
            return (decide(share), false);
        }
        (decision, kept)
    }

    /// The update's report (its timings filled in by the caller), with whether path tracing
    /// settles: after two clear wins later recordings cost more than the rare switch they
    /// find; one recording is too few, a caustic can look like path tracing's
    /// (docs/decisions/0041). Weighs a kept path-tracing start by the decision.
    fn report(
        &mut self,
        decision: &Decision,
        intensity: &Image,
        model: &CostModelInput,
        iteration: u32,
        restarted: bool,
    ) -> UpdateReport {
        let reduced = self.candidate_set == CandidateSet::Reduced;
        let mask = &decision.merge_mask.data;
        let start_weight = match (&mut self.start, decision.chosen) {
            (Some(start), Some(chosen)) if !reduced => {
                let k = start_weight(&decision.scores, chosen, relative_mean_square(&intensity.data));
                start.weight = Some(k);
                Some(k)
            }
            _ => None,
        };
        let mut report = UpdateReport {
            iteration,
            reduced,
            restarted,
            settled: false,
            start_weight,
            incumbent_margin: model.incumbent.map(|i| i.margin),
            nu: decision.nu,
            connections: decision.connections,
            mean_connections: decision.connection_mask.as_ref().map(|m| m.mean()),
            mean_merge_probability: mask.iter().map(|&v| v as f64).sum::<f64>() / mask.len().max(1) as f64,
            merging_pixels: mask.iter().filter(|&&v| v > 0.1).count() as f64 / mask.len().max(1) as f64,
            statistics: model.statistics,
            measured_constants: model.measured,
            candidates: decision.scores.iter().map(ScoreReport::from).collect(),
            denoise_ms: 0.0,
            optimize_ms: 0.0,
        };
        let wins = |r: &UpdateReport| r.reduced && !r.restarted && r.path_tracing_margin() >= self.config.settle_margin;
        report.settled =
            wins(&report) && self.reports.last().is_some_and(wins) && self.moments.iterations >= SETTLE_RECORDINGS;
        tracing::info!(
            iteration,
            nu = decision.nu,
            connections = decision.connections,
            mean_connections = report.mean_connections,
            merging = report.merging_pixels,
            restarted,
            settled = report.settled,
            "emis update"
        );
        report
    }

    /// Switches to `decision`'s strategy; on a restart, sets the path-tracing start (`image`,
    /// the iterations before `iteration`) aside and starts the moments again for the full set.
    fn adopt(&mut self, decision: Decision, restarted: bool, image: &[[f32; 3]], iteration: u32) {
        let (w, h) = (self.moments.width, self.moments.height);
        let merge = match (self.config.method, self.candidate_set) {
            (EmisMethod::Bdpt, _) => None,
            // merging everywhere or nowhere
            (EmisMethod::Vcm, CandidateSet::Reduced) => {
                Some(MergeMask::Constant(decision.merge_mask.data.first().copied().unwrap_or(0.0)))
            }
            (EmisMethod::Vcm, CandidateSet::Full) => Some(MergeMask::PerPixel(Arc::new(decision.merge_mask.data))),
        };
        let connections = match decision.connection_mask {
            Some(mask) => Connections::PerPixel(Arc::new(mask.data)),
            None => Connections::Fixed(decision.connections),
        };
        self.strategy = Strategy { nu: decision.nu, connections, merge };
        self.relative_moment = Some(decision.relative_moment);
        if restarted {
            // the path-tracing start is over: what follows is sampled with a bidirectional
            // strategy, and later updates choose from the full set on its moments alone
            self.candidate_set = CandidateSet::Full;
            self.candidates = self.config.candidates_of(CandidateSet::Full);
            self.moments = MomentBuffer::new(w, h, self.candidates.len());
            // path tracing's probe is not run again: its time stays for the later updates
            let probe = self.statistics.times;
            self.statistics = StatisticsSums::default();
            self.statistics.times.path_tracing_vertices = probe.path_tracing_vertices;
            self.statistics.times.path_tracing_ns = probe.path_tracing_ns;
            self.kept_from = iteration;
            self.start = Some(KeptStart { image: image.to_vec(), iterations: iteration, weight: None });
        }
    }

    /// The render's image from `film`, which holds the iterations from
    /// [`EmisState::kept_from`] on: combined with a kept path-tracing start once an update
    /// weighed it.
    pub fn image(&self, film: &Film) -> Vec<[f32; 3]> {
        let after = film.average();
        match &self.start {
            Some(start) if start.weight.is_some() => start.combine(&after, &film.count),
            _ => after,
        }
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

/// What an update prices candidates with (see [`EmisState::update`]).
struct CostModelInput {
    statistics: PathStatistics,
    constants: CostConstants,
    /// The constants measured per job, when they were.
    measured: Option<CostConstants>,
    incumbent: Option<Incumbent>,
}

/// Whether a render restarted into `decision`'s winner after `iteration` would still run the
/// update at `weighing`: reach it before `restart_total` (scaled by the winner's cost per
/// iteration over path tracing's under a time budget) and, as the render loop demands before
/// it collects for it, find it pays ([`RestartTotal::pays`]); an update reached but skipped
/// would leave the pilot's strategy to the end and the start unweighed
/// (docs/decisions/0032-light-probe-and-restart-share.md). With
/// `merging` the winner is priced as rendered until that update: its ν and c merging
/// everywhere (the same record).
fn reaches(
    decision: &Decision,
    restart_total: RestartTotal,
    iteration: u32,
    weighing: Option<u32>,
    merging: bool,
) -> bool {
    let Some(update) = weighing else { return false };
    let cost = |s: Option<&ImageLevelScore>| s.map(|s| s.cost).filter(|c| c.is_finite() && *c > 0.0);
    let pt = cost(decision.scores.iter().find(|s| s.nu == 0.0));
    let chosen = decision.chosen.and_then(|c| decision.scores.get(c));
    let merged = |w: &ImageLevelScore| {
        decision.scores.iter().find(|s| s.nu == w.nu && s.connections == w.connections && s.merge == Some(true))
    };
    let rendered = if merging { chosen.and_then(merged).or(chosen) } else { chosen };
    let winner = cost(rendered);
    let dearer = match (pt, winner) {
        (Some(pt), Some(winner)) => winner / pt,
        _ => 1.0,
    };
    restart_total.pays(update, restart_total.at_cost_ratio(iteration, dearer))
}

#[cfg(test)]
#[path = "state_tests.rs"]
mod tests;
