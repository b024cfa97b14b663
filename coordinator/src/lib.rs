//! Tessera's coordinator crate: the `tessera` command line (local rendering and benchmarks now;
//! the farm's coordinator service will live here too).

pub mod bench;
pub mod bench_emis;
pub mod chart;
pub mod cli;
pub mod ground_truth;
pub mod local;
pub mod telemetry;
