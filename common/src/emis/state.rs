//! The coordinator's side of `emis-*`: merges the pilot data of full-frame iteration ranges,
//! and at each update barrier denoises the image, runs the optimiser and switches the strategy.
//! Pure and synchronous (the farm calls it between passes); reports every update.
//!
//! A path-tracing start ([`PilotStart::PathTracing`]) decides from the reduced candidate set
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
use super::{CandidateSet, EmisConfig, EmisMethod, PilotData, PilotStart, Strategy};
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
    #[serde(default)]
    pub reduced: bool,
    /// A path-tracing start ended: the iterations so far left the image, to be combined
    /// with it at the end by the weight later updates estimate.
    #[serde(default)]
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
        let strategy = Strategy::initial(config.method, config.pilot);
        let candidate_set = match config.pilot {
            PilotStart::Bidirectional => CandidateSet::Full,
            PilotStart::PathTracing => CandidateSet::Reduced,
        };
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
    /// would follow before its end to weigh the start (under a time budget, at the winner's
    /// pace), a path-tracing start switches only to a candidate that beats path tracing by
    /// more than the share of them the restart discards.
    pub fn update(&mut self, image: &[[f32; 3]], iteration: u32, restart_total: RestartTotal) -> &UpdateReport {
        let (w, h) = (self.moments.width as usize, self.moments.height as usize);
        let t0 = Instant::now();
        let reduced = self.candidate_set == CandidateSet::Reduced;
        let denoise = self.config.denoise_of(self.candidate_set);
        // without à-trous levels the guides are not read (and not recorded)
        let (albedo, normal, depth) = if denoise.levels > 0 { self.guides.means() } else { Default::default() };
        let guides = Guides { albedo: &albedo, normal: &normal, depth: &depth };
        let intensity = denoised_intensity(w, h, image, &guides, denoise);
        let denoise_ms = t0.elapsed().as_secs_f64() * 1e3;
        let t1 = Instant::now();
        let statistics = self.statistics.statistics((w * h) as u32);
        let measured = if self.config.measured_costs {
            measured_constants(&self.statistics.times, &self.config.constants)
        } else {
            None
        };
        let constants = measured.unwrap_or(self.config.constants);
        let incumbent = (!reduced && self.config.incumbent_margin > 0.0).then(|| Incumbent {
            nu: self.strategy.nu,
            connections: match self.strategy.connections {
                Connections::Fixed(c) => Some(c),
                Connections::PerPixel(_) => None,
            },
            margin: Incumbent::margin_after(self.config.incumbent_margin, self.moments.iterations),
        });
        let decide = |restart_share: f64| {
            optimize(&OptimizerInput {
                candidates: &self.candidates,
                moments: &self.moments,
                image: &intensity,
                statistics,
                constants,
                filters: self.config.filters,
                merge_scope: if reduced { MergeScope::Global } else { MergeScope::PerPixel },
                connection_scope: self.config.connection_scope,
                restart_share,
                incumbent,
            })
        };
        // a restart discards the start unless an update of the full set follows to weigh it
        let share = iteration as f64 / restart_total.at_current_pace().max(1) as f64;
        let weighing = self.config.updates.iter().copied().find(|&u| u > iteration);
        let kept = reduced && weighing.is_some_and(|u| u < restart_total.at_current_pace());
        let mut decision = decide(if reduced && !kept { share } else { 0.0 });
        // whether an update of the full set follows a restart into the winner
        let mut followed = kept;
        if kept && decision.nu > 0.0 && !reaches(&decision, restart_total, iteration, weighing) {
            // at the winner's pace the render would end before that update
            decision = decide(share);
            followed = false;
        }
        let optimize_ms = t1.elapsed().as_secs_f64() * 1e3;
        let restarted = reduced && decision.nu > 0.0;
        // a restart that a full-set update follows pilots it as the method's own pilot does,
        // merging everywhere: the global decision comes from path-tracing samples that rarely
        // hold the paths merging is for, and the iterations up to that update stay in the image
        // (docs/decisions/0048-restart-pilots-with-merging.md)
        let pilot_merging = restarted && followed && self.config.method == EmisMethod::Vcm;
        if pilot_merging {
            decision.merge_mask = Image::filled(w, h, 1.0);
        }
        let mask = &decision.merge_mask.data;
        let recorded = self.moments.iterations;
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
            incumbent_margin: incumbent.map(|i| i.margin),
            nu: decision.nu,
            connections: decision.connections,
            mean_connections: decision.connection_mask.as_ref().map(|m| m.mean()),
            mean_merge_probability: mask.iter().map(|&v| v as f64).sum::<f64>() / mask.len().max(1) as f64,
            merging_pixels: mask.iter().filter(|&&v| v > 0.1).count() as f64 / mask.len().max(1) as f64,
            statistics,
            measured_constants: measured,
            candidates: decision.scores.iter().map(ScoreReport::from).collect(),
            denoise_ms,
            optimize_ms,
        };
        // after two clear wins later recordings cost more than the rare switch they find; one
        // recording is too few, a caustic can look like path tracing's (docs/decisions/0041)
        let wins = |r: &UpdateReport| r.reduced && !r.restarted && r.path_tracing_margin() >= self.config.settle_margin;
        report.settled = wins(&report) && self.reports.last().is_some_and(wins) && recorded >= SETTLE_RECORDINGS;
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
        let merge = match (self.config.method, reduced) {
            (EmisMethod::Bdpt, _) => None,
            // merging everywhere or nowhere
            (EmisMethod::Vcm, true) => Some(MergeMask::Constant(mask.first().copied().unwrap_or(0.0))),
            (EmisMethod::Vcm, false) => Some(MergeMask::PerPixel(Arc::new(decision.merge_mask.data.clone()))),
        };
        let connections = match decision.connection_mask {
            Some(mask) => Connections::PerPixel(Arc::new(mask.data)),
            None => Connections::Fixed(decision.connections),
        };
        self.strategy = Strategy { nu: decision.nu, connections, merge };
        if restarted {
            // the path-tracing start is over: what follows is sampled with a bidirectional
            // strategy, and later updates choose from the full set on its moments alone
            self.candidate_set = CandidateSet::Full;
            self.candidates = self.config.candidates_of(CandidateSet::Full);
            self.moments = MomentBuffer::new(w as u32, h as u32, self.candidates.len());
            self.statistics = StatisticsSums::default();
            self.kept_from = iteration;
            self.start = Some(KeptStart { image: image.to_vec(), iterations: iteration, weight: None });
        }
        self.relative_moment = Some(decision.relative_moment);
        self.updates_done += 1;
        if self.updates_done >= self.config.updates.len() || report.settled {
            self.collecting = false;
        }
        self.reports.push(report);
        self.reports.last().expect("invariant: just pushed")
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

