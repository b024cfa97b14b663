//! Durable state of the coordinator under `--data-dir`: `tessera.sqlite` (jobs, tiles,
//! workers, accepted results; see [`sqlite`], written through the group commit of [`commit`])
//! and `blobs/` (scene bundles, film checkpoints, outputs; see [`blobs`]); how the database gives
//! the space of deleted jobs back ([`space`]); the reserve of free space that keeps a full disk
//! from stopping the service ([`disk`]).

pub mod blobs;
pub mod commit;
pub mod disk;
pub mod space;
pub mod sqlite;

pub use blobs::{BlobStore, Live};
pub use sqlite::{Extra, JobFiles, OutputDigests, Store, StoreError, WorkerMode, WorkerRow};
