//! The denoiser's acceptance test (docs/emis.md, checklist 10): the optimiser's decisions with
//! the 1-iteration pilot image as Ī, denoised by the guided filter or not (the default), are
//! within one candidate step of the decisions made with the converged reference as Ī (ν and c
//! each at most one step apart in their candidate lists; merge-mask coverage within 0.1 of the
//! image). Seed 3.

mod common;

use common::scene_path;
use tessera_common::emis::denoise::{Guides, ImageEstimate, denoised_intensity};
use tessera_common::emis::filter::Image;
use tessera_common::emis::optimize::{ConnectionScope, Decision, MergeScope, OptimizerInput, optimize};
use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, PilotData, Strategy, render_iterations};
use tessera_common::film::Film;
use tessera_common::film::exr::read_rgb;
use tessera_common::integrator::PathSettings;
use tessera_common::scene::Scene;

fn check(name: &str, estimate: ImageEstimate) {
    let scene = Scene::load(&scene_path(name)).expect("scene loads");
    let reference = read_rgb(&scene_path(name).with_file_name("reference.exr")).expect("reference");
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut config = EmisConfig::own_pilot(EmisMethod::Vcm);
    config.denoise = estimate.settings();
    let candidates = config.candidates.candidates();
    let settings = PathSettings::from_scene(&scene, None);
    let pilot = Strategy::pilot(EmisMethod::Vcm);
    let (accum, data) = render_iterations(&scene, settings, &config, &pilot, 3, 0..1, Some(CandidateSet::Full));
    let PilotData { moments, statistics, guides } = data.expect("the pilot collects moments");
    let mut film = Film::new(&scene.film);
    film.merge_tile(&accum);
    let (albedo, normal, depth) = guides.means();
    let guides = Guides { albedo: &albedo, normal: &normal, depth: &depth };
    let denoised = denoised_intensity(w as usize, h as usize, &film.average(), &guides, &config.denoise);
    let converged =
        Image::from_data(w as usize, h as usize, reference.pixels.iter().map(|p| (p[0] + p[1] + p[2]) / 3.0).collect())
            .box_blur(config.denoise.final_box);
    let decide = |image: &Image| -> Decision {
        optimize(&OptimizerInput {
            restart_share: 0.0,
            incumbent: None,
            candidates: &candidates,
            moments: &moments,
            image,
            statistics: statistics.statistics(w * h),
            constants: config.constants,
            filters: config.filters,
            merge_scope: MergeScope::PerPixel,
            connection_scope: ConnectionScope::Image,
        })
    };
    let (ours, truth) = (decide(&denoised), decide(&converged));
    let step = |list: &[f32], v: f32| list.iter().position(|&x| x == v).map_or(-1, |i| i as i64);
    let nu_list: Vec<f32> = std::iter::once(0.0).chain(config.candidates.nu.iter().copied()).collect();
    let c_list: Vec<f32> = config.candidates.connections.iter().map(|&c| c as f32).collect();
    let coverage = |d: &Decision| d.merge_mask.data.iter().filter(|&&v| v > 0.1).count() as f64 / (w * h) as f64;
    eprintln!(
        "{name}, {estimate:?}: pilot → ν {} c {} merging {:.3}; reference → ν {} c {} merging {:.3}",
        ours.nu,
        ours.connections,
        coverage(&ours),
        truth.nu,
        truth.connections,
        coverage(&truth)
    );
    assert!((step(&nu_list, ours.nu) - step(&nu_list, truth.nu)).abs() <= 1, "{name}: ν {} vs {}", ours.nu, truth.nu);
    assert!(
        (step(&c_list, ours.connections as f32) - step(&c_list, truth.connections as f32)).abs() <= 1,
        "{name}: c {} vs {}",
        ours.connections,
        truth.connections
    );
    assert!((coverage(&ours) - coverage(&truth)).abs() <= 0.1, "{name}: merge coverage");
}

#[test]
fn indirect_room_decisions_match_the_reference_normalisation() {
    check("indirect-room", ImageEstimate::Pilot);
}

#[test]
fn veach_mis_decisions_match_the_reference_normalisation() {
    check("veach-mis", ImageEstimate::Pilot);
}

/// Fails: the not-denoised Ī chooses ν 0.5 against the reference's ν 2 (three steps); with
/// seeds 1 and 2, ν 0.5 and 0.25 against 2 and 0.75. At one sample per pixel a caustic's Ī
/// is too noisy. The guided filter passes with this seed but not with seed 1 (ν 0.75, c 0
/// against ν 2, c 1). Decision 0028 has why the default is still the pilot image.
#[test]
#[ignore = "known failure, issue 21: at 1 iteration ν 0.5 against 2 (decision 0028)"]
fn caustic_glass_decisions_match_the_reference_normalisation() {
    check("caustic-glass", ImageEstimate::Pilot);
}

#[test]
fn guided_caustic_glass_decisions_match_the_reference_normalisation() {
    check("caustic-glass", ImageEstimate::Guided);
}

#[test]
fn guided_indirect_room_decisions_match_the_reference_normalisation() {
    check("indirect-room", ImageEstimate::Guided);
}
