//! Efficiency-aware MIS (Grittmann et al. 2022; `docs/emis.md`), in two layers.
//!
//! The optimisation, pure and free of rendering and IO so that a coordinator can run it
//! between passes: the candidate strategies ([`candidate`]), the proxy weights and correction
//! factor that re-weight a pilot sample for every candidate ([`proxy`], [`delta`]), the moment
//! estimator and its buffers ([`estimator`], [`moments`]), the cost heuristic and its
//! constants measured per job ([`cost`], [`measured`]; `tessera bench calibrate-costs` fits
//! the calibrated ones), the image filters, quantiles and denoiser ([`filter`], `quantile`,
//! [`denoise`]) and the optimiser ([`optimize`]). The brute-force truth its decisions are
//! tested against is in the `tessera-testing` crate.
//!
//! The driver, which renders with the bidirectional integrators: strategies and iteration
//! ranges ([`render`]), the denoiser's guides ([`guides`]), the merged state and its updates
//! ([`EmisState`]) and its encoding for checkpoints and the wire.
//!
//! The direction of use is one way: this module uses the integrators and the MIS weights; they
//! know nothing of it (they report samples through [`crate::integrator::observer`]).

pub mod candidate;
pub mod cost;
pub mod delta;
pub mod denoise;
pub mod estimator;
pub mod filter;
pub mod guides;
pub mod halve;
pub mod measured;
pub mod moments;
pub mod optimize;
pub mod proxy;
mod quantile;
pub mod render;
mod schedule;
pub mod start;
mod state;
mod wire;

pub use render::{
    CandidateSet, EmisConfig, EmisMethod, EmisOutput, GUIDE_ITERATIONS, PilotData, PilotStart, Strategy, render_emis,
    render_iterations, render_iterations_until,
};
pub use schedule::{
    FINAL_ITERATIONS_PER_CALL, FINAL_PT_ITERATIONS_MAX, RestartTotal, SPARSE_FROM, calls, collecting_call,
    collects_moments, final_call, iterations_at_pace, seconds_per_iteration, update_pays,
};
pub use state::{EmisState, SETTLE_RECORDINGS, UpdateReport};
pub use wire::Decisions;
