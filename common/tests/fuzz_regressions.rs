//! The fuzzers' reproducers (`fuzz/regressions/`), replayed by the test suite so that their
//! fixes hold without cargo-fuzz: each loads with an error or a value, without a panic (the
//! image decoders' caught panics included), quickly and in bounded memory.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use tessera_common::scene::load::{ply::load_ply_bytes, serialized::load_serialized_bytes};
use tessera_common::scene::{LoadOptions, Scene};
use tessera_common::texture::{Bitmap, BitmapOptions, TextureLimits};

fn reproducers(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/regressions").join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir).map_or(vec![], |d| d.flatten().map(|e| e.path()).collect());
    files.sort();
    files
}

/// Runs `f`, failing on a panic, even one the code catches (a decoder's), or on a slow run.
fn replay(file: &Path, f: impl FnOnce(&[u8])) {
    let bytes = std::fs::read(file).expect("reproducer");
    let panicked = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flag = panicked.clone();
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        flag.store(true, std::sync::atomic::Ordering::Relaxed);
        eprintln!("{info}");
    }));
    let start = Instant::now();
    f(&bytes);
    std::panic::set_hook(previous);
    assert!(!panicked.load(std::sync::atomic::Ordering::Relaxed), "{} panicked", file.display());
    assert!(start.elapsed() < Duration::from_secs(30), "{} took {:?}", file.display(), start.elapsed());
}

/// A scene target's input: `scene.xml` up to the first NUL, then included files.
fn write_scene(dir: &Path, bytes: &[u8]) -> PathBuf {
    for (name, part) in
        ["scene.xml", "inc1.xml", "inc2.xml", "inc3.xml"].iter().zip(bytes.split(|&b| b == 0).chain([&[][..]; 4]))
    {
        std::fs::write(dir.join(name), part).expect("write");
    }
    dir.join("scene.xml")
}

/// One test: the hooks of `replay` are the process's.
#[test]
fn fuzz_reproducers_load_without_panics() {
    let limits = TextureLimits::total(16 << 20);
    for file in reproducers("bitmap") {
        replay(&file, |b| {
            let dir = tempfile::tempdir().expect("tempdir");
            let path = dir.path().join(file.file_name().expect("name"));
            std::fs::write(&path, b).expect("write");
            let _ = Bitmap::load(&path, BitmapOptions::default(), &limits);
        });
    }
    for file in reproducers("mesh_ply") {
        replay(&file, |b| {
            let _ = load_ply_bytes(&file, b);
        });
    }
    for file in reproducers("mesh_serialized") {
        replay(&file, |b| {
            let _ = load_serialized_bytes(&file, b, 0);
        });
    }
    for file in reproducers("scene_xml").into_iter().chain(reproducers("scene_build")) {
        replay(&file, |b| {
            let dir = tempfile::tempdir().expect("tempdir");
            let scene = write_scene(dir.path(), b);
            let options = LoadOptions {
                defines: HashMap::new(),
                confine_to: Some(dir.path().to_path_buf()),
                ..Default::default()
            };
            let _ = Scene::load_options(&scene, &options);
        });
    }
}
