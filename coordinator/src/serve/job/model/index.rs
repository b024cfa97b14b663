//! Which tiles of a job are queued and which leased, kept beside the tiles' states so that
//! leasing, expiry and the workers' status never scan a job's tiles.

use super::{Job, TileState};
use std::collections::BTreeSet;

/// Which tiles of a job are queued and which leased. Derived from the tiles' states (never
/// stored): kept by [`Job::set_tile_state`], rebuilt by [`Job::reindex`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TileIndex {
    /// Tiles waiting for a worker.
    pub queued: BTreeSet<usize>,
    /// Tiles held by a worker.
    pub leased: BTreeSet<usize>,
}

impl Job {
    /// Sets tile `i`'s state, keeping the index.
    pub fn set_tile_state(&mut self, i: usize, state: TileState) {
        self.index.queued.remove(&i);
        self.index.leased.remove(&i);
        match state {
            TileState::Queued => self.index.queued.insert(i),
            TileState::Leased { .. } => self.index.leased.insert(i),
            TileState::Accepted | TileState::Merged => false,
        };
        self.tiles[i].state = state;
    }

    /// Rebuilds the index from the tiles (after loading them).
    pub fn reindex(&mut self) {
        self.index = TileIndex::default();
        for (i, t) in self.tiles.iter().enumerate() {
            match t.state {
                TileState::Queued => self.index.queued.insert(i),
                TileState::Leased { .. } => self.index.leased.insert(i),
                _ => false,
            };
        }
    }
}
