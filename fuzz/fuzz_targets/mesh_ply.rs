//! Fuzzes the PLY mesh loader, `tessera_common::scene::load::ply::load_ply` (ASCII and binary
//! PLY through ply-rs-bw, then Tessera's own checks: indices, fans, attributes). The input is
//! the file, written to a scratch folder on a tmpfs because the loader takes a path.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tessera_common::scene::load::ply::load_ply;

fuzz_target!(|data: &[u8]| {
    let path = tessera_fuzz::write("mesh.ply", data);
    let _ = load_ply(&path);
});
