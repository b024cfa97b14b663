//! The same seed gives a bit-identical EXR whatever the thread count, and different seeds give
//! different images.

mod common;

use common::{render_bdpt, render_lt, render_pt, render_vcm, scene_path};
use tessera_common::film::Film;
use tessera_common::film::exr::{ExrExtras, write_exr};
use tessera_common::scene::Scene;

fn exr_bytes(scene: &Scene, seed: u64, threads: usize) -> Vec<u8> {
    exr_of(&render_pt(scene, 4, seed, threads))
}

fn exr_of(film: &Film) -> Vec<u8> {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("out.exr");
    write_exr(
        &path,
        film.width,
        film.height,
        &film.average(),
        &ExrExtras { counts: Some(&film.count), ..Default::default() },
    )
    .expect("write");
    std::fs::read(&path).expect("read")
}

#[test]
fn same_seed_gives_identical_bytes_with_one_and_two_threads() {
    for name in ["cornell-box", "caustic-glass"] {
        let scene = Scene::load(&scene_path(name)).expect("scene loads");
        let one = exr_bytes(&scene, 42, 1);
        let two = exr_bytes(&scene, 42, 2);
        assert!(one == two, "{name}: 1 and 2 threads differ");
        let other = exr_bytes(&scene, 43, 2);
        assert!(one != other, "{name}: the seed must matter");
    }
}

/// Light paths are seeded by (seed, path, iteration) and their splats merged in a fixed order.
#[test]
fn light_tracing_is_identical_with_one_and_two_threads() {
    let scene = Scene::load(&scene_path("cornell-box")).expect("scene loads");
    let one = exr_of(&render_lt(&scene, 2, 9, 1));
    let two = exr_of(&render_lt(&scene, 2, 9, 2));
    assert!(one == two, "1 and 2 threads differ");
    assert!(one != exr_of(&render_lt(&scene, 2, 10, 2)), "the seed must matter");
}

/// The light-vertex cache, connections and splats of bdpt are identical for any thread count.
#[test]
fn bdpt_is_identical_with_one_and_two_threads() {
    let scene = Scene::load(&scene_path("caustic-glass")).expect("scene loads");
    let one = exr_of(&render_bdpt(&scene, 1, 4, 1));
    let two = exr_of(&render_bdpt(&scene, 1, 4, 2));
    assert!(one == two, "1 and 2 threads differ");
}

/// The photon map and merges of vcm are identical for any thread count.
#[test]
fn vcm_is_identical_with_one_and_two_threads() {
    let scene = Scene::load(&scene_path("caustic-glass")).expect("scene loads");
    let one = exr_of(&render_vcm(&scene, 1, 4, 1));
    let two = exr_of(&render_vcm(&scene, 1, 4, 2));
    assert!(one == two, "1 and 2 threads differ");
}
