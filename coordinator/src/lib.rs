//! Tessera's coordinator crate: the `tessera` command line (local rendering and benchmarks now;
//! the farm's coordinator service will live here too).

pub mod bench;
pub mod cli;
pub mod local;
pub mod telemetry;
