//! The light probe of iterations observed for EMIS (`LightProbe`): an iteration without light
//! paths, or without a pixel that merges, measures the light paths' length (L̄l) and the
//! photons a merge query finds (φ) as a merging pilot does, so that a path-tracing start does
//! not see merging as free; and the probe leaves the image as it was.

mod common;

use common::scene_path;
use tessera_common::emis::cost::PathStatistics;
use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, Strategy, render_iterations};
use tessera_common::film::{Rect, TileAccum};
use tessera_common::integrator::path::merge::MergeMask;
use tessera_common::integrator::{Integrator, PathSettings, TileRequest};
use tessera_common::scene::Scene;

const SIZE: u32 = 128;

fn scene() -> Scene {
    Scene::load(&scene_path("cornell-box")).expect("scene loads").with_resolution(SIZE, SIZE).expect("square")
}

/// The statistics and the image of one recorded iteration with `strategy`.
fn record(scene: &Scene, strategy: &Strategy, set: CandidateSet) -> (PathStatistics, TileAccum) {
    let config = EmisConfig::new(EmisMethod::Vcm);
    let settings = PathSettings::from_scene(scene, None);
    let (accum, data) = render_iterations(scene, settings, &config, strategy, 3, 0..1, Some(set));
    let data = data.expect("a recording iteration returns pilot data");
    (data.statistics.statistics(SIZE * SIZE), accum)
}

fn within(a: f64, b: f64, tolerance: f64) -> bool {
    (a / b - 1.0).abs() <= tolerance
}

#[test]
fn iterations_without_light_paths_or_merges_measure_them_as_a_merging_pilot() {
    let scene = scene();
    let (vcm, _) = record(&scene, &Strategy::pilot(EmisMethod::Vcm), CandidateSet::Full);
    let start = Strategy::path_tracing_start(EmisMethod::Vcm);
    let (pt, _) = record(&scene, &start, CandidateSet::Reduced);
    let no_merge = Strategy { merge: Some(MergeMask::Constant(0.0)), ..Strategy::pilot(EmisMethod::Vcm) };
    let (bidir, _) = record(&scene, &no_merge, CandidateSet::Full);
    // without the probe: L̄l falls back to L̄c (3.2 here against 4.1) and φ to 1e-7
    for (name, s) in [("path tracing", pt), ("no merging", bidir)] {
        assert!(within(s.light_vertices, vcm.light_vertices, 0.1), "{name}: L̄l {s:?} against {vcm:?}");
        let phi = s.photons_per_query_per_path;
        assert!(within(phi, vcm.photons_per_query_per_path, 0.25), "{name}: φ {s:?} against {vcm:?}");
    }
}

#[test]
fn the_probe_leaves_the_image_unchanged() {
    let scene = scene();
    let start = Strategy::path_tracing_start(EmisMethod::Vcm);
    let (_, probed) = record(&scene, &start, CandidateSet::Reduced);
    let rect = Rect::full(SIZE, SIZE);
    let mut plain = TileAccum::new(rect, &scene.film);
    let integrator = start.integrator(PathSettings::from_scene(&scene, None), true);
    integrator.render_tile(&scene, &TileRequest::new(rect, 0..1, 3), &mut plain);
    assert_eq!(probed, plain);
}
