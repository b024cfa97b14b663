//! Local rendering: splits the image into tiles, renders them on a rayon pool in passes of
//! sample ranges, and merges their sums into a [`Film`] in a fixed order, so the result is
//! bit-identical for any thread count.

use crate::emis::{EmisState, render_emis};
use crate::film::{Film, Rect, TileAccum};
use crate::integrator::{Integrator, TileRequest};
use crate::scene::Scene;
use crate::settings::Renderer;
use rayon::prelude::*;
use std::time::{Duration, Instant};

/// How much to render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    /// Exactly this many samples per pixel.
    Samples(u32),
    /// Passes until this much wall time is used (at least one sample per pixel).
    Time(Duration),
}

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

/// Renders `scene` with `integrator`. `progress(done, total)` is called after each tile, in
/// units of pixel-samples (`total` is an estimate under a time budget).
pub fn render(
    scene: &Scene,
    integrator: &dyn Integrator,
    opts: &RenderOptions,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<RenderOutput, RenderError> {
    let pool = thread_pool(opts.threads)?;
    let (w, h) = (scene.camera.width, scene.camera.height);
    // image-level integrators render the full frame, one iteration per tile, parallel inside
    let tiles = if integrator.full_frame() { vec![Rect::full(w, h)] } else { Rect::tiles(w, h, opts.tile_size) };
    let max_pass = if integrator.full_frame() { 1 } else { u32::MAX };
    let mut film = Film::new(&scene.film);
    let start = Instant::now();
    let pixels = w as u64 * h as u64;
    let done = std::sync::atomic::AtomicU64::new(0);
    let mut spp_done = 0u32;
    let total_estimate = |spp_done: u32, per_spp: Option<f64>| -> u64 {
        match (opts.budget, per_spp) {
            (Budget::Samples(n), _) => n as u64 * pixels,
            (Budget::Time(t), Some(s)) => ((t.as_secs_f64() / s).max(spp_done as f64) as u64).max(1) * pixels,
            (Budget::Time(_), None) => pixels,
        }
    };
    loop {
        let per_spp = (spp_done > 0).then(|| start.elapsed().as_secs_f64() / spp_done as f64);
        let pass = match opts.budget {
            Budget::Samples(n) => (n - spp_done).min(max_pass),
            Budget::Time(t) => {
                let remaining = t.as_secs_f64() - start.elapsed().as_secs_f64();
                match per_spp {
                    None => 1,
                    Some(_) if remaining <= 0.0 => 0,
                    // aim for passes of about a tenth of the budget, never past the deadline
                    Some(s) => ((remaining / s).floor() as u32).min(((t.as_secs_f64() * 0.1 / s) as u32).max(1)),
                }
                .min(max_pass)
                .min(crate::settings::MAX_SPP.saturating_sub(spp_done))
            }
        };
        if pass == 0 {
            break;
        }
        let samples = spp_done..spp_done + pass;
        let total = total_estimate(spp_done, per_spp);
        let results: Vec<TileAccum> = pool.install(|| {
            tiles
                .par_iter()
                .map(|rect| {
                    let mut accum = TileAccum::new(*rect, &scene.film);
                    integrator.render_tile(scene, &TileRequest::new(*rect, samples.clone(), opts.seed), &mut accum);
                    let n = done.fetch_add(rect.area() as u64 * pass as u64, std::sync::atomic::Ordering::Relaxed)
                        + rect.area() as u64 * pass as u64;
                    progress(n, total.max(n));
                    accum
                })
                .collect()
        });
        for t in &results {
            film.merge_tile(t);
        }
        spp_done += pass;
        if matches!(opts.budget, Budget::Samples(n) if spp_done >= n) {
            break;
        }
    }
    Ok(RenderOutput { film, elapsed: start.elapsed(), spp: spp_done })
}
