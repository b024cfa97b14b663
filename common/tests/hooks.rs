//! Sample hooks: an observer attached to `bdpt`/`vcm` sees every contribution exactly once
//! (per pixel, the observed values add up to the rendered image) with weights in [0, 1].

mod common;

use common::{render_with, scene_path};
use std::sync::Mutex;
use tessera_common::integrator::observer::{SampleObserver, SampleRecord};
use tessera_common::integrator::path::merge::{MergeConfig, MergeMask};
use tessera_common::integrator::path::mis::Technique;
use tessera_common::integrator::{Bidir, PathSettings};
use tessera_common::scene::Scene;

struct Collect {
    sums: Mutex<Vec<f64>>,
    merges: Mutex<u64>,
}

impl SampleObserver for Collect {
    fn on_sample(&self, r: &SampleRecord) {
        assert!((0.0..=1.0).contains(&r.weight), "weight {}", r.weight);
        assert!(r.pdfs.len >= 2);
        if matches!(r.technique, Technique::Merge(_)) {
            *self.merges.lock().unwrap() += 1;
        }
        self.sums.lock().unwrap()[r.pixel as usize] += (r.value.x + r.value.y + r.value.z) as f64;
    }
}

#[test]
fn observed_samples_add_up_to_the_image() {
    let scene = Scene::load(&scene_path("caustic-glass")).expect("scene loads");
    let pixels = (scene.camera.width * scene.camera.height) as usize;
    let merge = MergeConfig { mask: MergeMask::Constant(0.5), correlation_aware: true };
    let observer = Collect { sums: Mutex::new(vec![0.0; pixels]), merges: Mutex::new(0) };
    let vcm = Bidir::vcm(PathSettings::from_scene(&scene, None), 0.5, 2, merge).with_observer(observer);
    let film = render_with(&scene, &vcm, 1, 3, 0);
    let observed = vcm.observer.sums.lock().unwrap();
    assert!(*vcm.observer.merges.lock().unwrap() > 0, "merges were reported");
    let mut worst = 0.0f64;
    for (i, s) in film.sum.iter().enumerate() {
        let image = s[0] + s[1] + s[2];
        worst = worst.max((image - observed[i]).abs() / image.abs().max(1e-3));
    }
    assert!(worst < 1e-4, "observed sums differ from the image by {worst}");
}
