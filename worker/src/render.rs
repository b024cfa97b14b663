//! Rendering a batch of leased tiles on the worker's rayon pool. Called from
//! `tokio::task::spawn_blocking`, never on an async thread. Image tiles render in parallel,
//! one per rayon task; full-frame tiles parallelise inside the integrator.

use std::time::Instant;
use tessera_common::film::{Rect, TileAccum};
use tessera_common::integrator::{Integrator, TileRequest};
use tessera_common::scene::Scene;

/// A tile to render.
#[derive(Clone, Debug)]
pub struct TileWork {
    /// Pixels.
    pub rect: Rect,
    /// Sample indices.
    pub samples: std::ops::Range<u32>,
    /// Seed of the job.
    pub seed: u64,
}

/// Renders `tiles` on `pool`; returns each tile's sums and seconds spent.
pub fn render_batch(
    pool: &rayon::ThreadPool,
    scene: &Scene,
    integrator: &dyn Integrator,
    tiles: &[TileWork],
) -> Vec<(TileAccum, f64)> {
    use rayon::prelude::*;
    pool.install(|| {
        tiles
            .par_iter()
            .map(|t| {
                let start = Instant::now();
                let mut accum = TileAccum::new(t.rect);
                let req = TileRequest { rect: t.rect, samples: t.samples.clone(), seed: t.seed };
                integrator.render_tile(scene, &req, &mut accum);
                (accum, start.elapsed().as_secs_f64())
            })
            .collect()
    })
}
