//! Durable state of the coordinator under `--data-dir`: `tessera.sqlite` (jobs, tiles,
//! workers, accepted results; see [`sqlite`], written through the group commit of [`commit`])
//! and `blobs/` (scene bundles, film checkpoints, outputs; see [`blobs`]).

pub mod blobs;
pub mod commit;
pub mod sqlite;

pub use blobs::BlobStore;
pub use sqlite::{Extra, JobFiles, Store, StoreError, WorkerRow};
