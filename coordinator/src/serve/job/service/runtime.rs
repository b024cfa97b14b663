//! What the service keeps in memory for one job beside the model's state: the merged film, the
//! EMIS state, results accepted ahead of the merge frontier, the job's stored files and the
//! last checkpoint's timing. One struct per job in one map, so that whatever ends or drops a
//! job handles all of it in one place.

use super::super::emis::EmisJob;
use super::super::view::StrategyView;
use crate::serve::storage::JobFiles;
use std::collections::{BTreeMap, BTreeSet};
use tessera_common::emis::PilotData;
use tessera_common::film::{Film, TileAccum};

/// An accepted result waiting for its turn in the merge order.
pub(super) type HeldResult = (TileAccum, Option<PilotData>);

/// The last checkpoint of a job.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct CheckpointState {
    /// When it was written.
    pub(super) at_ms: u64,
    /// How long writing it took.
    pub(super) cost_ms: u64,
}

/// One job's in-memory state.
#[derive(Default)]
pub(super) struct JobRuntime {
    /// The merged tiles, while the job runs.
    pub(super) film: Option<Film>,
    /// EMIS: merged pilot data, current strategy and reports, while the job runs.
    pub(super) emis: Option<EmisJob>,
    /// EMIS: the decisions of a job that ended (its state is dropped).
    pub(super) decisions: Option<StrategyView>,
    /// Accepted results ahead of the merge frontier, by tile index.
    pub(super) held: BTreeMap<usize, HeldResult>,
    /// Its checkpoint and outputs.
    pub(super) files: JobFiles,
    /// EMIS: digests of the merge masks it stored (deleted with the job; not persisted, so
    /// after a restart those of earlier passes go with the start-up sweep instead).
    pub(super) masks: BTreeSet<String>,
    /// Some accepted results are files (large ones), which go once a checkpoint holds them;
    /// set after a restart too, since files may be left from before it.
    pub(super) result_files: bool,
    /// The last checkpoint's time and cost; `None` until the first merge after submission or
    /// a restart, which starts the clock.
    pub(super) checkpoint: Option<CheckpointState>,
}

impl JobRuntime {
    /// The EMIS decisions so far (`None` before the first update and for other integrators).
    pub(super) fn strategy(&self) -> Option<StrategyView> {
        match &self.emis {
            Some(e) => e.view(),
            None => self.decisions.clone(),
        }
    }

    /// Drops what only a running job needs, keeping its decisions and files (masks included).
    pub(super) fn end(&mut self) {
        if let Some(view) = self.emis.take().and_then(|e| e.view()) {
            self.decisions = Some(view);
        }
        self.film = None;
        self.held.clear();
    }
}
