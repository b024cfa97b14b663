//! Tessera's renderer library: Mitsuba 3 scene loading, geometry and BVH, BSDFs, lights,
//! camera, deterministic samplers, film with EXR/PNG output, and the integrators.
//!
//! ```no_run
//! use tessera_common::{integrator::{PathTracer, PathSettings}, render::{render, Budget, RenderOptions}, scene::Scene};
//! let scene = Scene::load(std::path::Path::new("scenes/cornell-box/scene.xml")).unwrap();
//! let pt = PathTracer { settings: PathSettings::from_scene(&scene, None) };
//! let opts = RenderOptions { budget: Budget::Samples(16), seed: 1, threads: 0, tile_size: 32 };
//! let out = render(&scene, &pt, &opts, &|_, _| {}).unwrap();
//! assert_eq!(out.film.total_samples(), 16 * 256 * 256);
//! ```
#![deny(missing_docs)]

/// The version of every binary format Tessera writes and reads back: the pilot data a worker
/// uploads with a tile, and the coordinator's film and EMIS state checkpoints. A change to any
/// of them bumps it; readers refuse another version by name, and keep no reader for older ones.
pub const FORMAT_VERSION: u32 = 3;

/// The renderer's revision: a digest of this crate's sources and the workspace's `Cargo.lock`
/// (`build.rs`). Two builds that agree on it render the same bits.
pub const RENDERER_REVISION: &str = env!("TESSERA_RENDERER_REVISION");

/// This build as `tessera version` prints it and workers and the coordinator compare it.
pub fn build_id() -> String {
    format!("{} (renderer {RENDERER_REVISION})", env!("CARGO_PKG_VERSION"))
}

pub mod bsdf;
pub mod bundle;
pub mod camera;
pub mod cpu;
pub mod driver;
pub mod emis;
pub mod film;
pub mod geometry;
pub mod integrator;
pub mod light;
pub mod math;
pub mod render;
pub mod sampler;
pub mod scene;
pub mod settings;
pub mod spectrum;
#[cfg(any(test, feature = "test-util"))]
pub mod testing;
pub mod texture;
