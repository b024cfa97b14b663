//! The estimator's acceptance tests on a real scene (docs/emis.md, checklist 5 and 6): the
//! second moments one pilot predicts for other candidates agree with the second moments
//! measured by rendering each candidate itself, and the estimator's buffers are deterministic
//! and merge across "workers".
//!
//! What is compared: per iteration, Σ over pixels of Σ over samples of y² (the quantity M
//! estimates; by linearity of expectation it needs no independence assumption). The pilot's
//! δ-reweighted estimate for candidate n and n's own measurement are independent renders, so
//! their means must agree within 4 combined standard errors (per-iteration spread, 10
//! iterations each, more with `EMIS_IT`). Merging is left out here: the merge kernel's two
//! moment conventions are compared with measured variances by `tessera bench ground-truth`
//! (docs/emis.md, D3).

mod common;

use common::{mean_and_standard_error, scene_path};
use tessera_common::emis::candidate::Candidate;
use tessera_common::emis::estimator::MomentEstimator;
use tessera_common::emis::moments::MomentBuffer;
use tessera_common::film::{Rect, TileAccum};
use tessera_common::integrator::path::connections::Connections;
use tessera_common::integrator::{Bidir, Integrator, PathSettings, TileRequest};
use tessera_common::scene::Scene;

/// Iterations per render: 10, or `EMIS_IT` for longer manual checks.
fn iterations() -> u32 {
    std::env::var("EMIS_IT").ok().and_then(|v| v.parse().ok()).unwrap_or(10)
}

/// Per-iteration image totals of every candidate's moment, from `pilot` (ν, c).
fn per_iteration_totals(scene: &Scene, pilot: (f32, u32), candidates: &[Candidate], seed: u64) -> Vec<Vec<f64>> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    // without Russian roulette: its survival probabilities are not part of the techniques'
    // densities, so with it the moments are estimated slightly off (0.15 % for ν = 0.25,
    // c = 0 on this scene at 60 iterations, 8σ); the estimator is exact for the model it has
    let settings = PathSettings { rr_depth: u32::MAX, ..PathSettings::from_scene(scene, None) };
    (0..iterations())
        .map(|it| {
            let estimator = MomentEstimator::new(w, h, candidates);
            let bidir = Bidir::bdpt(settings, pilot.0, pilot.1).with_observer(&estimator);
            let mut accum = TileAccum::new(Rect::full(w, h), &scene.film);
            bidir.render_tile(scene, &TileRequest::new(Rect::full(w, h), it..it + 1, seed), &mut accum);
            let (buffer, _) = estimator.snapshot();
            (0..candidates.len()).map(|c| (0..w * h).map(|p| buffer.moment(p, c)).sum::<f64>()).collect()
        })
        .collect()
}

#[test]
fn pilot_moments_agree_with_each_candidate_rendered_directly() {
    let scene = Scene::load(&scene_path("cornell-box")).expect("scene loads");
    let candidates = [
        Candidate::PATH_TRACING,
        Candidate { nu: 0.25, connections: 0, merge: false },
        Candidate { nu: 2.0, connections: 4, merge: false },
        Candidate { nu: 0.5, connections: 8, merge: false },
    ];
    let pilot = per_iteration_totals(&scene, (1.0, 1), &candidates, 1);
    let mut means = Vec::new();
    for (c, cand) in candidates.iter().enumerate() {
        let predicted = mean_and_standard_error(pilot.iter().map(|t| t[c]));
        let direct = per_iteration_totals(&scene, (cand.nu, cand.connections), &[*cand], 2);
        let measured = mean_and_standard_error(direct.iter().map(|t| t[0]));
        let sigma = (predicted.1.powi(2) + measured.1.powi(2)).sqrt();
        eprintln!(
            "{cand:?}: pilot predicts {:.4e} ± {:.1e}, direct {:.4e} ± {:.1e}",
            predicted.0, predicted.1, measured.0, measured.1
        );
        assert!(
            (predicted.0 - measured.0).abs() < 4.0 * sigma,
            "{cand:?}: pilot predicts {:.4e} ± {:.1e}, rendering it measures {:.4e} ± {:.1e}",
            predicted.0,
            predicted.1,
            measured.0,
            measured.1
        );
        means.push(measured);
    }
    // the test has power: the candidates' moments differ by far more than the tolerance
    let (lo, hi) = means.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), m| (lo.min(m.0), hi.max(m.0)));
    let widest = means.iter().map(|m| m.1).fold(0.0, f64::max);
    assert!(hi - lo > 10.0 * widest, "candidates are distinguishable: {means:?}");
}