/// Whether a render restarted into `decision`'s winner after `iteration` would still reach
/// the update at `weighing` (before `restart_total`, scaled by the winner's cost per iteration
/// over path tracing's under a time budget).
fn reaches(decision: &Decision, restart_total: RestartTotal, iteration: u32, weighing: Option<u32>) -> bool {
    let Some(update) = weighing else { return false };
    let cost = |s: Option<&ImageLevelScore>| s.map(|s| s.cost).filter(|c| c.is_finite() && *c > 0.0);
    let pt = cost(decision.scores.iter().find(|s| s.nu == 0.0));
    let winner = cost(decision.chosen.and_then(|c| decision.scores.get(c)));
    let dearer = match (pt, winner) {
        (Some(pt), Some(winner)) => winner / pt,
        _ => 1.0,
    };
    restart_total.at_cost_ratio(iteration, dearer) > update as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emis::cost::CostTerms;

    const SIDE: u32 = 16;

    /// One iteration of pilot data in which every pixel has `moment(candidate)`.
    fn pilot(state: &EmisState, moment: impl Fn(&Candidate) -> f32) -> PilotData {
        let k = state.candidates.len();
        let mut moments = MomentBuffer::new(SIDE, SIDE, k);
        for (i, sum) in moments.sums.iter_mut().enumerate() {
            *sum = moment(&state.candidates[i % k]);
        }
        moments.iterations = 1;
        let statistics =
            StatisticsSums { iterations: 1, camera_vertices: 3 * (SIDE * SIDE) as u64, ..Default::default() };
        PilotData { moments, statistics, guides: GuideBuffer::new(SIDE, SIDE) }
    }

    /// A path-tracing start: path tracing stays while it wins (nothing discarded); the update a
    /// bidirectional candidate wins restarts (full set, empty moments and statistics, the
    /// image kept from that iteration on) with that candidate's global merge decision.
    #[test]
    fn a_path_tracing_start_restarts_when_a_bidirectional_candidate_wins() {
        let config = EmisConfig { pilot: PilotStart::PathTracing, ..EmisConfig::new(EmisMethod::Vcm) };
        let mut state = EmisState::new(config, SIDE, SIDE);
        assert_eq!((state.candidate_set, state.candidates.len()), (CandidateSet::Reduced, 9));
        assert_eq!(state.strategy, Strategy::path_tracing_start(EmisMethod::Vcm));
        let image = vec![[0.5f32; 3]; (SIDE * SIDE) as usize];
        let pt_wins = pilot(&state, |c| if c.is_path_tracing() { 1.0 } else { 1e3 });
        state.absorb(&pt_wins).unwrap();
        let report = state.update(&image, 1, RestartTotal::Samples(64)).clone();
        assert!(report.reduced && !report.restarted, "{report:?}");
        assert_eq!(report.candidates.len(), 9);
        assert_eq!((state.strategy.nu, state.candidate_set, state.kept_from), (0.0, CandidateSet::Reduced, 0));
        assert_eq!(state.moments.iterations, 1, "moments are kept while path tracing stays");
        // merged with the first iteration's moments, the target's mean is 10× lower than pt's
        let target = Candidate { nu: 1.0, connections: 0, merge: true };
        state.absorb(&pilot(&state, |c| if *c == target { 1e-3 } else { 1e4 })).unwrap();
        let report = state.update(&image, 4, RestartTotal::Samples(64)).clone();
        assert!(report.reduced && report.restarted, "{report:?}");
        assert_eq!(
            state.strategy,
            Strategy { nu: 1.0, connections: Connections::Fixed(0), merge: Some(MergeMask::Constant(1.0)) },
            "merging everywhere"
        );
        assert_eq!((state.candidate_set, state.candidates.len(), state.kept_from), (CandidateSet::Full, 51, 4));
        assert_eq!((state.moments.iterations, state.moments.sums.len()), (0, 51 * (SIDE * SIDE) as usize));
        assert!(state.moments.sums.iter().all(|&s| s == 0.0));
        assert_eq!(state.statistics, StatisticsSums::default());
        assert!(state.collecting(), "the update after 16 follows, on the full set");
        let start = state.start.clone().expect("the start is kept");
        assert_eq!((start.image, start.iterations, start.weight), (image.clone(), 4, None));
        state.absorb(&pilot(&state, |c| if c.nu == 0.5 && c.connections == 2 { 1e-3 } else { 1.0 })).unwrap();
        let report = state.update(&image, 16, RestartTotal::Samples(64)).clone();
        assert!(!report.reduced && !report.restarted, "{report:?}");
        // pt's relative variance is about 3, the winner's almost 0: the start weighs little
        let k = state.start.as_ref().and_then(|s| s.weight).expect("the full set's update weighs the start");
        assert!(k > 0.0 && k < 1e-3 && report.start_weight == Some(k), "{k} {report:?}");
        assert_eq!((state.strategy.nu, &state.strategy.connections, state.kept_from), (0.5, &Connections::Fixed(2), 4));
        assert!(matches!(state.strategy.merge, Some(MergeMask::PerPixel(_))));
    }

    /// A restart into a candidate that merges nowhere renders with merging everywhere until
    /// the full set's update that follows it (the report says so); at the last update, which
    /// no other follows, it keeps the candidate's own global decision. emis-bdpt never merges.
    #[test]
    fn a_restart_pilots_the_next_update_with_merging_everywhere() {
        let image = vec![[0.5f32; 3]; (SIDE * SIDE) as usize];
        let target = Candidate { nu: 1.0, connections: 1, merge: false };
        let restart = |method: EmisMethod, updates: Vec<u32>| {
            let config = EmisConfig { pilot: PilotStart::PathTracing, updates, ..EmisConfig::new(method) };
            let mut state = EmisState::new(config, SIDE, SIDE);
            state.absorb(&pilot(&state, |c| if *c == target { 1e-3 } else { 1e4 })).unwrap();
            let report = state.update(&image, 4, RestartTotal::Samples(1000)).clone();
            assert!(report.restarted, "{report:?}");
            assert_eq!((state.strategy.nu, &state.strategy.connections), (1.0, &Connections::Fixed(1)));
            (state.strategy.merge, report.mean_merge_probability)
        };
        assert_eq!(restart(EmisMethod::Vcm, vec![4, 16]), (Some(MergeMask::Constant(1.0)), 1.0));
        assert_eq!(restart(EmisMethod::Vcm, vec![1, 4]), (Some(MergeMask::Constant(0.0)), 0.0));
        assert_eq!(restart(EmisMethod::Bdpt, vec![4, 16]), (None, 0.0));
    }

    /// A path-tracing start switches only to a candidate that beats path tracing by more than
    /// the share of the render a restart discards: 1.5× better is worth discarding 1 of 64
    /// iterations, not 16 of 20. A restart that an update of the full set follows (after 4 of
    /// 17, the next update after 16) discards nothing, and 1.05× better is enough; under a
    /// time budget of 17 iterations at pt's pace the dearer winner would not reach 16.
    #[test]
    fn a_restart_must_win_back_the_iterations_it_discards() {
        let config = EmisConfig { pilot: PilotStart::PathTracing, ..EmisConfig::new(EmisMethod::Vcm) };
        let image = vec![[0.5f32; 3]; (SIDE * SIDE) as usize];
        let target = Candidate { nu: 1.0, connections: 0, merge: false };
        use RestartTotal::{Samples, Time};
        for (iteration, total, better, restarts) in [
            (1, Samples(64), 1.5, true),
            (16, Samples(64), 1.5, true),
            (16, Samples(20), 1.5, false),
            (16, Samples(16), 1.5, false),
            (4, Samples(17), 1.05, true),
            (16, Samples(64), 1.05, false),
            (4, Time(17), 1.05, false),
            (4, Time(u32::MAX), 1.05, true),
        ] {
            let mut state = EmisState::new(config.clone(), SIDE, SIDE);
            // the target's moment × cost is `better` times lower than path tracing's
            let (pt_cost, target_cost) = {
                // the statistics of `pilot`: three camera vertices per pixel
                let sums =
                    StatisticsSums { iterations: 1, camera_vertices: 3 * (SIDE * SIDE) as u64, ..Default::default() };
                let s = sums.statistics(SIDE * SIDE);
                let terms = crate::emis::cost::CostTerms::of_candidates(
                    &config.constants,
                    &s,
                    &[Candidate::PATH_TRACING, target],
                    SIDE * SIDE,
                );
                (terms[0].at(0.0), terms[1].at(0.0))
            };
            // the time-budget case needs 4 + 13 · pt / target ≤ 16
            assert!(target_cost / pt_cost > 1.1, "{target_cost} {pt_cost}");
            let moment = |c: &Candidate| match c {
                c if c.is_path_tracing() => 1.0,
                c if *c == target => (pt_cost / target_cost / better) as f32,
                _ => 1e3,
            };
            state.absorb(&pilot(&state, moment)).unwrap();
            let report = state.update(&image, iteration, total).clone();
            assert_eq!(report.restarted, restarts, "update after {iteration} of {total:?}: {report:?}");
            assert_eq!(state.strategy.nu > 0.0, restarts);
        }
    }

    /// A path-tracing start settles on path tracing when it wins two updates in a row by the
    /// margin: not after a narrow win (every bidirectional candidate 1.05× path tracing's
    /// moment × cost, over the iterations so far), nor after one clear win (1000×), nor on
    /// one recorded iteration, and never with an infinite margin.
    #[test]
    fn path_tracing_settles_after_two_clear_wins_in_a_row() {
        let config = EmisConfig { pilot: PilotStart::PathTracing, ..EmisConfig::new(EmisMethod::Vcm) };
        let image = vec![[0.5f32; 3]; (SIDE * SIDE) as usize];
        // one iteration in which path tracing's moment is `pt` and every other candidate's
        // moment × cost is `other` times path tracing's cost
        let iteration_of = |state: &EmisState, pt: f64, other: f64| {
            let sums =
                StatisticsSums { iterations: 1, camera_vertices: 3 * (SIDE * SIDE) as u64, ..Default::default() };
            let statistics = sums.statistics(SIDE * SIDE);
            let terms = CostTerms::of_candidates(&config.constants, &statistics, &state.candidates, SIDE * SIDE);
            let pt_cost = terms[state.candidates.iter().position(Candidate::is_path_tracing).unwrap()].at(0.0);
            let moments: Vec<f32> = (terms.iter().zip(&state.candidates))
                .map(|(t, c)| if c.is_path_tracing() { pt } else { other * pt_cost / t.at(c.merge as u8 as f64) })
                .map(|m| m as f32)
                .collect();
            let mut data = pilot(state, |_| 0.0);
            let k = moments.len();
            data.moments.sums.iter_mut().enumerate().for_each(|(i, s)| *s = moments[i % k]);
            data
        };
        // the margins each update sees over the iterations so far: path tracing's moment grows
        // a thousandfold per update, so a later update can undo an earlier clear win
        let run = |config: &EmisConfig, margins: &[f64]| {
            let mut state = EmisState::new(config.clone(), SIDE, SIDE);
            let (mut pt_sum, mut other_sum) = (0.0, 0.0);
            for (i, (&margin, iteration)) in margins.iter().zip([1, 4, 16]).enumerate() {
                if !state.collecting() {
                    break;
                }
                let pt = 1e3f64.powi(i as i32);
                let other = margin * (pt_sum + pt) - other_sum;
                (pt_sum, other_sum) = (pt_sum + pt, other_sum + other);
                state.absorb(&iteration_of(&state, pt, other)).unwrap();
                let report = state.update(&image, iteration, RestartTotal::Samples(1000)).clone();
                let seen = report.path_tracing_margin();
                assert!((seen / margin - 1.0).abs() < 0.01, "{margins:?}: {seen} {report:?}");
                assert_eq!(report.settled, !state.collecting(), "{margins:?}: {report:?}");
                if report.settled {
                    assert_eq!(state.next_update(), None);
                    return Some(iteration);
                }
            }
            None
        };
        for (margins, settles_at) in [
            ([1e3, 1e3, 1e3], Some(4)),
            ([1.05, 1e3, 1e3], Some(16)),
            ([1e3, 1.05, 1e3], None),
            ([1.05, 1.05, 1.05], None),
        ] {
            assert_eq!(run(&config, &margins), settles_at, "{margins:?}");
        }
        let never = EmisConfig { settle_margin: f64::INFINITY, ..config.clone() };
        assert_eq!(run(&never, &[1e3, 1e3, 1e3]), None);
        // updates after 1 and 2 see the same single recording (iteration 1 records nothing)
        let mut state = EmisState::new(EmisConfig { updates: vec![1, 2, 4], ..config.clone() }, SIDE, SIDE);
        state.absorb(&iteration_of(&state, 1.0, 1e3)).unwrap();
        assert!(!state.update(&image, 1, RestartTotal::Samples(1000)).settled);
        assert!(!state.update(&image, 2, RestartTotal::Samples(1000)).settled);
        state.absorb(&iteration_of(&state, 1.0, 1e3)).unwrap();
        assert!(state.update(&image, 4, RestartTotal::Samples(1000)).settled);
    }

    /// The bidirectional pilot (`EmisConfig::new`'s) never restarts, even when its first
    /// update chooses a bidirectional strategy.
    #[test]
    fn the_bidirectional_pilot_never_restarts() {
        let mut state = EmisState::new(EmisConfig::new(EmisMethod::Bdpt), SIDE, SIDE);
        assert_eq!((state.candidate_set, state.candidates.len()), (CandidateSet::Full, 26));
        state.absorb(&pilot(&state, |c| if c.nu == 2.0 && c.connections == 1 { 1e-3 } else { 1.0 })).unwrap();
        let report = state.update(&vec![[0.5f32; 3]; (SIDE * SIDE) as usize], 1, RestartTotal::Samples(64)).clone();
        assert!(!report.reduced && !report.restarted);
        assert_eq!((state.strategy.nu, state.kept_from, state.moments.iterations), (2.0, 0, 1));
    }
}
