//! Diagnostic, ignored by default: per-iteration relative variance of `vcm` on caustic-glass at
//! 128² for several connection counts c and seeds, with the merge mask of
//! `tessera bench decision-truth` (docs/decisions/0018-decision-quality-tests.md, addendum).
//!
//! The cached truth renders every candidate with one seed, so a candidate's figure is one draw of
//! a heavy-tailed lottery: a handful of emitter hits worth ~280 landing in dark pixels decide
//! it. This prints, per (seed, c), the figure the truth uses, the same with the 1 % worst pixels
//! left out, the share of the 10 worst pixels, and which techniques made the samples above 20.
//!
//! ```text
//! SEEDS=1000,1001,1002 CS=1,2,4 NU=1 ITERS=256 \
//!   cargo test --release -p tessera-common --test connection_variance -- --ignored --nocapture
//! ```

mod common;

use common::scene_path;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use tessera_common::emis::denoise::DenoiseSettings;
use tessera_common::emis::filter::Image;
use tessera_common::emis::optimize::{ConnectionScope, MergeScope, OptimizerInput, optimize};
use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, Strategy, render_iterations};
use tessera_common::film::{Film, Rect, TileAccum};
use tessera_common::integrator::observer::{SampleObserver, SampleRecord};
use tessera_common::integrator::path::merge::MergeMask;
use tessera_common::integrator::{Integrator, PathSettings, TileRequest};
use tessera_common::scene::Scene;

/// Side of the square images, as in the cached truth.
const SIZE: usize = 128;
/// Samples whose mean channel exceeds this are counted as fireflies.
const FIREFLY: f32 = 20.0;

fn env_list<T: std::str::FromStr>(name: &str, default: &str) -> Vec<T> {
    std::env::var(name).unwrap_or_else(|_| default.into()).split(',').filter_map(|s| s.trim().parse().ok()).collect()
}

/// The Mitsuba reference averaged over 2 × 2 blocks (exact for the box filter).
fn reference(scene: &std::path::Path) -> Vec<[f64; 3]> {
    let full = tessera_common::film::exr::read_rgb(&scene.with_file_name("reference.exr")).expect("reference");
    let side = (full.pixels.len() as f64).sqrt() as usize;
    let f = side / SIZE;
    let mut out = vec![[0.0f64; 3]; SIZE * SIZE];
    for (i, p) in full.pixels.iter().enumerate() {
        let (x, y) = (i % side, i / side);
        for c in 0..3 {
            out[(y / f) * SIZE + x / f][c] += p[c] as f64 / (f * f) as f64;
        }
    }
    out
}

/// The bench's merge mask: the optimiser's pixel level on a 64-iteration pilot (seed 7).
fn bench_mask(scene: &Scene, reference: &[[f64; 3]]) -> MergeMask {
    let settings = PathSettings::from_scene(scene, None);
    let config = EmisConfig::new(EmisMethod::Vcm);
    let pilot = Strategy::pilot(EmisMethod::Vcm);
    let (_, data) = render_iterations(scene, settings, &config, &pilot, 7, 0..64, Some(CandidateSet::Full));
    let data = data.expect("the pilot collects moments");
    let intensity =
        Image::from_data(SIZE, SIZE, reference.iter().map(|p| ((p[0] + p[1] + p[2]) / 3.0) as f32).collect())
            .box_blur(DenoiseSettings::default().final_box);
    let candidates = config.candidates_of(CandidateSet::Full);
    let decision = optimize(&OptimizerInput {
        restart_share: 0.0,
        incumbent: None,
        candidates: &candidates,
        moments: &data.moments,
        image: &intensity,
        statistics: data.statistics.statistics((SIZE * SIZE) as u32),
        constants: config.constants,
        filters: config.filters,
        merge_scope: MergeScope::PerPixel,
        connection_scope: ConnectionScope::Image,
    });
    MergeMask::PerPixel(Arc::new(decision.merge_mask.data))
}

/// Counts samples above [`FIREFLY`] by technique and path length, with their Σ y².
#[derive(Default)]
struct Fireflies(Mutex<BTreeMap<String, (u32, f64)>>);

impl SampleObserver for Fireflies {
    fn on_sample(&self, r: &SampleRecord) {
        let y = (r.value.x + r.value.y + r.value.z) / 3.0;
        if y > FIREFLY {
            let mut map = self.0.lock().unwrap();
            let e = map.entry(format!("{:?} k={}", r.technique, r.pdfs.len - 1)).or_default();
            e.0 += 1;
            e.1 += (y as f64).powi(2);
        }
    }
}

/// Per-pixel per-iteration variance over (ref² + 1e-4), averaged over channels, from
/// single-iteration renders (as the bench measures it), plus the firefly census.
fn measure(scene: &Scene, strategy: &Strategy, seed: u64, iterations: u32, reference: &[[f64; 3]]) -> Vec<f64> {
    let settings = PathSettings::from_scene(scene, None);
    let integrator = strategy.integrator(settings, true).with_observer(Fireflies::default());
    let rect = Rect::full(SIZE as u32, SIZE as u32);
    let mut sums = vec![[0.0f64; 6]; SIZE * SIZE];
    for it in 0..iterations {
        let mut accum = TileAccum::new(rect, &scene.film);
        integrator.render_tile(scene, &TileRequest::new(rect, it..it + 1, seed), &mut accum);
        let mut film = Film::new(&scene.film);
        film.merge_tile(&accum);
        for (s, p) in sums.iter_mut().zip(film.average()) {
            for c in 0..3 {
                s[c] += p[c] as f64;
                s[3 + c] += (p[c] as f64).powi(2);
            }
        }
    }
    for (kind, (n, y2)) in integrator.observer.0.lock().unwrap().iter() {
        println!("    fireflies {kind}: {n} samples, Σy² {y2:.3e}");
    }
    let k = iterations as f64;
    sums.iter()
        .zip(reference)
        .map(|(s, r)| {
            (0..3).map(|c| ((s[3 + c] - s[c] * s[c] / k) / (k - 1.0)).max(0.0) / (r[c] * r[c] + 1e-4)).sum::<f64>()
                / 3.0
        })
        .collect()
}

#[test]
#[ignore = "diagnostic measurement; minutes in release"]
fn caustic_glass_variance_by_connections_and_seed() {
    let path = scene_path("caustic-glass");
    let scene = Scene::load(&path).expect("scene").with_resolution(SIZE as u32, SIZE as u32).expect("square");
    let reference = reference(&path);
    let mask = bench_mask(&scene, &reference);
    let iterations = env_list::<u32>("ITERS", "256")[0];
    let nu = env_list::<f32>("NU", "1")[0];
    for seed in env_list::<u64>("SEEDS", "1000,1001,1002") {
        for c in env_list::<u32>("CS", "1,2,4") {
            let strategy = Strategy {
                nu,
                connections: tessera_common::integrator::path::connections::Connections::Fixed(c),
                merge: Some(mask.clone()),
            };
            let mut per_pixel = measure(&scene, &strategy, seed, iterations, &reference);
            let n = per_pixel.len() as f64;
            let whole = per_pixel.iter().sum::<f64>() / n;
            per_pixel.sort_by(|a, b| b.total_cmp(a));
            let top10 = per_pixel[..10].iter().sum::<f64>() / n;
            let trimmed = per_pixel[per_pixel.len() / 100..].iter().sum::<f64>() / n;
            println!(
                "seed {seed} ν {nu} c {c}: relative variance {whole:.3}, 10 worst pixels' share {:.2}, \
                 without the worst 1 % {trimmed:.4}",
                top10 / whole
            );
        }
    }
}
