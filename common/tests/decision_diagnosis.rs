//! Diagnostic, ignored by default: where do the decision tests' failures on caustic-glass and
//! veach-mis come from, the moments or Ī? (docs/decisions/0027-decision-truth-over-seeds.md)
//!
//! Per scene, seed and pilot length n, a `vcm` pilot's moments over iterations 0..n and over
//! each half. The image-level choice is made five ways, with Ī the converged reference
//! (box-blurred as the denoiser's output is) unless said otherwise: the default outlier rule;
//! `each` (every candidate's own top 0.1 % before the filter); `halves`, the default after
//! zeroing, per candidate, the 0.1 % of pixels whose smaller half-moment is largest (would it
//! tell concentrated excess, which the metric drops, from one-sample spikes?); the default
//! with Ī the pilot's own denoised image, as an update computes it; and the default with Ī the
//! pilot's image without the denoiser (channel mean, the same box). Each choice's regret
//! against the cached truth is printed, with how many pixels the pilot's Ī puts below half the
//! reference's and the worst of them; nothing is asserted.
//!
//! ```text
//! cargo test -p tessera-common --test decision_diagnosis -- --ignored --nocapture
//! ```

mod common;

use common::scene_path;
use tessera_common::emis::decision_truth::DecisionTruth;
use tessera_common::emis::denoise::{DenoiseSettings, Guides, denoised_intensity};
use tessera_common::emis::filter::Image;
use tessera_common::emis::moments::MomentBuffer;
use tessera_common::emis::optimize::{ConnectionScope, MergeScope, OptimizerInput, OutlierStage, optimize};
use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, PilotData, Strategy, render_iterations};
use tessera_common::film::Film;
use tessera_common::film::compare::DROPPED_FRACTION;
use tessera_common::integrator::PathSettings;
use tessera_common::scene::Scene;

/// Side of the square images, as in the cached truth.
const SIZE: usize = 128;

/// The reference's channel mean averaged over 2 × 2 blocks, box-blurred as the denoiser's
/// final box.
fn intensity(scene: &std::path::Path) -> Image {
    let full = tessera_common::film::exr::read_rgb(&scene.with_file_name("reference.exr")).expect("reference");
    let side = (full.pixels.len() as f64).sqrt() as usize;
    let f = side / SIZE;
    let mut out = vec![0.0f32; SIZE * SIZE];
    for (i, p) in full.pixels.iter().enumerate() {
        let (x, y) = (i % side, i / side);
        out[(y / f) * SIZE + x / f] += (p[0] + p[1] + p[2]) / (3 * f * f) as f32;
    }
    Image::from_data(SIZE, SIZE, out).box_blur(DenoiseSettings::default().final_box)
}

/// The pilot's data, Ī as an update computes it (the pilot's image, denoised) and the pilot's
/// image without the denoiser (channel mean, the same box).
fn pilot(scene: &Scene, config: &EmisConfig, seed: u64, iterations: std::ops::Range<u32>) -> (PilotData, Image, Image) {
    let settings = PathSettings::from_scene(scene, None);
    let strategy = Strategy::pilot(EmisMethod::Vcm);
    let (accum, data) =
        render_iterations(scene, settings, config, &strategy, seed, iterations, Some(CandidateSet::Full));
    let data = data.expect("the pilot collects moments");
    let mut film = Film::new(&scene.film);
    film.merge_tile(&accum);
    let (albedo, normal, depth) = data.guides.means();
    let guides = Guides { albedo: &albedo, normal: &normal, depth: &depth };
    let average = film.average();
    let image = denoised_intensity(SIZE, SIZE, &average, &guides, &config.denoise);
    let raw = Image::from_data(SIZE, SIZE, average.iter().map(|p| (p[0] + p[1] + p[2]) / 3.0).collect())
        .box_blur(config.denoise.final_box);
    (data, image, raw)
}

/// How many pixels `pilot` puts below half of `reference` (both + 0.01), and the lowest
/// ratio with its pixel and the value there without the denoiser.
fn underestimates(pilot: &Image, raw: &Image, reference: &Image) -> String {
    let ratio = |p: usize| (pilot.data[p] + 0.01) / (reference.data[p] + 0.01);
    let low = (0..SIZE * SIZE).filter(|&p| ratio(p) < 0.5).count();
    let worst = (0..SIZE * SIZE).min_by(|&a, &b| ratio(a).total_cmp(&ratio(b))).unwrap_or(0);
    format!(
        "{low} | {:.3} at ({}, {}): {:.3} (not denoised {:.3}) against {:.3}",
        ratio(worst),
        worst % SIZE,
        worst / SIZE,
        pilot.data[worst],
        raw.data[worst],
        reference.data[worst]
    )
}

