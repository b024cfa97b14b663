//! Jobs: what a job renders ([`spec`]), the pure state machine ([`model`]) that wraps the job
//! driver of `tessera_common::driver` (which cuts jobs into passes of tiles) with leases,
//! result validation ([`validate`]), the EMIS state and updates ([`emis`]), removal
//! of ended jobs ([`retention`]) and the service that wraps them with storage and
//! notifications ([`service`]).

pub mod emis;
pub mod model;
pub mod retention;
pub mod service;
pub mod spec;
pub mod validate;
pub mod view;

#[cfg(test)]
mod control_tests;
#[cfg(test)]
mod fault_tests;
#[cfg(test)]
mod frames_tests;
#[cfg(test)]
mod retention_tests;
#[cfg(test)]
pub(crate) mod service_tests;
#[cfg(test)]
mod tests;
