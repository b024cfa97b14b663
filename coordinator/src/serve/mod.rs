//! The coordinator service, `tessera serve`: the pure job state machine and the service that
//! persists and merges around it ([`job`]), bundles received in pieces ([`bundle_stream`]),
//! durable storage ([`storage`]), the gRPC and REST APIs ([`grpc`], [`rest`]) over the state
//! they share ([`state`]), authentication, the browser guard ([`origin`]), connection limits
//! ([`conn`]), TLS ([`tls`]), the error table, the event stream ([`events`]), metrics
//! ([`metrics`]) and logging, and the wiring ([`app`]) configured by [`config`].
//!
//! Nothing here imports the command line or the benchmarks.

pub mod app;
pub mod auth;
pub mod bundle_stream;
pub mod clock;
pub mod config;
pub mod conn;
pub mod error;
pub mod events;
pub mod grpc;
pub mod job;
pub mod metrics;
pub mod metrics_process;
pub mod origin;
pub mod rest;
pub mod state;
pub mod storage;
pub mod telemetry;
pub mod tls;
