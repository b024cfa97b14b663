//! Diagnostic, ignored by default: how does the normaliser Ī change the image-level choice?
//! (docs/decisions/0027-decision-truth-over-seeds.md, 0028-pilot-image-not-denoised.md)
//!
//! Per scene, seed and pilot length n, a `vcm` pilot's moments over iterations 0..n. The
//! image-level choice is made with the default outlier rule and six normalisers: the converged
//! reference (box-blurred as Ī is), and the pilot's own image through the guided à-trous
//! filter with 5, 3, 2, 1 or no levels (no levels: the channel mean and the box alone, the
//! default). Each choice's regret against the cached truth is printed, with how many pixels
//! the 5-level Ī puts below half the reference's and the worst of them; nothing is asserted.
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
use tessera_common::integrator::PathSettings;
use tessera_common::scene::Scene;

/// The denoiser's à-trous levels tried; 0 leaves the channel mean and the box alone.
const LEVELS: [u32; 5] = [5, 3, 2, 1, 0];

/// Side of the square images, as in the cached truth.
const SIZE: usize = 128;

/// The reference's channel mean averaged down to `SIZE`², box-blurred as the denoiser's
/// final box.
fn intensity(name: &str) -> Image {
    Image::from_data(SIZE, SIZE, common::reference_intensity(name, SIZE)).box_blur(DenoiseSettings::default().final_box)
}

/// The pilot's data, Ī through the guided filter with each of [`LEVELS`], and the pilot's
/// image without the filter (channel mean, the same box).
fn pilot(
    scene: &Scene,
    config: &EmisConfig,
    seed: u64,
    iterations: std::ops::Range<u32>,
) -> (PilotData, [Image; 5], Image) {
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
    let image = LEVELS
        .map(|levels| denoised_intensity(SIZE, SIZE, &average, &guides, &DenoiseSettings { levels, ..config.denoise }));
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
        restart_share: 0.0,
        incumbent: None,
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
        "| scene | seed | pilot | reference | regret | levels 5 | regret | 3 | regret | 2 | regret | 1 | regret | 0 | regret | pixels Ī < ½ | lowest ratio |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for name in ["caustic-glass", "cornell-box", "veach-mis"] {
        let file = scene_path(name);
        let scene = Scene::load(&file).expect("loads").with_resolution(SIZE as u32, SIZE as u32).expect("square");
        let image = intensity(name);
        let config = EmisConfig::new(EmisMethod::Vcm);
        let t = truth.scene(name).expect("in the truth");
        let cell = |(nu, c): (f32, u32)| format!("ν {nu} c {c} | {:.2}", t.regret(nu, c).unwrap_or(f64::NAN));
        for seed in 1..=3 {
            for n in [1u32, 4, 16] {
                let (whole, denoised, raw) = pilot(&scene, &config, seed, 0..n);
                let pick = |i: &Image| cell(choose(&config, &whole.moments, &whole, i, OutlierStage::Shared));
                let [l5, l3, l2, l1, l0] = &denoised;
                println!(
                    "| {name} | {seed} | {n} | {} | {} | {} | {} | {} | {} | {} |",
                    pick(&image),
                    pick(l5),
                    pick(l3),
                    pick(l2),
                    pick(l1),
                    pick(l0),
                    underestimates(l5, &raw, &image),
                );
            }
        }
    }
}
