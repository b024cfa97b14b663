//! Test support that is not renderer code: what `tessera bench` measures once and the
//! renderer's tests read, so that the library carries no tool code.

pub mod decision_truth;
