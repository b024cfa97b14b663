//! Local rendering: runs a job's [`Driver`] on a rayon pool, rendering each pass's tiles and
//! merging their sums into a [`Film`] in the driver's order, so the result is bit-identical
//! for any thread count and to a farm's.

use crate::driver::{Driver, Shape, Step, TileSpec};
use crate::emis::{EmisState, render_emis};
use crate::film::{Film, TileAccum};
use crate::integrator::{Integrator, TileRequest};
use crate::scene::Scene;
use crate::settings::Renderer;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

pub use crate::driver::Budget;

/// Options of a local render.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// Samples or time.
    pub budget: Budget,
    /// Job seed.
    pub seed: u64,
    /// Worker threads (0 = all cores).
    pub threads: usize,
    /// Tile edge in pixels.
    pub tile_size: u32,
}

/// A finished render.
#[derive(Debug)]
pub struct RenderOutput {
    /// The accumulated film.
    pub film: Film,
    /// Wall time of rendering (excluding scene loading).
    pub elapsed: Duration,
    /// Samples per pixel rendered.
    pub spp: u32,
}

/// Why rendering could not start.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// The thread pool could not be created.
    #[error("cannot start {threads} render threads: {message}")]
    ThreadPool {
        /// Requested threads.
        threads: usize,
        /// The reason.
        message: String,
    },
}

/// A rayon pool of `threads` threads (0 = all cores).
pub fn thread_pool(threads: usize) -> Result<rayon::ThreadPool, RenderError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| RenderError::ThreadPool { threads, message: e.to_string() })
}

impl Renderer {
    /// Renders `scene` on this machine; for EMIS also returns the final state (decisions and
    /// reports).
    pub fn render(
        &self,
        scene: &Scene,
        opts: &RenderOptions,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(RenderOutput, Option<EmisState>), RenderError> {
        Ok(match self {
            Renderer::Tiles(i) => (render(scene, i.as_ref(), opts, progress)?, None),
            Renderer::Emis(config, settings) => {
                let out = render_emis(scene, *settings, config, opts, progress)?;
                (out.render, Some(out.state))
            }
        })
    }
}

/// The driver's shape of a local render of `scene` with `opts`: image tiles of
/// `opts.tile_size` for integrators that have them, else full-frame iterations.
pub fn shape(scene: &Scene, opts: &RenderOptions, full_frame: bool) -> Shape {
    let (width, height) = (scene.camera.width, scene.camera.height);
    Shape { width, height, budget: opts.budget, tile: (!full_frame).then_some(opts.tile_size), emis: None }
}

/// Milliseconds since `start`, the driver's clock for a local render.
pub(crate) fn ms_since(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}

/// Renders `scene` with `integrator`, running the job [`Driver`] on the pool: a pass's image
/// tiles in parallel, full-frame tiles one after another (parallel inside), merged in pass
/// order. `progress(done, total)` is called after each tile, in units of pixel-samples
/// (`total` is an estimate under a time budget).
pub fn render(
    scene: &Scene,
    integrator: &dyn Integrator,
    opts: &RenderOptions,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<RenderOutput, RenderError> {
    let pool = thread_pool(opts.threads)?;
    let full_frame = integrator.full_frame();
    let pixels = scene.camera.width as u64 * scene.camera.height as u64;
    let mut film = Film::new(&scene.film);
    let start = Instant::now();
    let (mut driver, mut tiles) = Driver::new(shape(scene, opts, full_frame));
    driver.start(0.0);
    let done = AtomicU64::new(0);
    loop {
        let spp_before = tiles.first().map_or(0, |t| t.samples.start);
        let total = driver.expected_total(spp_before, ms_since(start)) as u64 * pixels;
        let render = |tile: &TileSpec| {
            let mut accum = TileAccum::new(tile.rect, &scene.film);
            integrator.render_tile(scene, &TileRequest::new(tile.rect, tile.samples.clone(), opts.seed), &mut accum);
            let n = done.fetch_add(tile.pixel_samples(), Ordering::Relaxed) + tile.pixel_samples();
            progress(n, total.max(n));
            accum
        };
        if full_frame {
            // one full frame at a time: a pass may hold hundreds of iterations
            for tile in &tiles {
                let accum = pool.install(|| render(tile));
                film.merge_tile(&accum);
            }
        } else {
            let results: Vec<TileAccum> = pool.install(|| tiles.par_iter().map(render).collect());
            results.iter().for_each(|t| film.merge_tile(t));
        }
        tiles = match driver.barrier(ms_since(start)) {
            Step::Render(next) => next,
            Step::Finish => break,
            Step::Update(_) => unreachable!("invariant: only EMIS jobs update"),
        };
    }
    Ok(RenderOutput { film, elapsed: start.elapsed(), spp: driver.planned() })
}
