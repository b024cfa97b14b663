//! Computes the renderer's revision: a digest of this crate's sources and of the workspace's
//! `Cargo.lock`, which fix every bit a render produces. Workers and the coordinator compare
//! it at registration, so that a farm render stays equal to a local one bit for bit.

use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            files(&path, out);
        } else {
            out.push(path);
        }
    }
}

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let mut sources = Vec::new();
    files(&root.join("src"), &mut sources);
    sources.sort();
    let mut hash = Sha256::new();
    for path in &sources {
        let relative = path.strip_prefix(&root).unwrap_or(path);
        hash.update(relative.to_string_lossy().as_bytes());
        hash.update([0]);
        hash.update(std::fs::read(path).unwrap_or_default());
    }
    // the dependencies' versions (absent when the crate is built outside the workspace)
    let lock = root.join("../Cargo.lock");
    hash.update(std::fs::read(&lock).unwrap_or_default());
    let digest: String = hash.finalize()[..6].iter().map(|b| format!("{b:02x}")).collect();
    println!("cargo:rustc-env=TESSERA_RENDERER_REVISION={digest}");
    println!("cargo:rerun-if-changed=src");
    println!("cargo:rerun-if-changed=../Cargo.lock");
}
