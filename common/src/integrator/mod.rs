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

pub use bidir::{Bidir, LightProbe};
pub use lt::LightTracer;
pub use pt::PathTracer;

/// One unit of work.
#[derive(Clone, Debug)]
pub struct TileRequest {
    /// Pixels to render.
    pub rect: Rect,
    /// Sample indices to render for every pixel.
    pub samples: Range<u32>,
    /// Job seed.
    pub seed: u64,
    /// Asks the render to give up early; what it returns then is to be thrown away.
    pub stop: Stop,
}

impl TileRequest {
    /// A request that runs to its end.
    pub fn new(rect: Rect, samples: Range<u32>, seed: u64) -> Self {
        TileRequest { rect, samples, seed, stop: Stop::default() }
    }

    /// The same request, given up when `stop` is requested.
    pub fn stoppable(self, stop: Stop) -> Self {
        TileRequest { stop, ..self }
    }
}

/// A request to stop rendering, shared between whoever may ask (a worker that lost its lease)
/// and the render, which checks it between pixels, rows or iterations: a stopped tile's sums
/// are incomplete and must be discarded.
#[derive(Clone, Debug, Default)]
pub struct Stop(Option<std::sync::Arc<std::sync::atomic::AtomicBool>>);

impl Stop {
    /// A flag that can be requested.
    pub fn new() -> Self {
        Stop(Some(Default::default()))
    }

    /// Asks every render holding this flag to stop.
    pub fn request(&self) {
        if let Some(f) = &self.0 {
            f.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    }

    /// Whether stopping was asked for.
    #[inline]
    pub fn requested(&self) -> bool {
        self.0.as_ref().is_some_and(|f| f.load(std::sync::atomic::Ordering::Relaxed))
    }
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
