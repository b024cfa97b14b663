//! Durable state of the coordinator under `--data-dir`: `tessera.sqlite` (jobs, tiles,
//! workers; see [`sqlite`]) and `blobs/` (scene bundles, tile results, film checkpoints,
//! outputs; see [`blobs`]).

pub mod blobs;
pub mod sqlite;

pub use blobs::BlobStore;
pub use sqlite::{Extra, JobFiles, Store, StoreError, WorkerRow};
