//! Integrators and the per-tile contract they share.
//!
//! A tile is an image rectangle × a range of sample indices. Every random number a tile uses
//! is a function of (seed, pixel, sample index, dimension), so a tile renders to bit-identical
//! sums wherever and however it is rendered.

pub mod bidir;
pub mod lt;
pub mod observer;
pub mod path;
pub mod pt;

use crate::film::{Rect, TileAccum};
use crate::scene::Scene;
use std::ops::Range;

pub use bidir::Bidir;
pub use lt::LightTracer;
pub use pt::PathTracer;

/// One unit of work.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileRequest {
    /// Pixels to render.
    pub rect: Rect,
    /// Sample indices to render for every pixel.
    pub samples: Range<u32>,
    /// Job seed.
    pub seed: u64,
}

/// Path-length and emitter settings shared by the integrators (Mitsuba's `path` parameters).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PathSettings {
    /// Longest path in segments, counting the camera ray (`u32::MAX` = unlimited).
    pub max_depth: u32,
    /// Depth from which Russian roulette may end paths.
    pub rr_depth: u32,
    /// Hide emitters seen directly by the camera.
    pub hide_emitters: bool,
}

impl PathSettings {
    /// The scene file's settings, with an optional override of `max_depth`.
    pub fn from_scene(scene: &Scene, max_depth: Option<u32>) -> Self {
        PathSettings {
            max_depth: max_depth.or(scene.integrator.max_depth).unwrap_or(u32::MAX),
            rr_depth: scene.integrator.rr_depth,
            hide_emitters: scene.integrator.hide_emitters,
        }
    }
}

/// An algorithm that renders tiles. Dispatch is per tile, so a trait object is fine here.
pub trait Integrator: Send + Sync {
    /// Short name, e.g. `pt`.
    fn name(&self) -> &'static str;
    /// Renders `tile` into `accum` (which covers `tile.rect`).
    fn render_tile(&self, scene: &Scene, tile: &TileRequest, accum: &mut TileAccum);
    /// Whether tiles must cover the whole frame (light paths, splats and photon maps are
    /// image-level), rendering a range of iterations.
    fn full_frame(&self) -> bool {
        false
    }
}
