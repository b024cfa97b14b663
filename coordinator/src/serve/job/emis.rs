//! The coordinator's side of an EMIS job: the merged pilot data and decisions (an
//! [`EmisState`] from `common`, the same one `tessera render` drives locally), the strategy
//! each lease carries to its worker, the checks on the pilot data that comes back, and the
//! update run at each optimisation barrier. The job model decides *when* (passes and
//! barriers); this decides *what* the next pass renders with.

use super::model::{JobSpec, TileSpec};
pub use super::spec::MergeSpec;
use super::spec::WarmStart;
use super::view::StrategyView;
use crate::serve::storage::BlobStore;
use std::sync::Arc;
use tessera_common::emis::{CandidateSet, EmisState, PilotData, RestartTotal, Strategy, collects_moments};
use tessera_common::film::Film;
use tessera_common::integrator::path::connections::Connections;
use tessera_common::integrator::path::merge::MergeMask;

/// The counts an EMIS tile renders with, as a lease carries them.
#[derive(Clone, Debug, PartialEq)]
pub struct TileStrategy {
    /// Light paths per pixel per iteration (0: path tracing).
    pub nu: f32,
    /// Connections per camera vertex (0 with a connection mask).
    pub connections: u32,
    /// Per-pixel expected connections stored as a blob (width·height little-endian f32).
    pub connection_mask: Option<String>,
    /// Merge probability.
    pub merge: MergeSpec,
    /// Record and return pilot data.
    pub collect: bool,
    /// The candidates the pilot data is for.
    pub candidates: CandidateSet,
}

/// The size of an EMIS job's pilot data, copied out so that decoding a result (megabytes)
/// needs no lock on the job.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PilotShape {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Candidates per pixel.
    pub candidates: usize,
    /// ν of the current strategy ([`collects_moments`] depends on it).
    pub nu: f32,
}

/// No path statistics count (vertices, light paths, merge queries) is this many times the
/// pixels × iterations of its tile: far above any render, far below overflowing the sums.
const MAX_COUNT_PER_SAMPLE: u64 = 1 << 16;

impl PilotShape {
    /// Decodes and checks the pilot data of a result for `tile`: present exactly when the
    /// tile collects (in a collecting pass and [`collects_moments`]), the job's size and
    /// candidate count, one iteration per tile iteration.
    pub fn decode(&self, tile: &TileSpec, collect: bool, bytes: &[u8]) -> Result<Option<PilotData>, String> {
        let collect = collect && collects_moments(self.nu, &tile.samples);
        match (collect, bytes.is_empty()) {
            (false, true) => return Ok(None),
            (false, false) => return Err("result has pilot data but the tile does not collect moments".into()),
            (true, true) => return Err("result has no pilot data but the tile collects moments".into()),
            (true, false) => {}
        }
        let pilot = PilotData::decode(bytes, self.width, self.height, self.candidates)?;
        let iterations = tile.samples.len() as u32;
        if pilot.moments.iterations != iterations || pilot.statistics.iterations != iterations as u64 {
            return Err(format!(
                "pilot data covers {} iterations ({} in the statistics), the tile {iterations}",
                pilot.moments.iterations, pilot.statistics.iterations
            ));
        }
        // counts no render can reach would overflow the job's sums and skew its costs
        let most = u64::from(iterations) * u64::from(self.width) * u64::from(self.height) * MAX_COUNT_PER_SAMPLE;
        let s = &pilot.statistics;
        let t = &s.times;
        let counts = [s.camera_vertices, s.light_paths, s.light_vertices, s.merge_queries];
        let timed = [t.light_vertices, t.photons_built, t.camera_vertices, t.connections, t.queries, t.photons];
        if let Some(c) = counts.into_iter().chain(timed).find(|&c| c > most) {
            return Err(format!("path statistics count {c} is over {MAX_COUNT_PER_SAMPLE} per pixel and iteration"));
        }
        if t.iterations > iterations as u64 {
            return Err(format!("work times cover {} iterations, the tile {iterations}", t.iterations));
        }
        Ok(Some(pilot))
    }
}

/// The digest of `mask` (little-endian f32) as a blob, stored the first time (`digest` keeps it
/// for the pass).
fn stored(blobs: &BlobStore, digest: &mut Option<String>, mask: &[f32]) -> std::io::Result<String> {
    if let Some(d) = digest {
        return Ok(d.clone());
    }
    let d = blobs.put(&tessera_link::mask::encode(mask))?;
    *digest = Some(d.clone());
    Ok(d)
}

