//! Helpers shared by the integration tests: locating the repository's scenes and rendering.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use tessera_common::film::Film;
use tessera_common::integrator::path::merge::{MergeConfig, MergeMask};
use tessera_common::integrator::{Bidir, Integrator, LightTracer, PathSettings, PathTracer};
use tessera_common::render::{Budget, RenderOptions, render};
use tessera_common::scene::Scene;

/// `scenes/NAME/scene.xml` in the repository.
pub fn scene_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("scenes").join(name).join("scene.xml")
}

/// Renders `scene` with `pt` at `spp` samples per pixel.
pub fn render_pt(scene: &Scene, spp: u32, seed: u64, threads: usize) -> Film {
    render_with(scene, &PathTracer { settings: PathSettings::from_scene(scene, None) }, spp, seed, threads)
}

/// Renders `scene` with `lt` (ν = 1) for `iterations` iterations.
pub fn render_lt(scene: &Scene, iterations: u32, seed: u64, threads: usize) -> Film {
    render_with(
        scene,
        &LightTracer { settings: PathSettings::from_scene(scene, None), light_paths_per_pixel: 1.0 },
        iterations,
        seed,
        threads,
    )
}

/// Renders `scene` with `bdpt` (ν light paths per pixel, c connections) for `iterations`.
pub fn render_bdpt_with(scene: &Scene, nu: f32, c: u32, iterations: u32, seed: u64, threads: usize) -> Film {
    render_with(scene, &Bidir::bdpt(PathSettings::from_scene(scene, None), nu, c), iterations, seed, threads)
}

/// Renders `scene` with vanilla `bdpt` (ν = 1, c = 1).
pub fn render_bdpt(scene: &Scene, iterations: u32, seed: u64, threads: usize) -> Film {
    render_bdpt_with(scene, 1.0, 1, iterations, seed, threads)
}

/// Renders `scene` with `vcm` (ν, c, constant χ, correlation-aware weights on or off).
pub fn render_vcm_with(
    scene: &Scene,
    nu: f32,
    c: u32,
    chi: f32,
    correlation_aware: bool,
    iterations: u32,
    seed: u64,
    threads: usize,
) -> Film {
    let merge = MergeConfig { mask: MergeMask::Constant(chi), correlation_aware };
    render_with(scene, &Bidir::vcm(PathSettings::from_scene(scene, None), nu, c, merge), iterations, seed, threads)
}

/// Renders `scene` with vanilla `vcm` (ν = 1, c = 1, χ = 1, correlation-aware).
pub fn render_vcm(scene: &Scene, iterations: u32, seed: u64, threads: usize) -> Film {
    render_vcm_with(scene, 1.0, 1, 1.0, true, iterations, seed, threads)
}

/// Renders `scene` with any integrator.
pub fn render_with(scene: &Scene, integrator: &dyn Integrator, spp: u32, seed: u64, threads: usize) -> Film {
    let opts = RenderOptions { budget: Budget::Samples(spp), seed, threads, tile_size: 32 };
    render(scene, integrator, &opts, &|_, _| {}).expect("render").film
}

/// Renders `scene` locally with `emis-bdpt` or `emis-vcm` (default configuration) for
/// `iterations` iterations; returns the film and the final state.
pub fn render_emis_state(
    scene: &Scene,
    method: tessera_common::emis::EmisMethod,
    iterations: u32,
    seed: u64,
    threads: usize,
) -> (Film, tessera_common::emis::EmisState) {
    use tessera_common::emis::{EmisConfig, render_emis};
    let opts = RenderOptions { budget: Budget::Samples(iterations), seed, threads, tile_size: 32 };
    let out =
        render_emis(scene, PathSettings::from_scene(scene, None), &EmisConfig::own_pilot(method), &opts, &|_, _| {})
            .expect("render");
    (out.render.film, out.state)
}

/// `emis-bdpt` for `iterations` iterations.
pub fn render_emis_bdpt(scene: &Scene, iterations: u32, seed: u64, threads: usize) -> Film {
    render_emis_state(scene, tessera_common::emis::EmisMethod::Bdpt, iterations, seed, threads).0
}

/// `emis-vcm` for `iterations` iterations.
pub fn render_emis_vcm(scene: &Scene, iterations: u32, seed: u64, threads: usize) -> Film {
    render_emis_state(scene, tessera_common::emis::EmisMethod::Vcm, iterations, seed, threads).0
}

/// The mean of `v` and its standard error (sample standard deviation / √n).
pub fn mean_and_standard_error(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let v: Vec<f64> = v.collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// The channel mean of `scenes/NAME/reference.exr` (square), averaged down to `size`² over
/// blocks of whole pixels, row-major.
pub fn reference_intensity(name: &str, size: usize) -> Vec<f32> {
    let file = scene_path(name).with_file_name("reference.exr");
    let full = tessera_common::film::exr::read_rgb(&file).expect("the scene has a reference");
    let side = (full.pixels.len() as f64).sqrt() as usize;
    let f = side / size;
    let mut out = vec![0.0f32; size * size];
    for (i, p) in full.pixels.iter().enumerate() {
        let (x, y) = (i % side, i / side);
        out[(y / f) * size + x / f] += (p[0] + p[1] + p[2]) / (3 * f * f) as f32;
    }
    out
}
