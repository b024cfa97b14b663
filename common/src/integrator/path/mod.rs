//! Path-space building blocks shared by the bidirectional integrators: subpath tracing, the
//! light-vertex cache, the photon map and merging, the sampling techniques, the gathered pdf
//! arrays and the balance-heuristic MIS weights with sample counts. The integrators use these;
//! nothing here knows an integrator.

pub mod connections;
pub mod gather;
pub mod light_cache;
pub mod light_path;
pub mod merge;
pub mod mis;
pub mod photon_map;
pub mod prefetch;
pub mod techniques;
pub mod vertex;