/// The strategy of `warm`, its masks of `pixels` values read from `blobs`.
fn warm_strategy(warm: &WarmStart, blobs: &BlobStore, pixels: u32) -> Result<Strategy, String> {
    let mask = |digest: &str| -> Result<Arc<Vec<f32>>, String> {
        let bytes = blobs.get(digest).map_err(|e| e.to_string())?;
        let bytes = bytes.ok_or_else(|| format!("the warm start's mask {digest} is missing"))?;
        let mask = tessera_link::mask::decode(&bytes, pixels as usize);
        Ok(Arc::new(mask.map_err(|e| format!("the warm start's mask {digest} has {e}"))?))
    };
    let connections = match &warm.connection_mask {
        Some(d) => Connections::PerPixel(mask(d)?),
        None => Connections::Fixed(warm.connections),
    };
    let merge = match &warm.merge {
        MergeSpec::None => None,
        MergeSpec::Constant(c) => Some(MergeMask::Constant(*c)),
        MergeSpec::Mask(d) => Some(MergeMask::PerPixel(mask(d)?)),
    };
    Ok(Strategy { nu: warm.nu, connections, merge })
}

/// An EMIS job's state on the coordinator.
pub struct EmisJob {
    /// Merged pilot data, current strategy, reports.
    pub state: EmisState,
    /// Digest of the current per-pixel mask blob, once stored.
    mask_digest: Option<String>,
    /// The blob of the current strategy's connection mask, once stored.
    connection_digest: Option<String>,
}

impl EmisJob {
    /// The state before the pilot of an `emis-*` job (starting from its warm start's strategy,
    /// whose masks are read from `blobs`); `None` for other integrators.
    pub fn new(spec: &JobSpec, blobs: &BlobStore) -> Result<Option<EmisJob>, String> {
        if spec.settings.integrator.emis_method().is_none() {
            return Ok(None);
        }
        let mut config = spec.settings.emis_config();
        config.warm_start =
            spec.warm.as_ref().map(|w| warm_strategy(w, blobs, spec.width * spec.height)).transpose()?;
        let state = EmisState::new(config, spec.width, spec.height);
        Ok(Some(EmisJob { state, mask_digest: None, connection_digest: None }))
    }

    /// Restores a checkpointed state ([`EmisJob::checkpoint`]).
    pub fn restore(spec: &JobSpec, bytes: &[u8]) -> Result<EmisJob, String> {
        let state = EmisState::decode(spec.settings.emis_config(), spec.width, spec.height, bytes)?;
        Ok(EmisJob { state, mask_digest: None, connection_digest: None })
    }

    /// The bytes to checkpoint beside the film.
    pub fn checkpoint(&self) -> Vec<u8> {
        self.state.encode()
    }

    /// The strategy of the current pass; stores the per-pixel masks as blobs the first time.
    pub fn strategy(&mut self, blobs: &BlobStore, collect: bool) -> std::io::Result<TileStrategy> {
        let s = &self.state.strategy;
        let merge = match &s.merge {
            None => MergeSpec::None,
            Some(MergeMask::Constant(c)) => MergeSpec::Constant(*c),
            Some(MergeMask::PerPixel(mask)) => MergeSpec::Mask(stored(blobs, &mut self.mask_digest, mask)?),
        };
        let (connections, connection_mask) = match &s.connections {
            Connections::Fixed(c) => (*c, None),
            Connections::PerPixel(mask) => (0, Some(stored(blobs, &mut self.connection_digest, mask)?)),
        };
        Ok(TileStrategy {
            nu: s.nu,
            connections,
            connection_mask,
            merge,
            collect,
            candidates: self.state.candidate_set,
        })
    }

    /// The decision a job of frames hands to its next frame: the current strategy, its masks
    /// stored as blobs.
    pub fn decision(&mut self, blobs: &BlobStore) -> std::io::Result<WarmStart> {
        let s = self.strategy(blobs, false)?;
        Ok(WarmStart { nu: s.nu, connections: s.connections, connection_mask: s.connection_mask, merge: s.merge })
    }

    /// What this job's pilot data must look like.
    pub fn shape(&self) -> PilotShape {
        let m = &self.state.moments;
        PilotShape {
            width: m.width,
            height: m.height,
            candidates: self.state.candidates.len(),
            nu: self.state.strategy.nu,
        }
    }

