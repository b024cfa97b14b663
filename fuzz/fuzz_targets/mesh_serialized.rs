//! Fuzzes the loader of Mitsuba's `serialized` meshes,
//! `tessera_common::scene::load::serialized::load_serialized`: the file's first mesh (the zlib
//! stream after the header) and its second (found through the offset table at the end). The
//! input is the file, written to a scratch folder on a tmpfs because the loader takes a path.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tessera_common::scene::load::serialized::load_serialized;

fuzz_target!(|data: &[u8]| {
    let path = tessera_fuzz::write("mesh.serialized", data);
    let _ = load_serialized(&path, 0);
    let _ = load_serialized(&path, 1);
});