#[test]
fn moment_buffers_are_thread_count_independent_and_merge_like_one_run() {
    let scene = Scene::load(&scene_path("caustic-glass")).expect("scene loads");
    let (w, h) = (scene.camera.width, scene.camera.height);
    let candidates = tessera_common::emis::candidate::CandidateConfig::vcm().candidates();
    let settings = PathSettings::from_scene(&scene, None);
    let render = |iterations: std::ops::Range<u32>, threads: usize| -> MomentBuffer {
        let estimator = MomentEstimator::new(w, h, &candidates);
        let merge = tessera_common::integrator::path::merge::MergeConfig {
            mask: tessera_common::integrator::path::merge::MergeMask::Constant(1.0),
            correlation_aware: true,
        };
        let vcm = Bidir::vcm(settings, 1.0, 1, merge).with_observer(&estimator);
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let mut accum = TileAccum::new(Rect::full(w, h), &scene.film);
        pool.install(|| vcm.render_tile(&scene, &TileRequest::new(Rect::full(w, h), iterations, 5), &mut accum));
        estimator.snapshot().0
    };
    let one = render(0..2, 1);
    assert_eq!(one.iterations, 2);
    assert!(one.sums.iter().any(|&v| v > 0.0) && one.sums.iter().all(|v| !v.is_nan()));
    let two_threads = render(0..2, 2);
    assert!(one.sums.iter().zip(&two_threads.sums).all(|(a, b)| a.to_bits() == b.to_bits()), "bit-identical");
    // two workers rendering one iteration each, merged
    let mut first = render(0..1, 2);
    first.merge(&render(1..2, 2)).unwrap();
    assert_eq!(first.iterations, one.iterations);
    for (a, b) in first.sums.iter().zip(&one.sums) {
        assert_eq!(a.is_infinite(), b.is_infinite());
        if b.is_finite() {
            assert!((a - b).abs() <= 1e-6 * b.abs().max(1e-30), "{a} vs {b}");
        }
    }
}

/// While path tracing is the strategy, a collecting call records moments in iteration 0, those
/// ≡ 2 mod 4 before `SPARSE_FROM` and those ≡ 6 mod 8 after it only (`collects_moments`), its
/// pilot data counts exactly those, and guides stop after `GUIDE_ITERATIONS`; another
/// iteration's image is `pt`'s own.
#[test]
fn pt_strategy_records_moments_in_a_quarter_then_an_eighth_of_the_iterations() {
    use tessera_common::emis::denoise::DenoiseSettings;
    use tessera_common::emis::{
        CandidateSet, EmisConfig, EmisMethod, GUIDE_ITERATIONS, SPARSE_FROM, Strategy, render_iterations,
    };
    use tessera_common::integrator::PathTracer;
    let scene = Scene::load(&scene_path("cornell-box")).expect("scene loads");
    let settings = PathSettings::from_scene(&scene, None);
    // the guided Ī, whose updates read guides
    let config = EmisConfig { denoise: DenoiseSettings::GUIDED, ..EmisConfig::own_pilot(EmisMethod::Vcm) };
    let pt = Strategy { nu: 0.0, connections: Connections::Fixed(0), merge: None };
    let sparse = [SPARSE_FROM + 2, SPARSE_FROM + 10];
    for skipped in [1, 3, 4, 5, 8].into_iter().chain(sparse) {
        let (_, none) =
            render_iterations(&scene, settings, &config, &pt, 3, skipped..skipped + 1, Some(CandidateSet::Full));
        assert!(none.is_none(), "iteration {skipped} of a pt strategy records nothing");
    }
    let (odd, _) = render_iterations(&scene, settings, &config, &pt, 3, 3..4, Some(CandidateSet::Full));
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut direct = TileAccum::new(Rect::full(w, h), &scene.film);
    let request = TileRequest::new(Rect::full(w, h), 3..4, 3);
    PathTracer { settings }.render_tile(&scene, &request, &mut direct);
    assert_eq!(odd.sum, direct.sum, "a non-recording iteration is rendered by pt");
    for recorded in [0, 2, 6, SPARSE_FROM + 6, SPARSE_FROM + 14] {
        let (_, data) =
            render_iterations(&scene, settings, &config, &pt, 3, recorded..recorded + 1, Some(CandidateSet::Full));
        let data = data.unwrap_or_else(|| panic!("iteration {recorded} records"));
        let guides = u32::from(recorded < GUIDE_ITERATIONS);
        assert_eq!((data.moments.iterations, data.statistics.iterations, data.guides.samples), (1, 1, guides));
    }
    // a call that contains a recording iteration records all of its iterations
    let (_, two) = render_iterations(&scene, settings, &config, &pt, 3, 5..7, Some(CandidateSet::Full));
    assert_eq!(two.expect("5..7 contains 6").moments.iterations, 2);
    let late = (GUIDE_ITERATIONS..).find(|i| i % 8 == 6).expect("some iteration is ≡ 6 mod 8");
    let (_, late) = render_iterations(&scene, settings, &config, &pt, 3, late..late + 1, Some(CandidateSet::Full));
    let late = late.expect("iterations ≡ 6 mod 8 record");
    assert_eq!((late.moments.iterations, late.guides.samples), (1, 0), "no guides after GUIDE_ITERATIONS");
    // a bidirectional strategy records every iteration
    let (_, bidir) = render_iterations(
        &scene,
        settings,
        &config,
        &Strategy::pilot(EmisMethod::Bdpt),
        3,
        3..4,
        Some(CandidateSet::Full),
    );
    assert!(bidir.is_some());
}

