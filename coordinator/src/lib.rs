//! Tessera's coordinator crate, binary `tessera`, in three rooms with the direction of use
//! visible from the tree:
//!
//! * [`cli`]: argument parsing and dispatch, `tessera render`, and the farm client commands
//!   (`submit`, `status`, `cancel`), which reach a coordinator only through `tessera-proto`
//!   and `tessera-link`;
//! * [`serve`]: the coordinator service (`tessera serve`): job state machine, storage, gRPC,
//!   REST; it imports neither `cli` nor `bench`;
//! * [`bench`]: every `tessera bench …` measurement.
//!
//! Below them, [`options`] holds the command-line option types `cli` and `bench` share, and
//! [`output`] the image files `cli` and `serve` both write.

pub mod bench;
pub mod cli;
pub mod options;
pub mod output;
pub mod serve;
