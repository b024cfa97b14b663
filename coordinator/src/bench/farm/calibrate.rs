//! A real worker's tile render time, measured in-process with the worker's own code path
//! (`Integrator::render_tile` on a one-thread rayon pool): a 64×64 pt tile and one full-frame
//! vcm iteration of a scene. The ingest figures are turned into "workers fed" with these, and
//! the scaling run sizes its job with them.

use anyhow::Context;
use std::path::Path;
use std::time::Instant;
use tessera_common::film::{Rect, TileAccum};
use tessera_common::integrator::TileRequest;
use tessera_common::scene::Scene;
use tessera_common::settings::{IntegratorName, RenderSettings, Renderer};

/// Measured render times on one thread.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TileTimes {
    /// The scene's name.
    pub scene: String,
    /// Film size.
    pub width: u32,
    /// Film height.
    pub height: u32,
    /// The scene's samples per pixel.
    pub pt_spp: u32,
    /// Seconds for a 64×64 pt tile at `pt_spp` (mean over the tiles rendered).
    pub pt_tile_s: f64,
    /// pt samples per second on one thread.
    pub samples_per_s: f64,
    /// Seconds for one full-frame vcm iteration (ν = 1, c = 1).
    pub vcm_iteration_s: f64,
}

/// Renders a few tiles of `scene_path` on one thread.
pub fn measure(scene_path: &Path) -> anyhow::Result<TileTimes> {
    let scene = Scene::load(scene_path).with_context(|| format!("cannot load {}", scene_path.display()))?;
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let (w, h) = (scene.camera.width, scene.camera.height);
    let pt = RenderSettings { integrator: IntegratorName::Pt, ..Default::default() }.resolved(&scene);
    let spp = pt.spp.unwrap_or(1);
    let Renderer::Tiles(pt) = pt.make_renderer(&scene)? else { anyhow::bail!("pt is a tile integrator") };
    // the 64×64 tiles of the frame, up to four, spread over it
    let tiles = Rect::tiles(w, h, 64);
    let picked: Vec<Rect> = (0..4.min(tiles.len())).map(|i| tiles[i * tiles.len() / 4.min(tiles.len())]).collect();
    let t = Instant::now();
    let mut pixels = 0usize;
    pool.install(|| {
        for rect in &picked {
            let mut accum = TileAccum::new(*rect, &scene.film);
            pt.render_tile(&scene, &TileRequest::new(*rect, 0..spp, 1), &mut accum);
            pixels += rect.area();
        }
    });
    let pt_s = t.elapsed().as_secs_f64();
    let samples_per_s = pixels as f64 * spp as f64 / pt_s;
    let vcm = RenderSettings { integrator: IntegratorName::Vcm, ..Default::default() }.resolved(&scene);
    let Renderer::Tiles(vcm) = vcm.make_renderer(&scene)? else { anyhow::bail!("vcm is a tile integrator") };
    let full = Rect::full(w, h);
    let iterations = 3;
    let t = Instant::now();
    pool.install(|| {
        for i in 0..iterations {
            let mut accum = TileAccum::new(full, &scene.film);
            vcm.render_tile(&scene, &TileRequest::new(full, i..i + 1, 1), &mut accum);
        }
    });
    let vcm_iteration_s = t.elapsed().as_secs_f64() / iterations as f64;
    Ok(TileTimes {
        scene: crate::options::scene_name(scene_path),
        width: w,
        height: h,
        pt_spp: spp,
        pt_tile_s: 64.0 * 64.0 * spp as f64 / samples_per_s,
        samples_per_s,
        vcm_iteration_s,
    })
}