/// The denoiser's guides come from the pilot's own primary vertices: on cornell-box, where
/// every surface is diffuse, a one-sample albedo is exactly a reflectance of the scene;
/// normals are unit, distances positive, and two calls merge into the guides of one.
#[test]
fn guides_are_the_pilots_primary_vertices_and_merge_like_one_run() {
    use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, Strategy, render_iterations};
    let scene = Scene::load(&scene_path("cornell-box")).expect("scene loads");
    let settings = PathSettings::from_scene(&scene, None);
    use tessera_common::emis::denoise::DenoiseSettings;
    let config = EmisConfig { denoise: DenoiseSettings::GUIDED, ..EmisConfig::own_pilot(EmisMethod::Bdpt) };
    let pilot = Strategy::pilot(EmisMethod::Bdpt);
    let guides = |iterations| {
        let (_, data) = render_iterations(&scene, settings, &config, &pilot, 7, iterations, Some(CandidateSet::Full));
        data.expect("the pilot collects").guides
    };
    let one = guides(0..1);
    assert_eq!(one.samples, 1);
    let reflectances = [[0.885809, 0.698859, 0.666422], [0.105421, 0.37798, 0.076425], [0.570068, 0.043014, 0.044371]];
    let mut hits = 0;
    for ((albedo, normal), depth) in one.albedo.iter().zip(&one.normal).zip(&one.depth) {
        if *depth == 0.0 {
            assert_eq!((*albedo, *normal), ([0.0; 3], [0.0; 3]), "an escaped camera ray has no guides");
            continue;
        }
        hits += 1;
        assert!(*depth > 0.0);
        assert!((glam::Vec3::from_array(*normal).length() - 1.0).abs() < 1e-4, "unit normal {normal:?}");
        let is = |r: &[f32; 3]| r.iter().zip(albedo).all(|(a, b)| (a - b).abs() < 1e-4);
        assert!(*albedo == [0.0; 3] || reflectances.iter().any(is), "albedo {albedo:?} is a reflectance");
    }
    assert!(hits > one.depth.len() / 2, "most camera rays hit the box");
    let mut merged = one.clone();
    merged.merge(&guides(1..2)).unwrap();
    assert_eq!(merged, guides(0..2), "guides of two calls add up to one call's, bit for bit");
}

