//! `lt`: light tracing. Each iteration traces N = ⌊ν·P⌋ light paths (ν light paths per pixel,
//! P pixels) and connects every vertex, the light vertex included, to the camera, splatting
//! the contribution into the pixel it projects to (Mitsuba's `ptracer`).
//!
//! Parameters: `max_depth` (segments, as for `path`), ν (`--light-paths-per-pixel`).
//!
//! Light tracing cannot form paths whose camera end is a delta (smooth glass or mirror)
//! surface: pixels that see such surfaces, or an infinite environment directly, stay dark.
//! Use it where light reaches the visible surfaces in ways camera paths find hard (small,
//! hidden lights) and no specular surface is seen directly.

use super::path::light_path::{LIGHT_PATH_CHUNK, MAX_BIDIR_EDGES, light_path_count, trace_light_path};
use super::path::techniques::connect_to_camera;
use super::{Integrator, PathSettings, TileRequest};
use crate::film::TileAccum;
use crate::math::Rgb;
use crate::sampler::Sampler;
use crate::scene::Scene;
use glam::Vec2;
use rayon::prelude::*;

/// The light tracer.
#[derive(Clone, Debug)]
pub struct LightTracer {
    /// Depth settings (`max_depth`; Russian roulette from `rr_depth`).
    pub settings: PathSettings,
    /// Light paths per pixel per iteration (ν).
    pub light_paths_per_pixel: f32,
}

impl LightTracer {
    fn max_edges(&self) -> u32 {
        // the connection to the camera adds one edge
        self.settings.max_depth.min(MAX_BIDIR_EDGES + 1).saturating_sub(1)
    }

    /// Splats of light paths `range` of iteration `iteration`.
    fn trace_chunk(
        &self,
        scene: &Scene,
        seed: u64,
        iteration: u32,
        range: std::ops::Range<u32>,
        scale: f32,
    ) -> Vec<(Vec2, Rgb)> {
        let mut splats = Vec::new();
        let mut vertices = Vec::with_capacity(16);
        for index in range {
            vertices.clear();
            let mut sampler = Sampler::for_light_path(seed, index, iteration);
            trace_light_path(scene, &mut sampler, self.max_edges(), self.settings.rr_depth, &mut vertices);
            for v in &vertices {
                if let Some((value, raster)) = connect_to_camera(scene, v) {
                    splats.push((raster, value * scale));
                }
            }
        }
        splats
    }
}

impl Integrator for LightTracer {
    fn name(&self) -> &'static str {
        "lt"
    }

    fn full_frame(&self) -> bool {
        true
    }

    fn render_tile(&self, scene: &Scene, tile: &TileRequest, accum: &mut TileAccum) {
        let (w, h) = (scene.camera.width, scene.camera.height);
        assert_eq!(tile.rect, crate::film::Rect::full(w, h), "invariant: light tracing renders full-frame tiles");
        if self.settings.max_depth == 0 {
            accum.count_iterations(tile.samples.len() as u32);
            return;
        }
        let n = light_path_count(self.light_paths_per_pixel, w * h).max(1);
        // the pixel filter's importance is P times the image-normalised We
        let scale = (w * h) as f32 / n as f32;
        for iteration in tile.samples.clone() {
            if tile.stop.requested() {
                return;
            }
            let chunks: Vec<Vec<(Vec2, Rgb)>> = (0..n.div_ceil(LIGHT_PATH_CHUNK))
                .into_par_iter()
                .map(|c| {
                    self.trace_chunk(
                        scene,
                        tile.seed,
                        iteration,
                        c * LIGHT_PATH_CHUNK..((c + 1) * LIGHT_PATH_CHUNK).min(n),
                        scale,
                    )
                })
                .collect();
            for splats in &chunks {
                for (raster, value) in splats {
                    accum.add_splat(*raster, *value);
                }
            }
            accum.count_iterations(1);
        }
    }
}
