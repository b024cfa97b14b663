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

use super::path::light_path::trace_light_path;
use super::path::vertex::{PathVertex, VertexKind};
use super::{Integrator, PathSettings, TileRequest};
use crate::bsdf::TransportMode;
use crate::film::TileAccum;
use crate::light::Light;
use crate::math::Rgb;
use crate::sampler::Sampler;
use crate::scene::Scene;
use rayon::prelude::*;

/// Light paths traced per task; splats are merged in task order, so results do not depend on
/// the thread count.
pub const LIGHT_PATH_CHUNK: u32 = 256;

/// Longest subpath, in edges, the bidirectional integrators trace.
pub const MAX_BIDIR_EDGES: u32 = (super::path::mis::MAX_VERTICES - 2) as u32;

/// The light tracer.
#[derive(Clone, Debug)]
pub struct LightTracer {
    /// Depth settings (`max_depth`; Russian roulette from `rr_depth`).
    pub settings: PathSettings,
    /// Light paths per pixel per iteration (ν).
    pub light_paths_per_pixel: f32,
}

/// Number of light paths per iteration for ν and P pixels: ⌊ν·P⌋, at least 1 unless ν = 0
/// (no light paths: the bidirectional engine then path traces with hits and NEE only).
pub fn light_path_count(nu: f32, pixels: u32) -> u32 {
    if nu <= 0.0 { 0 } else { ((nu as f64 * pixels as f64).floor() as u32).max(1) }
}

/// Contribution of light-path vertex `v` (whose predecessor on the path is `prev`, if any)
/// seen by the camera, and the raster position it lands on. Ignores MIS.
pub fn connect_to_camera(scene: &Scene, v: &PathVertex) -> Option<(Rgb, glam::Vec2)> {
    let cam = &scene.camera;
    let cs = cam.sample_direct(v.p)?;
    let value = match v.kind {
        VertexKind::Light { light } => match &scene.lights[light as usize] {
            Light::Area { radiance, .. } => {
                Light::eval_area(*radiance, v.n_geo, cs.wi) * (v.n_geo.dot(cs.wi).abs() * v.beta.x)
            }
            Light::Point { intensity, .. } => *intensity * v.beta.x,
            Light::Constant { .. } => return None,
        },
        VertexKind::Camera => return None,
        VertexKind::Surface { material } => {
            let frame = v.frame();
            let f = scene.materials[material as usize].eval(
                frame.to_local(v.wo),
                frame.to_local(cs.wi),
                TransportMode::Importance,
            );
            v.beta * f * (v.importance_correction(v.wo, cs.wi) * v.n_shading.dot(cs.wi).abs())
        }
    };
    if value == Rgb::ZERO {
        return None;
    }
    if !super::path::techniques::visible(scene, v, &super::path::techniques::camera_vertex(scene)) {
        return None;
    }
    Some((value * cs.weight, cs.raster))
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
    ) -> Vec<(u32, Rgb)> {
        let mut splats = Vec::new();
        let mut vertices = Vec::with_capacity(16);
        let width = scene.camera.width;
        for index in range {
            vertices.clear();
            let mut sampler = Sampler::for_light_path(seed, index, iteration);
            trace_light_path(scene, &mut sampler, self.max_edges(), self.settings.rr_depth, &mut vertices);
            for v in &vertices {
                if let Some((value, raster)) = connect_to_camera(scene, v) {
                    let pixel = raster.y as u32 * width + raster.x as u32;
                    splats.push((pixel, value * scale));
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
            let chunks: Vec<Vec<(u32, Rgb)>> = (0..n.div_ceil(LIGHT_PATH_CHUNK))
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
                for (pixel, value) in splats {
                    accum.add_splat(*pixel as usize, *value);
                }
            }
            accum.count_iterations(1);
        }
    }
}
