//! Durable state of the coordinator under `--data-dir`: `tessera.sqlite` (jobs, tiles,
//! workers, accepted results; see [`sqlite`], written through the group commit of [`commit`])
//! and `blobs/` (scene bundles, film checkpoints, outputs; see [`blobs`]); how the database gives
//! the space of deleted jobs back ([`space`]).

pub mod blobs;
pub mod commit;
pub mod space;
pub mod sqlite;

pub use blobs::{BlobStore, Live};
pub use sqlite::{Extra, JobFiles, OutputDigests, Store, StoreError, WorkerRow};
