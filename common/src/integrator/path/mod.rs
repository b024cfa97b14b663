//! Path-space building blocks shared by the bidirectional integrators: the gathered pdf arrays
//! and the balance-heuristic MIS weights with sample counts.

pub mod gather;
pub mod light_path;
pub mod mis;
pub mod techniques;
pub mod vertex;