/// Guides are recorded only for updates that read them: the guided Ī's, and a path-tracing
/// start's (decision 0029). A pilot for the default Ī leaves them out: zero sums, no samples,
/// so its uploads carry none.
#[test]
fn guides_are_recorded_only_where_an_update_reads_them() {
    use tessera_common::emis::denoise::DenoiseSettings;
    use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, Strategy, render_iterations};
    let scene = Scene::load(&scene_path("cornell-box")).expect("scene loads");
    let settings = PathSettings::from_scene(&scene, None);
    let default = EmisConfig::own_pilot(EmisMethod::Vcm);
    let guided = EmisConfig { denoise: DenoiseSettings::GUIDED, ..EmisConfig::own_pilot(EmisMethod::Vcm) };
    let start = EmisConfig::new(EmisMethod::Vcm);
    let record = |config: &EmisConfig, strategy: &Strategy, set| {
        let (_, data) = render_iterations(&scene, settings, config, strategy, 5, 0..1, Some(set));
        data.expect("iteration 0 records").guides
    };
    let pilot = Strategy::pilot(EmisMethod::Vcm);
    let none = record(&default, &pilot, CandidateSet::Full);
    assert!(none.samples == 0 && none.is_zero(), "the default Ī reads no guides");
    assert_eq!(record(&guided, &pilot, CandidateSet::Full).samples, 1);
    let pt_start = Strategy::path_tracing_start(EmisMethod::Vcm);
    let reduced = record(&start, &pt_start, CandidateSet::Reduced);
    assert!(reduced.samples == 1 && !reduced.is_zero(), "a path-tracing start's updates read guides");
}

/// Issue 21, fault 1: once path tracing wins with a merge mask (ν = 0, χ > 0 somewhere), a
/// collecting iteration traces no light paths for the image, so it must not count merge
/// queries against an empty map: they would be counted with no photons found and dilute φ
/// (photons per query and light path), making merging look cheaper at the next update than
/// it is. The queries it counts are the light probe's, against the probe's own light paths
/// (`tests/light_probe.rs` checks their φ).
#[test]
fn path_tracing_with_a_merge_mask_counts_only_the_probes_queries() {
    use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, Strategy, render_iterations};
    use tessera_common::integrator::LightProbe;
    use tessera_common::integrator::path::light_path::light_path_count;
    use tessera_common::integrator::path::merge::MergeMask;
    let scene = Scene::load(&scene_path("cornell-box")).expect("scene loads");
    let settings = PathSettings::from_scene(&scene, None);
    let config = EmisConfig::own_pilot(EmisMethod::Vcm);
    let merging_pt = Strategy { nu: 0.0, connections: Connections::Fixed(0), merge: Some(MergeMask::Constant(1.0)) };
    let (image, data) = render_iterations(&scene, settings, &config, &merging_pt, 3, 2..3, Some(CandidateSet::Full));
    let statistics = data.expect("iteration 2 records").statistics;
    let probe = light_path_count(LightProbe::LIGHT_PATHS_PER_PIXEL, scene.camera.width * scene.camera.height);
    assert_eq!(statistics.light_paths, probe as u64, "{statistics:?}");
    assert!(statistics.merge_queries > 0 && statistics.photons_per_path > 0.0, "{statistics:?}");
    assert!(statistics.camera_vertices > 0);
    // the samples drawn for merging are drawn all the same: the image is that of χ = 0
    let plain = Strategy { merge: Some(MergeMask::Constant(0.0)), ..merging_pt };
    let (same, _) = render_iterations(&scene, settings, &config, &plain, 3, 2..3, Some(CandidateSet::Full));
    assert_eq!(image.sum, same.sum);
}