    /// [`PilotShape::decode`] with this job's shape.
    pub fn decode_pilot(&self, tile: &TileSpec, collect: bool, bytes: &[u8]) -> Result<Option<PilotData>, String> {
        self.shape().decode(tile, collect, bytes)
    }

    /// Whether [`EmisJob::absorb`] would take `pilot`.
    pub fn check(&self, pilot: &PilotData) -> Result<(), String> {
        self.state.check(pilot)
    }

    /// Adds a tile's pilot data (tiles are merged in order, so the sums are those of a local
    /// render).
    pub fn absorb(&mut self, pilot: &PilotData) -> Result<(), String> {
        self.state.absorb(pilot)
    }

    /// The update at a barrier after `iterations` iterations: denoise the film's image,
    /// optimise, switch the strategy. True if it ended a path-tracing start: the caller must
    /// clear the film.
    ///
    /// Idempotent: the update's checkpoint can land before the transition it belongs to is
    /// committed (both name the same merged count), and a restart in between comes back to
    /// the barrier with the state the update already produced. That state's last report is
    /// for this barrier (updates are at increasing iteration counts), so it is not run twice.
    /// `restart_total`: the iterations the job would run in all if this update restarted it.
    pub fn update(&mut self, film: &Film, iterations: u32, restart_total: RestartTotal) -> bool {
        self.mask_digest = None;
        self.connection_digest = None;
        if let Some(done) = self.state.reports.last().filter(|r| r.iteration == iterations) {
            return done.restarted;
        }
        self.state.update(&film.average(), iterations, restart_total).restarted
    }