/// `whole` with, per candidate, the pixels whose smaller relative half-moment is among the
/// top 0.1 % zeroed (flagged pixels stay flagged).
fn drop_consistent_outliers(whole: &MomentBuffer, halves: [&MomentBuffer; 2], image: &Image) -> MomentBuffer {
    let n = SIZE * SIZE;
    let drop = (n as f64 * DROPPED_FRACTION).ceil() as usize;
    let mut out = whole.clone();
    for c in 0..whole.candidates {
        let mut keys: Vec<(f64, usize)> = (0..n)
            .map(|p| {
                let norm = (image.data[p] as f64).powi(2) + 1e-4;
                let m = halves.map(|h| h.moment(p as u32, c) / norm);
                (if m[0].is_finite() && m[1].is_finite() { m[0].min(m[1]) } else { 0.0 }, p)
            })
            .collect();
        keys.sort_by(|a, b| b.0.total_cmp(&a.0));
        for &(key, p) in keys.iter().take(drop) {
            let i = p * whole.candidates + c;
            if key > 0.0 && out.sums[i].is_finite() {
                out.sums[i] = 0.0;
            }
        }
    }
    out
}

fn choose(
    config: &EmisConfig,
    moments: &MomentBuffer,
    data: &PilotData,
    image: &Image,
    rule: OutlierStage,
) -> (f32, u32) {
    let candidates = config.candidates_of(CandidateSet::Full);
    let mut filters = config.filters;
    filters.outliers = rule;
    let decision = optimize(&OptimizerInput {
        candidates: &candidates,
        moments,
        image,
        statistics: data.statistics.statistics((SIZE * SIZE) as u32),
        constants: config.constants,
        filters,
        merge_scope: MergeScope::PerPixel,
        connection_scope: ConnectionScope::Image,
    });
    (decision.nu, decision.connections)
}

#[test]
#[ignore = "diagnostic measurement"]
fn decisions_by_outlier_rule_and_normaliser() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/emis-decision-truth.json");
    let truth: DecisionTruth = serde_json::from_str(&std::fs::read_to_string(path).expect("truth")).expect("parses");
    println!(
        "| scene | seed | pilot | default | regret | each | regret | halves | regret | default, Ī of the pilot | regret | default, Ī of the pilot not denoised | regret | pixels Ī < ½ | lowest ratio |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for name in ["caustic-glass", "cornell-box", "veach-mis"] {
        let file = scene_path(name);
        let scene = Scene::load(&file).expect("loads").with_resolution(SIZE as u32, SIZE as u32).expect("square");
        let image = intensity(&file);
        let config = EmisConfig::new(EmisMethod::Vcm);
        let t = truth.scene(name).expect("in the truth");
        let cell = |(nu, c): (f32, u32)| format!("ν {nu} c {c} | {:.2}", t.regret(nu, c).unwrap_or(f64::NAN));
        for seed in 1..=3 {
            for n in [4u32, 16] {
                let (whole, denoised, raw) = pilot(&scene, &config, seed, 0..n);
                let (a, ..) = pilot(&scene, &config, seed, 0..n / 2);
                let (b, ..) = pilot(&scene, &config, seed, n / 2..n);
                let halves = drop_consistent_outliers(&whole.moments, [&a.moments, &b.moments], &image);
                println!(
                    "| {name} | {seed} | {n} | {} | {} | {} | {} | {} | {} |",
                    cell(choose(&config, &whole.moments, &whole, &image, OutlierStage::Shared)),
                    cell(choose(&config, &whole.moments, &whole, &image, OutlierStage::Each)),
                    cell(choose(&config, &halves, &whole, &image, OutlierStage::Shared)),
                    cell(choose(&config, &whole.moments, &whole, &denoised, OutlierStage::Shared)),
                    cell(choose(&config, &whole.moments, &whole, &raw, OutlierStage::Shared)),
                    underestimates(&denoised, &raw, &image),
                );
            }
        }
    }
}