/// Costs measured per job: a collecting call times its work as it renders (light vertices and
/// the photon map every iteration, camera vertices, connections and merges in one pixel of
/// eight), and the times give constants of plausible size. With the default calibrated costs
/// nothing is timed.
#[test]
fn collecting_iterations_time_their_work() {
    use tessera_common::emis::cost::CostConstants;
    use tessera_common::emis::measured::measured_constants;
    use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, Strategy, render_iterations};
    use tessera_common::integrator::observer::TIMED_PIXEL_STRIDE;
    let scene = Scene::load(&scene_path("cornell-box")).expect("scene loads");
    let settings = PathSettings::from_scene(&scene, None);
    let config = EmisConfig::own_pilot(EmisMethod::Vcm);
    let measured = EmisConfig { measured_costs: true, ..config.clone() };
    let pilot = Strategy::pilot(EmisMethod::Vcm);
    // not the job's first call, which would also probe path tracing
    let (_, data) = render_iterations(&scene, settings, &measured, &pilot, 2, 1..3, Some(CandidateSet::Full));
    let s = data.expect("a collecting call").statistics;
    let t = s.times;
    assert_eq!((t.iterations, t.light_vertices), (2, s.light_vertices), "{t:?}");
    let share = t.camera_vertices as f64 / s.camera_vertices as f64;
    let expected = 1.0 / TIMED_PIXEL_STRIDE as f64;
    assert!((share - expected).abs() < 0.2 * expected, "timed share {share}");
    assert!(t.connections > 0 && t.queries > 0 && t.photons > 0 && t.photons_built > 0, "{t:?}");
    assert!(t.queries <= s.merge_queries && t.photons as f64 <= t.photons_squared, "{t:?}");
    assert!([t.light_ns, t.build_ns, t.camera_ns, t.connection_ns, t.merge_ns, t.observer_ns].iter().all(|&ns| ns > 0));
    let k = measured_constants(&t, &CostConstants::calibrated()).expect("enough timed vertices");
    for (name, v) in [
        ("light vertex", k.light_vertex),
        ("connection", k.connection),
        ("photon shading", k.photon_shading),
        ("build", k.build),
    ] {
        assert!(v.is_finite() && (1e-3..1e3).contains(&v), "{name} {v} camera vertices: {k:?}");
    }
    // path tracing is probed by the first call only
    assert_eq!((t.path_tracing_vertices, t.path_tracing_ns), (0, 0), "{t:?}");
    assert_eq!(k.path_tracing, CostConstants::calibrated().path_tracing);
    // calibrated costs time nothing
    let (_, plain) = render_iterations(&scene, settings, &config, &pilot, 2, 0..2, Some(CandidateSet::Full));
    let plain = plain.expect("a collecting call").statistics;
    assert_eq!(plain.times, Default::default(), "{:?}", plain.times);
    assert!(plain.camera_vertices > 0 && plain.light_vertices > 0, "the counts are kept: {plain:?}");
    // a call that does not collect times nothing
    let (_, none) = render_iterations(&scene, settings, &config, &pilot, 2, 0..1, None);
    assert!(none.is_none());
}

/// With costs measured per job, the job's first collecting call (and only it) also times the
/// `pt` integrator on iteration 0, without changing the image, and the probe gives path
/// tracing's constant, of plausible size.
#[test]
fn the_first_call_probes_path_tracing_when_costs_are_measured() {
    use tessera_common::emis::cost::CostConstants;
    use tessera_common::emis::measured::measured_constants;
    use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, Strategy, render_iterations};
    let scene = Scene::load(&scene_path("cornell-box")).expect("scene loads");
    let settings = PathSettings::from_scene(&scene, None);
    let mut config = EmisConfig::own_pilot(EmisMethod::Vcm);
    let start = Strategy::path_tracing_start(EmisMethod::Vcm);
    let (plain, _) = render_iterations(&scene, settings, &config, &start, 2, 0..1, Some(CandidateSet::Reduced));
    config.measured_costs = true;
    let (image, data) = render_iterations(&scene, settings, &config, &start, 2, 0..1, Some(CandidateSet::Reduced));
    assert_eq!(image.sum, plain.sum, "the probe's image is discarded");
    let s = data.expect("a collecting call").statistics;
    let t = s.times;
    assert_eq!(t.path_tracing_vertices, s.camera_vertices, "{t:?}");
    assert!(t.path_tracing_ns > 0, "{t:?}");
    let k = measured_constants(&t, &CostConstants::calibrated()).expect("enough timed vertices");
    assert!(k.path_tracing > 0.1 && k.path_tracing < 1.5, "{k:?}");
    // later calls do not probe again
    let (_, later) = render_iterations(&scene, settings, &config, &start, 2, 2..3, Some(CandidateSet::Reduced));
    assert_eq!(later.expect("a collecting call").statistics.times.path_tracing_ns, 0);
}
