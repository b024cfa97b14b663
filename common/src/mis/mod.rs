//! Efficiency-aware MIS (Grittmann et al. 2022; `shared/docs/emis-spec.md`): the candidate
//! strategies, the correction factor that re-weights pilot samples for every candidate, the
//! moment buffers that collect them, the cost heuristic and the image filters the optimiser
//! uses. Everything here is pure: no rendering, no IO, so the coordinator can run it between
//! passes.

pub mod calibrate;
pub mod candidate;
pub mod cost;
pub mod delta;
pub mod denoise;
pub mod estimator;
pub mod filter;
pub mod moments;
pub mod optimize;
