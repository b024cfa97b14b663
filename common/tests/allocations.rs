//! No heap allocation per sample in connections or merges: a counting global allocator
//! watches thousands of connection and merge evaluations.

use glam::Vec2;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use tessera_common::integrator::observer::NoObserver;
use tessera_common::integrator::path::light_cache::LightCache;
use tessera_common::integrator::path::mis::SampleCounts;
use tessera_common::integrator::path::techniques::{Report, camera_vertex, connect, next_event};
use tessera_common::integrator::path::vertex::{PathVertex, VertexKind, solid_angle_to_area};
use tessera_common::integrator::path::{
    merge::{merge, merge_radius_max},
    photon_map::PhotonMap,
};
use tessera_common::scene::Scene;

struct Counting;

thread_local! {
    /// Allocations made by this thread only: other threads (the idle rayon pool, the test
    /// harness) must not be counted against the loop under test. `const` initialisation keeps
    /// the counter itself free of allocation.
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn allocations() -> u64 {
    ALLOCATIONS.with(|c| c.get())
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn connections_and_merges_do_not_allocate() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/scene.xml");
    let scene = Scene::load(&path).expect("scene loads");
    let cache = LightCache::trace(&scene, 1, 0, 4096, 10, 5);
    let radius = merge_radius_max(&scene) * 4.0;
    let photons = PhotonMap::build(&cache.vertices, &cache.selectable, radius);
    // a two-vertex camera subpath: the pinhole and the primary hit through the image centre
    let cam = camera_vertex(&scene);
    let ray = scene.camera.generate_ray(Vec2::new(128.0, 200.0));
    let hit = scene.intersect(&ray).expect("the floor is hit");
    let material = scene.shapes[hit.shape as usize].material;
    let z1 = PathVertex {
        p: hit.p,
        n_geo: hit.n_geo,
        n_shading: hit.frame.n,
        tangent: scene.vertex_tangent(&hit),
        wo: hit.wo,
        beta: glam::Vec3::ONE,
        pdf_fwd: solid_angle_to_area(1.0, cam.p, hit.p, hit.n_geo),
        pdf_rev: 0.0,
        pdf_next_event: 0.0,
        kind: VertexKind::Surface { material, at: hit.surface() },
        delta: false,
        depth: 1,
    };
    // and a second vertex straight above it (the ceiling), as a diffuse bounce would reach
    let up = tessera_common::geometry::Ray::new(
        tessera_common::geometry::offset_ray_origin(hit.p, hit.n_geo, glam::Vec3::Y),
        glam::Vec3::Y,
    );
    let hit2 = scene.intersect(&up).expect("the ceiling is hit");
    let z2 = PathVertex {
        p: hit2.p,
        n_geo: hit2.n_geo,
        n_shading: hit2.frame.n,
        tangent: scene.vertex_tangent(&hit2),
        wo: hit2.wo,
        pdf_fwd: solid_angle_to_area(1.0 / std::f32::consts::PI, hit.p, hit2.p, hit2.n_geo),
        depth: 2,
        kind: VertexKind::Surface { material: scene.shapes[hit2.shape as usize].material, at: hit2.surface() },
        ..z1
    };
    let camera = [cam, z1, z2];
    let merge_counts = tessera_common::integrator::path::mis::MergeCounts {
        area: std::f32::consts::PI * radius * radius,
        count: 4096.0,
        correlation_aware: true,
        correlation_area: 1e-3,
        light_paths: 4096.0,
    };
    let counts =
        SampleCounts { hit: 1.0, next_event: 1.0, connect: 0.25, light_trace: 4096.0, merge: Some(merge_counts) };
    let report = Report { observer: &NoObserver, pixel: 0, clock: None };
    let mut energy = glam::Vec3::ZERO;
    let before = allocations();
    // resolved once per vertex, as the integrator does, inside the counted region
    let mz = scene.material_at(scene.shapes[hit2.shape as usize].material, hit2.surface(), hit2.p);
    for &i in &cache.selectable {
        if let Some(w) = connect(&scene, &camera, &mz, cache.subpath(i as usize), 1.0, &counts, &report) {
            energy += w.value;
        }
    }
    for k in 0..1000 {
        if let Some(w) = next_event(&scene, &camera, &mz, k as f32 / 1000.0, Vec2::splat(0.37), &counts, &report) {
            energy += w.value;
        }
        energy += merge(&scene, &camera, &mz, &cache, &photons, radius, 1.0, &counts, 12, &report).0;
    }
    let made = allocations() - before;
    // the counter does see this thread's allocations
    let probe = allocations();
    let v: Vec<u64> = Vec::with_capacity(std::hint::black_box(8));
    drop(std::hint::black_box(v));
    assert!(allocations() > probe, "the counter must see an allocation");
    assert!(energy.max_element() > 0.0, "the loop did real work");
    assert_eq!(made, 0, "{made} heap allocations in {} connections and 1000 merges", cache.selectable.len());
}