    /// The decisions so far, for status views (`None` before the first update).
    pub fn view(&self) -> Option<StrategyView> {
        let last = self.state.reports.last()?;
        Some(StrategyView {
            nu: self.state.strategy.nu,
            connections: match &self.state.strategy.connections {
                Connections::Fixed(c) => *c,
                Connections::PerPixel(_) => 0,
            },
            mean_connections: last.mean_connections,
            mean_merge_probability: last.mean_merge_probability,
            updates: self.state.reports.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tessera_common::emis::cost::StatisticsSums;
    use tessera_common::emis::guides::GuideBuffer;
    use tessera_common::emis::moments::MomentBuffer;
    use tessera_common::film::Rect;
    use tessera_common::settings::{IntegratorName, RenderSettings};

    /// An emis-vcm job with the bidirectional pilot, whose every iteration records.
    fn spec() -> JobSpec {
        let mut spec = JobSpec::bare("j", IntegratorName::EmisVcm, Some(8), 4, 2);
        spec.settings.emis_pilot = tessera_common::emis::PilotStart::Bidirectional;
        spec
    }

    fn blobs() -> (tempfile::TempDir, BlobStore) {
        let dir = tempfile::tempdir().unwrap();
        let blobs = BlobStore::open(dir.path()).unwrap();
        (dir, blobs)
    }

    /// A decision handed to the next frame through blobs comes back as the same strategy, which
    /// the next frame starts from, deciding from the full set; a path-tracing decision under
    /// the path-tracing start starts that frame as the start does; a lost mask is an error.
    #[test]
    fn a_warm_start_begins_with_the_decision_it_was_handed() {
        let (_dir, blobs) = blobs();
        let mut before = EmisJob::new(&spec(), &blobs).unwrap().unwrap();
        let mask: Vec<f32> = (0..8).map(|i| i as f32 / 8.0).collect();
        before.state.strategy = Strategy {
            nu: 0.5,
            connections: Connections::PerPixel(Arc::new(mask.iter().map(|m| m * 4.0).collect())),
            merge: Some(MergeMask::PerPixel(Arc::new(mask))),
        };
        let warm = before.decision(&blobs).unwrap();
        assert_eq!(warm.blobs().count(), 2, "{warm:?}");
        let mut path_tracing = JobSpec { warm: Some(warm.clone()), ..spec() };
        path_tracing.settings.emis_pilot = tessera_common::emis::PilotStart::PathTracing;
        let after = EmisJob::new(&path_tracing, &blobs).unwrap().unwrap();
        assert_eq!(after.state.strategy, before.state.strategy);
        assert_eq!(after.state.candidate_set, CandidateSet::Full);
        assert_eq!(path_tracing.shape().emis.unwrap().initial_nu, 0.5);
        let pt = WarmStart { nu: 0.0, connections: 0, connection_mask: None, merge: MergeSpec::Constant(0.0) };
        let cold = EmisJob::new(&JobSpec { warm: Some(pt), ..path_tracing.clone() }, &blobs).unwrap().unwrap();
        assert_eq!(cold.state.candidate_set, CandidateSet::Reduced, "a path-tracing decision starts cold");
        let lost = WarmStart { merge: MergeSpec::Mask("0".repeat(64)), ..warm };
        let error = EmisJob::new(&JobSpec { warm: Some(lost), ..path_tracing }, &blobs).err().unwrap();
        assert!(error.contains("missing"), "{error}");
    }

    fn pilot(job: &EmisJob, iterations: u32) -> PilotData {
        let mut moments = MomentBuffer::new(4, 2, job.state.candidates.len());
        moments.iterations = iterations;
        let statistics = StatisticsSums { iterations: iterations as u64, ..Default::default() };
        PilotData { moments, statistics, guides: GuideBuffer::new(4, 2) }
    }

    /// Running the update of a barrier again (a restart between its checkpoint and the commit
    /// of its transition) leaves the state as the first run made it.
    #[test]
    fn an_update_runs_once_per_barrier() {
        let (_dir, blobs) = blobs();
        let mut job = EmisJob::new(&spec(), &blobs).unwrap().unwrap();
        job.absorb(&pilot(&job, 1)).unwrap();
        let film = Film::for_filter(4, 2, &tessera_common::film::filter::Filter::BOX);
        let restarted = job.update(&film, 1, RestartTotal::Samples(64));
        let (strategy, reports) = (job.state.strategy.clone(), job.state.reports.len());
        assert_eq!(job.update(&film, 1, RestartTotal::Samples(64)), restarted);
        assert_eq!(
            (job.state.strategy.clone(), job.state.reports.len(), job.state.updates_done),
            (strategy, reports, 1)
        );
        job.update(&film, 4, RestartTotal::Samples(64));
        assert_eq!(job.state.reports.len(), 2, "the next barrier's update runs");
    }

    #[test]
    fn pilot_data_must_match_the_tile_and_whether_it_collects() {
        let (_dir, blobs) = blobs();
        let job = EmisJob::new(&spec(), &blobs).unwrap().unwrap();
        assert!(EmisJob::new(&JobSpec { settings: RenderSettings::default(), ..spec() }, &blobs).unwrap().is_none());
        let tile = TileSpec { rect: Rect::full(4, 2), samples: 1..2 };
        let good = pilot(&job, 1).encode();
        assert!(job.decode_pilot(&tile, true, &good).unwrap().is_some());
        assert!(job.decode_pilot(&tile, false, &[]).unwrap().is_none());
        assert!(job.decode_pilot(&tile, true, &[]).unwrap_err().contains("no pilot data"));
        assert!(job.decode_pilot(&tile, false, &good).unwrap_err().contains("does not collect"));
        let two = pilot(&job, 2).encode();
        assert!(job.decode_pilot(&tile, true, &two).unwrap_err().contains("covers 2 iterations"));
        assert!(job.decode_pilot(&tile, true, &good[..good.len() - 4]).is_err());
        // a hostile worker's statistics that would overflow the job's sums
        let mut absurd = pilot(&job, 1);
        absurd.statistics.camera_vertices = u64::MAX;
        assert!(job.decode_pilot(&tile, true, &absurd.encode()).unwrap_err().contains("path statistics count"));
        absurd.statistics.camera_vertices = 8 << 16;
        assert!(job.decode_pilot(&tile, true, &absurd.encode()).is_ok(), "the bound itself is allowed");
        // with path tracing as the strategy only iteration 0, those ≡ 2 mod 4 before 16 and
        // those ≡ 6 mod 8 after it record moments
        let mut pt = EmisJob::new(&spec(), &blobs).unwrap().unwrap();
        pt.state.strategy.nu = 0.0;
        assert!(pt.decode_pilot(&tile, true, &[]).unwrap().is_none());
        assert!(pt.decode_pilot(&tile, true, &good).unwrap_err().contains("does not collect"));
        let skipped = TileSpec { samples: 4..5, ..tile.clone() };
        assert!(pt.decode_pilot(&skipped, true, &[]).unwrap().is_none());
        let sparse = TileSpec { samples: 18..19, ..tile.clone() };
        assert!(pt.decode_pilot(&sparse, true, &good).unwrap_err().contains("does not collect"));
        let recorded = TileSpec { samples: 2..3, ..tile };
        assert!(pt.decode_pilot(&recorded, true, &good).unwrap().is_some());
        assert!(pt.decode_pilot(&recorded, true, &[]).unwrap_err().contains("no pilot data"));
    }
}
