//! Rendering a batch of leased tiles on the worker's rayon pool. Called from
//! `tokio::task::spawn_blocking`, never on an async thread. Image tiles render in parallel,
//! one per rayon task; full-frame tiles parallelise inside the integrator. EMIS tiles render
//! with the lease's strategy and, when asked, return the pilot data (moments, statistics,
//! guides) encoded for the upload. Each tile's start and end are logged (at `info`, with the
//! job id, tile index and duration) from the thread that renders it.

use std::time::Instant;
use tessera_common::emis::{CandidateSet, Strategy, render_iterations_until};
use tessera_common::film::{Rect, TileAccum};
use tessera_common::integrator::{Stop, TileRequest};
use tessera_common::scene::Scene;
use tessera_common::settings::Renderer;

/// A tile to render.
#[derive(Clone, Debug)]
pub struct TileWork {
    /// The job, for the log.
    pub job_id: String,
    /// The tile's index in its job, for the log.
    pub tile: u32,
    /// Pixels.
    pub rect: Rect,
    /// Sample indices.
    pub samples: std::ops::Range<u32>,
    /// Seed of the job.
    pub seed: u64,
    /// Requested when the lease is lost (cancelled, expired): the render gives up.
    pub stop: Stop,
}

/// What an EMIS lease renders with.
#[derive(Clone, Debug)]
pub struct EmisWork {
    /// The pass's counts.
    pub strategy: Strategy,
    /// Whether to return pilot data, and for which candidates.
    pub collect: Option<CandidateSet>,
}

/// A rendered tile.
pub struct TileOutput {
    /// Image sums.
    pub accum: TileAccum,
    /// Seconds spent.
    pub seconds: f64,
    /// Encoded pilot data (empty unless collected).
    pub pilot: Vec<u8>,
}

/// Renders `tiles` with `renderer` on `pool` (`emis` is required for EMIS renderers). A tile
/// whose `stop` was requested comes back incomplete, to be dropped.
pub fn render_batch(
    pool: &rayon::ThreadPool,
    scene: &Scene,
    renderer: &Renderer,
    emis: Option<&EmisWork>,
    tiles: &[TileWork],
) -> Vec<TileOutput> {
    use rayon::prelude::*;
    // the batch's calls trace their light caches into one memory
    let memory = std::sync::Arc::default();
    pool.install(|| match (renderer, emis) {
        (Renderer::Emis(config, settings), Some(work)) => tiles
            .iter()
            .map(|t| {
                let start = started(t);
                let (accum, pilot) = render_iterations_until(
                    scene,
                    *settings,
                    config,
                    &work.strategy,
                    t.seed,
                    t.samples.clone(),
                    work.collect,
                    &t.stop,
                    &memory,
                );
                let pilot = pilot.map(|p| p.encode()).unwrap_or_default();
                TileOutput { accum, seconds: finished(t, start), pilot }
            })
            .collect(),
        (Renderer::Emis(..), None) => unreachable!("invariant: EMIS leases carry a strategy (checked by the runner)"),
        (Renderer::Tiles(integrator), _) => tiles
            .par_iter()
            .map(|t| {
                let start = started(t);
                let mut accum = TileAccum::new(t.rect, &scene.film);
                let req = TileRequest::new(t.rect, t.samples.clone(), t.seed).stoppable(t.stop.clone());
                integrator.render_tile(scene, &req, &mut accum);
                TileOutput { accum, seconds: finished(t, start), pilot: Vec::new() }
            })
            .collect(),
    })
}

/// Logs that `t` starts rendering now; returns the time.
fn started(t: &TileWork) -> Instant {
    tracing::info!(job_id = %t.job_id, tile = t.tile, samples = %format_args!("{}..{}", t.samples.start, t.samples.end), pixels = t.rect.area(), "tile started");
    Instant::now()
}

/// Logs that `t`, started at `start`, ended (finished, or stopped because its lease was lost);
/// returns the seconds it took.
fn finished(t: &TileWork, start: Instant) -> f64 {
    let seconds = start.elapsed().as_secs_f64();
    let duration_ms = (seconds * 1000.0).round() as u64;
    if t.stop.requested() {
        tracing::info!(job_id = %t.job_id, tile = t.tile, duration_ms, "tile stopped: its lease was lost");
    } else {
        tracing::info!(job_id = %t.job_id, tile = t.tile, duration_ms, "tile finished");
    }
    seconds
}
