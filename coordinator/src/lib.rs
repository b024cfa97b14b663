//! Tessera's coordinator crate: the `tessera` command line (local rendering, benchmarks, the
//! farm client commands) and the farm's coordinator service (`tessera serve`): the pure job
//! state machine in [`job`], storage in [`storage`], gRPC in [`grpc`], REST in [`rest`].

pub mod app;
pub mod auth;
pub mod bench;
pub mod bench_emis;
pub mod bench_farm;
pub mod calibrate;
pub mod chart;
pub mod cli;
pub mod client;
pub mod error;
pub mod ground_truth;
pub mod grpc;
pub mod job;
pub mod local;
pub mod rest;
pub mod storage;
pub mod telemetry;
